#!/usr/bin/env python3
"""Red team, round 3: campaigns hiding effects that none of the earlier studies (hidden_effects_study,
robot_hidden_study, honesty_study) hides, built the way an outside judge would, run through the DEFAULT
``close_loop`` (``aacmm close-loop``'s defaults: a URDF robot with masses starts from its joint compliance) and
compared on the outer test set with the nominal model, the base model calibrated on the design set (what
``aacmm calibrate`` fits on it), the loop's final model and the truth itself (its floor), every model with the same
nuisance unknowns solved on the test points (``robot_hidden_study.figures``: the test set's outliers included, the
torques at each model's own equilibrium). The loop's model file is written and read back as ``aacmm close-loop``
writes it.

    python scripts/redteam_study.py -o out/redteam                       # every case, about 5 min on 2 loaded cores
    python scripts/redteam_study.py --cases blunders,sphere-diameter -o out/redteam

What is checked ("false"): a verdict of "No structured residual remains" while the loop's held-out RMS is above
1.5 x the truth's; an effect kept while the held-out RMS went up (both :func:`hidden_effects_study.judge`); an
effect added none of whose parameters the final fit resolves (every one within 2 u of zero) or a parameter of an
added effect written as estimated (state ``free``) with an uncertainty beyond its value's plausible size; a model
file that does not read back.

Cases (the measuring arm: hidden_effects_study's campaign, ball bar at 10 positions, 4 seats, 5 spheres, 152
points, 2 um probing noise, campaign seed 3; the robot: robot_hidden_study's Panda by motion capture, 60 postures
in 3 sessions, 0.1 mm noise, the third session held out). A change of the readings or of a logged column after
the simulation keeps the simulator's own rows as the truth's (``Case.truth_points``):

* ``backlash-gravity``: j4 sits 0.002 deg beyond its reading to the side its weight pushes it (against the sign of
  its gravity torque: a gear or bearing play the arm's weight takes up one way or the other, the reading on the
  drive's side; until 2026-11-27 the campaign put it on the other side, a play no weight closes);
* ``backlash-motion``: j1's reading lags by 0.002 deg in the direction the joint moved onto each point from the
  point captured before it (hysteresis by the sign of the joint's velocity, the path between two points taken as
  monotone; the campaign's first point from a random side);
* ``harmonics23``: j3's encoder with a 2nd (0.003 deg) and a 3rd (0.002 deg) harmonic and no first;
* ``probe-aniso``: the stylus bends 1.5x / 0.6x the declared compliance along probe x / y, with xy (4 um/N) and
  yz (0.5 um/N) cross terms, 4 N mean force;
* ``force-sensor``: the force sensor's gains (+5 %, -4 %, +3 %), offsets (0.15, -0.1, 0.2 N) and cross-talk (up to
  5 %), 4 N mean force;
* ``force-lag``: the force is sampled 25 +- 10 ms before the encoders (on the pulse's rising edge: 0.72-0.93 of
  the force at the capture), 4 N mean force;
* ``link-sag``: the links after j3 tilt about j3's x axis under gravity, 3e5 N m/rad (a link's bending, not a
  joint's turning);
* ``thermal-gradient``: links grow 23 ppm/K times 0.2 ... 1.4 from base to probe (a gradient along the arm: the
  distal links warmer), the room drifting 8 K/h, 5 min between measurements;
* ``bar-30um``: the ball bar 30 um longer than its certificate;
* ``sphere-diameter``: the spheres' declared diameter 20 um above the true one;
* ``blunders``: four points moved 10, 20, 30, 40 um (5-20 sigma) by a slip of one reading;
* ``urdf-truth``: the campaign simulated on the arm's URDF (urdf/aacmm7.urdf: each joint origin off in 6
  components, 20 um and 0.003 deg) and analysed with its DH description (4 per joint);
* ``panda-backlash``: the Panda's joints 2 and 4 sit 0.5 mrad beyond their readings to the side their weight pushes
  them (as ``backlash-gravity``);
* ``panda-hysteresis``: the Panda's joint 2 and 4 readings off by 0.5 mrad by the direction each last turned,
  from the posture before (a robot's backlash as it drives from posture to posture; a session's first posture
  from a random side);
* ``panda-base-drift``: the Panda's base tilting 1 mrad/h about a horizontal axis relative to the instrument
  during the campaign (20 min a session).
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "scripts"))

from hidden_effects_study import (  # noqa: E402
    RMS_COLUMN,
    Case,
    _arm_campaign,
    _from_sim,
    cli_defaults,
    effects_text,
    judge,
    listed,
    loop_row,
    markdown_table,
    rms_cell,
    save_row,
)
from robot_hidden_study import (  # noqa: E402
    campaign as robot_campaign,  # noqa: E402
    figures,
    model_file_check,
)

from arm_model import PinocchioArm, load_description  # noqa: E402
from arm_model.io import Feature  # noqa: E402
from arm_model.model import reading_motion  # noqa: E402
from calibration.data import Weights  # noqa: E402
from calibration.identifiability import prior_scales  # noqa: E402
from calibration.loop import close_loop  # noqa: E402

DEG = np.pi / 180.0


def _readings(case: Case, q: np.ndarray) -> Case:
    """``case`` with the readings ``q``: the truth keeps the simulator's rows (``truth_points``)."""
    return dataclasses.replace(case, points=dataclasses.replace(case.points, q=q))


def _tau_gravity(camp_dict: dict) -> tuple[Case, np.ndarray]:
    """The simulated campaign and the gravity torque of each joint at each row [N m] (nominal masses, readings)."""
    c = _from_sim(camp_dict, "")
    return c, PinocchioArm(c.desc).torques(c.points.q, np.zeros((len(c.points.q), 6)))[0]


def case_backlash_gravity(seed: int = 3) -> Case:
    c, tau = _tau_gravity(_arm_campaign({}, seed))
    q = c.points.q.copy()
    q[:, 3] += 0.002 * DEG * np.sign(tau[:, 3])     # the joint at q + b sign(-tau): JointBacklash's b > 0
    share = float(np.mean(tau[:, 3] > 0))
    return dataclasses.replace(_readings(c, q), what=f"j4 play 0.002 deg by the sign of its gravity torque "
                               f"({share:.0%} positive)")


def case_backlash_motion(seed: int = 3) -> Case:
    c = _from_sim(_arm_campaign({}, seed), "j1 hysteresis 0.002 deg by the sign of its motion")
    q = c.points.q.copy()
    # the joint's last move onto each point: from the point captured before it (a monotone path between the two),
    # the campaign's first point from a random side
    sign = reading_motion(q, None, c.points.time)[:, 0]
    sign[sign == 0] = np.random.default_rng(seed + 300).choice([-1.0, 1.0], int(np.sum(sign == 0)))
    q[:, 0] -= 0.002 * DEG * sign
    return _readings(c, q)


def case_harmonics23(seed: int = 3) -> Case:
    h = [{"joint": "j3", "harmonic": 2, "amplitude_deg": 0.003, "phase_deg": 40.0},
         {"joint": "j3", "harmonic": 3, "amplitude_deg": 0.002, "phase_deg": -70.0}]
    return _from_sim(_arm_campaign({"truth": {"harmonics": h}}, seed), "j3 encoder harmonics 2 and 3, no first")


def case_probe_aniso(seed: int = 3) -> Case:
    cb = 0.0142
    pc = {"bending_x_mm_per_N": 1.5 * cb, "bending_y_mm_per_N": 0.6 * cb, "coupling_xy_mm_per_N": 0.004,
          "coupling_yz_mm_per_N": 0.0005}
    return _from_sim(_arm_campaign({"truth": {"probe_compliance": pc}}, seed, force=4.0),
                     "stylus 1.5x / 0.6x compliant along x / y, xy 4 um/N, yz 0.5 um/N, 4 N")


def case_force_sensor(seed: int = 3) -> Case:
    fs = {"gain": [0.05, -0.04, 0.03], "offset_N": [0.15, -0.1, 0.2],
          "cross_talk": [[0.0, 0.05, 0.0], [0.03, 0.0, 0.04], [0.0, 0.02, 0.0]]}
    return _from_sim(_arm_campaign({"truth": {"force_sensor": fs}}, seed, force=4.0),
                     "force sensor gains 5 %, offsets 0.2 N, cross-talk 5 %, 4 N")


def case_force_lag(seed: int = 3) -> Case:
    c = _from_sim(_arm_campaign({}, seed, force=4.0), "force sampled 25 +- 10 ms before the encoders, 4 N")
    rng = np.random.default_rng(seed + 100)
    lag = 0.025 + rng.uniform(-0.01, 0.01, len(c.points.measurement))
    rise = 0.12                                          # the simulator's default pulse rise [s]
    factor = np.sin(0.5 * np.pi * (1 - lag / rise)) ** 3  # its rising edge (arm_model.sim.operator)
    pts = dataclasses.replace(c.points, force=c.points.force * factor[:, None])
    # the floor: the truth knowing the lag's mean but not its jitter (no model of these data can know that)
    return dataclasses.replace(c, points=pts, truth_points=dataclasses.replace(pts, force=pts.force / factor.mean()))


def case_link_sag(seed: int = 3) -> Case:
    lc = {"joints": ["j3"], "stiffness_x_Nm_per_rad": 3e5, "gravity": True, "contact": False}
    return _from_sim(_arm_campaign({"truth": {"lateral_compliance": lc}}, seed),
                     "links after j3 bend about its x axis under gravity, 3e5 N m/rad")


def case_thermal_gradient(seed: int = 3) -> Case:
    alpha = [2.3e-5 * g for g in np.linspace(0.2, 1.4, 7)]
    return _from_sim(_arm_campaign({"truth": {"thermal": {"alpha_per_K": alpha}},
                                    "environment": {"drift_C_per_h": 8.0}, "operator": {"measurement_gap_s": 300.0}},
                                   seed), "links grow 23 ppm/K x 0.2 ... 1.4 from base to probe, 8 K/h")


def case_bar_30um(seed: int = 3) -> Case:
    tasks = [{**_arm_campaign({})["task"][0], "true_length_mm": 600.03}, *_arm_campaign({})["task"][1:]]
    return _from_sim(_arm_campaign({}, seed, tasks=tasks), "ball bar 30 um longer than its certificate")


def case_sphere_diameter(seed: int = 3) -> Case:
    c = _from_sim(_arm_campaign({}, seed), "spheres declared 20 um larger than they are")
    feats = {k: (dataclasses.replace(f, diameter=f.diameter + 20e-6) if f.kind == "sphere" and f.diameter else f)
             for k, f in c.artefacts.features.items()}
    assert all(isinstance(f, Feature) for f in feats.values())
    return dataclasses.replace(c, artefacts=dataclasses.replace(c.artefacts, features=feats))


def case_blunders(seed: int = 3) -> Case:
    c = _from_sim(_arm_campaign({}, seed), "four points moved 10-40 um (5-20 sigma) by a slipped reading")
    model = c.truth_model
    q = c.points.q.copy()
    rng = np.random.default_rng(seed + 200)
    rows = rng.choice(len(q), 4, replace=False)
    for size, i in zip((10e-6, 20e-6, 30e-6, 40e-6), rows, strict=True):
        j = int(rng.integers(0, 3))
        dq = np.zeros_like(q[i])
        dq[j] = 1e-5
        w = None if c.points.force is None else np.r_[c.points.force[i], 0, 0, 0][None]
        move = np.linalg.norm(model.ball_centres((q[i] + dq)[None], w, c.p_true)
                              - model.ball_centres(q[i][None], w, c.p_true)) / 1e-5
        q[i, j] += size / move
    return _readings(c, q)


def case_urdf_truth(seed: int = 3) -> Case:
    d = _arm_campaign({}, seed)
    d.update({"arm": str(ROOT / "urdf/aacmm7.urdf"), "tip_frame": "ball"})
    c = _from_sim(d, "simulated on the URDF (6 errors a joint origin), analysed with the DH description")
    return dataclasses.replace(c, desc=load_description(ROOT / "urdf/aacmm7.dh.toml"))


def _panda(seed: int) -> tuple[Case, np.ndarray]:
    return _tau_gravity(robot_campaign("panda", "mocap", seed, {}))


def _mocap(c: Case) -> Case:
    last = sorted(set(c.points.session))[-1]
    held = tuple(sorted(set(c.points.measurement[c.points.session == last])))
    return dataclasses.replace(c, holdout=held, weights=Weights(probe=1e-4, reference=1e-4))


def case_panda_backlash(seed: int = 1) -> Case:
    c, tau = _panda(seed)
    q = c.points.q.copy()
    for j in (1, 3):
        q[:, j] += 5e-4 * np.sign(tau[:, j])
    share = [f"{np.mean(tau[:, j] > 0):.0%}" for j in (1, 3)]
    return _mocap(dataclasses.replace(_readings(c, q), what=f"joints 2 and 4 play 0.5 mrad by the sign of their "
                                      f"gravity torque ({' / '.join(share)} positive)"))


def case_panda_hysteresis(seed: int = 1) -> Case:
    c, _ = _panda(seed)
    q = c.points.q.copy()
    sign = reading_motion(q, c.points.session, c.points.time)
    sign[sign == 0] = np.random.default_rng(seed + 300).choice([-1.0, 1.0], int(np.sum(sign == 0)))
    for j in (1, 3):
        q[:, j] -= 5e-4 * sign[:, j]
    return _mocap(dataclasses.replace(_readings(c, q), what="joints 2 and 4 backlash 0.5 mrad by the direction "
                                      "they last turned (posture to posture)"))


def case_panda_base_drift(seed: int = 1) -> Case:
    c, _ = _panda(seed)
    pts = c.points
    t = (pts.time - pts.time.min()) / 3600.0
    ang = 1e-3 * t                                              # [rad]
    ref = pts.ref.copy()
    for s in sorted(set(pts.session)):
        rows = pts.session == s
        centre = ref[rows].reshape(-1, 3).mean(axis=0)
        x = ref[rows] - centre
        ca, sa = np.cos(ang[rows])[:, None], np.sin(ang[rows])[:, None]
        ref[rows, :, 1] = centre[1] + ca * x[:, :, 1] - sa * x[:, :, 2]
        ref[rows, :, 2] = centre[2] + sa * x[:, :, 1] + ca * x[:, :, 2]
    span = float(t.max() * 60)
    c = dataclasses.replace(c, points=dataclasses.replace(pts, ref=ref),
                            what=f"base tilting 1 mrad/h relative to the instrument ({span:.0f} min)")
    return _mocap(c)


CASES = {"backlash-gravity": case_backlash_gravity, "backlash-motion": case_backlash_motion,
         "harmonics23": case_harmonics23, "probe-aniso": case_probe_aniso, "force-sensor": case_force_sensor,
         "force-lag": case_force_lag, "link-sag": case_link_sag, "thermal-gradient": case_thermal_gradient,
         "bar-30um": case_bar_30um, "sphere-diameter": case_sphere_diameter, "blunders": case_blunders,
         "urdf-truth": case_urdf_truth, "panda-backlash": case_panda_backlash,
         "panda-hysteresis": case_panda_hysteresis, "panda-base-drift": case_panda_base_drift}


def written_claims(loop) -> list[str]:
    """What the loop's final fit writes of the effects it added that nobody resolved: an added effect none of
    whose parameters is beyond 2 u of zero, and a parameter written as estimated (``free``) whose uncertainty
    exceeds its plausible size (:func:`calibration.identifiability.prior_scales`)."""
    res = loop.model_fit if loop.model_fit is not None else loop.stages[-1].result
    spec = res.model.spec
    out = []
    for cand in loop.added:
        names = [n for e, sl in res.model.effect_slices() if e == cand.effect for n in spec.names[sl]]
        if not names:
            continue
        scales = prior_scales(res.model, names)
        z = [abs(res.value(n)) / res.uncertainty(n) if res.uncertainty(n) > 0 else np.inf for n in names]
        if max(z) < 2.0:
            out.append(f"{cand.name}: no parameter beyond 2 u")
        for n, scale in zip(names, scales, strict=True):
            if res.state(n) == "free" and res.uncertainty(n) > float(scale):
                out.append(f"{n}: written free, u {res.uncertainty(n):.3g} beyond its plausible size")
    return out


def run_case(name: str, campaign_seed: int | None, out: Path | None) -> dict:
    t0 = time.time()
    make = CASES[name]
    case = make() if campaign_seed is None else make(campaign_seed)
    loop = close_loop(case.points, case.artefacts, case.desc, reference=case.reference, weights=case.weights,
                      holdout=case.holdout, progress=lambda s: None, **cli_defaults(case.desc))
    fig = figures(case, loop)
    status, neg = model_file_check(loop, case)
    row = {"case": name, "what": case.what, "campaign_seed": campaign_seed, **fig, **loop_row(loop),
           **judge(fig, loop), "unresolved_written": written_claims(loop), "model_file": status,
           "negative_compliances": neg, "seconds": round(time.time() - t0, 1)}
    row["false"] = (not row["honest"]) or bool(row["unresolved_written"]) or status != "ok" or bool(neg)
    worse = (row["heldout_check"] or {}).get("worse_than_stated")
    dropped = sum(len(v) for v in loop.dropped.values())
    print(f"[{name}] {case.what}: nominal {fig['nominal']:.2f} / calibrated {fig['calibrated']:.2f} / loop "
          f"{fig['loop']:.2f} / truth {fig['floor']:.2f} um; {effects_text(row)}; test set worse than stated "
          f"{worse}; points dropped {dropped}; false {row['false']} {row['unresolved_written'] or ''} "
          f"({row['seconds']:.0f} s)", flush=True)
    save_row(out, name, row)
    return row


def verdict_word(row: dict) -> str:
    v = row["verdict"]
    if "No structured residual remains" in v:
        return "complete"
    if "not complete" in v:
        return "not complete"
    return "structure left" if row["remaining"] else "residual above stated"


def table(rows: list[dict]) -> str:
    cells = [[r["case"], r["what"], rms_cell(r, 2), listed(r["added"]), listed(r["remaining"]), verdict_word(r),
              "**yes**" if r["false"] else "no"] for r in rows]
    columns = ["case", "hidden effect", RMS_COLUMN, "added (* built)", "structure left", "verdict", "false"]
    return markdown_table(columns, cells) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", default=",".join(CASES), help="comma-separated: " + ", ".join(CASES))
    ap.add_argument("--campaign-seed", type=int, default=None, help="every campaign's seed (default: 3 on the "
                    "measuring arm, 1 on the robot, the earlier studies' own)")
    ap.add_argument("-o", "--output", type=Path, default=None, help="folder for one JSON a case and table.md")
    a = ap.parse_args(argv)
    rows = [run_case(n.strip(), a.campaign_seed, a.output) for n in a.cases.split(",")]
    text = table(rows)
    print(text)
    if a.output is not None:
        (a.output / "table.md").write_text(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
