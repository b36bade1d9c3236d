#!/usr/bin/env python3
"""Red-team the defaults on robots: simulated campaigns on URDF robots as they ship, each hiding one effect the
base model lacks, run through the DEFAULT ``close_loop`` (``aacmm close-loop``'s defaults: the joint compliance of
a URDF robot with masses as base model, its prior, the data-defined outer test set) and compared on data no
decision saw (another session, other placements) with the nominal URDF, the base model calibrated on the design
set (what ``aacmm calibrate`` fits) and the truth itself, every model with the same nuisance unknowns solved on
the test points (``T_ref_base`` and the marker offset, the seats' centres). The loop's model file is written and
read back as ``aacmm close-loop`` does (:func:`calibration.model_output.write_model`: a file ``tip`` refuses
stops it), and every joint compliance it writes is checked for sign.

    python scripts/robot_hidden_study.py -o out/robot-hidden                    # every robot, case and kind
    python scripts/robot_hidden_study.py --robots panda --kinds mocap --cases gain -o out/robot-hidden

Every truth: each joint origin of the chain off by 0.5 mm and 1 mrad (1 sigma per axis), every joint sagging
under the URDF's masses (20 000 N m/rad), and one hidden effect:

* ``none``: nothing more (the clean reference: what the loop adds here it adds for nothing);
* ``eccentricity``: the base joint's encoder eccentricity, 1 mrad (the size the real Panda shows);
* ``gain``: the shoulder's (joint 2's) encoder scale 1e-3 (put into the exact readings, ``q_enc / (1 + g)``);
* ``stiff2x``: the shoulder's compliance twice the base model's prior (20 mrad of sag under its RMS gravity
  torque in the campaign, where the prior's scale is 10 mrad);
* ``coupling``: the wrist's reading (joint J-2) carries 2e-3 of the elbow's (joint J-3) angle (readings);
* ``lateral``: the shoulder's off-axis compliance under gravity, 5 000 N m/rad about both axes across it;
* ``tracker-scale`` (motion capture only): the instrument reads every length 0.1 % long.

Kinds: ``mocap`` (one marker 50 mm from the tip frame, 60 postures in 3 sessions of the instrument, 0.1 mm
noise; the third session held out) and ``seats`` (seat pairs 100 mm apart at 12 placements of the bar, 6
articulations a seat, 0.1 mm probing scatter; the loop's own outer test set: 3 placements).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "scripts"))

from hidden_effects_study import (  # noqa: E402
    RMS_COLUMN,
    Case,
    cli_defaults,
    effects_text,
    judge,
    listed,
    loop_row,
    markdown_table,
    rms_cell,
    save_row,
)

from arm_model import PinocchioArm  # noqa: E402
from arm_model.effects import JointGain  # noqa: E402
from arm_model.model import ArmModel  # noqa: E402
from arm_model.sim import campaign_from_dict, simulate  # noqa: E402
from calibration.data import Weights, make_data  # noqa: E402
from calibration.loop import close_loop, heldout_figures  # noqa: E402
from calibration.loop_report import loop_model_name  # noqa: E402
from calibration.model_output import at_equilibrium, refine_torques, with_fitted_torques, write_model  # noqa: E402

#: name: (URDF, tip link); the Panda from examples/ (its masses), the others from example-robot-data 4.1.0
ROBOTS = {"panda": (ROOT / "examples/data/real-panda-seats/panda-with-inertials.urdf", "panda_link8", "ball_link"),
          "ur5": ("ur_description/urdf/ur5_robot.urdf", "tool0", "tool0")}
KINDS = ("mocap", "seats")
CASES = ("none", "eccentricity", "gain", "stiff2x", "coupling", "lateral", "tracker-scale")
STIFFNESS = 20000.0       # [N m/rad] every joint of every truth
NOISE = 1e-4              # [m] the instrument's noise / the probing scatter, 1 sigma per axis


def robot_urdf(name: str) -> Path:
    path = Path(ROBOTS[name][0])
    if path.is_absolute():
        return path
    cache = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "aacmm-toolkit"
    full = cache / "example-robot-data-4.1.0" / "robots" / path
    if not full.is_file():
        sys.exit(f"{full} not found: run `pytest -m slow tests/test_robot_set.py -k quick` once to download it")
    return full


def campaign(robot: str, kind: str, seed: int, truth: dict) -> dict:
    urdf = robot_urdf(robot)
    tip = ROBOTS[robot][1] if kind == "mocap" else ROBOTS[robot][2]
    task = ({"kind": "mocap", "postures": 60, "markers": 1, "sessions": 3, "noise_mm": NOISE * 1e3} if kind == "mocap"
            else {"kind": "ballbar", "ends": "seat", "length_mm": 100.0, "positions": 12, "articulations": 6})
    d = {"seed": seed, "arm": str(urdf), "tip_frame": tip, "sensor": "none",
         "truth": {"length_error_mm": 0.5, "angle_error_deg": 0.0573,
                   "joint_compliance": {"stiffness_Nm_per_rad": STIFFNESS, "gravity": True, "contact": False},
                   **truth},
         "task": [task]}
    if kind == "seats":
        d["noise"] = {"probing_repeatability_mm": NOISE * 1e3}
    return d


def _simulate(d: dict, what: str) -> Case:
    camp = campaign_from_dict(d)
    sim = simulate(camp)
    return Case(sim.points, sim.artefacts, camp.arm, sim.truth["model"], np.asarray(sim.truth["p_vector"]),
                sim.reference_points, what=what, truth_points=sim.points)


def _with_reading_effect(case: Case, effect, value: float, q_read: np.ndarray) -> Case:
    """The case with readings ``q_read`` and ``effect`` (one parameter, ``value``) first in the truth's model."""
    truth = ArmModel(case.desc, (effect, *case.truth_model.effects))
    b = case.truth_model.base_size
    p = np.concatenate([case.p_true[:b], [value], case.p_true[b:]])
    pts = dataclasses.replace(case.points, q=q_read)
    return dataclasses.replace(case, points=pts, truth_points=pts, truth_model=truth, p_true=p)


def make_case(robot: str, kind: str, name: str, seed: int) -> Case:
    """The campaign of ``robot``, ``kind`` and hidden effect ``name`` (module docstring)."""
    names = campaign_from_dict(campaign(robot, kind, seed, {})).arm.joint_names
    truth: dict = {}
    if name == "eccentricity":
        truth = {"eccentricity": [{"joint": names[0], "amplitude_deg": 0.0573, "phase_deg": 30.0}]}
    elif name == "lateral":
        truth = {"lateral_compliance": {"joints": [names[1]], "stiffness_x_Nm_per_rad": 5000.0,
                                        "stiffness_y_Nm_per_rad": 5000.0, "gravity": True, "contact": False}}
    d = campaign(robot, kind, seed, truth)
    if name == "stiff2x":
        base = _simulate(d, "")
        tau = PinocchioArm(base.desc).torques(base.points.q, np.zeros((len(base.points.q), 6)))[0][:, 1]
        k2 = float(np.sqrt(np.mean(tau ** 2))) / 2e-2
        per = [STIFFNESS] * base.desc.n_joints
        per[1] = k2
        d["truth"]["joint_compliance"]["stiffness_Nm_per_rad"] = per
        c = _simulate(d, f"j2 compliance 2x the prior ({k2:.0f} N m/rad: 20 mrad under its RMS torque)")
    else:
        c = _simulate(d, {"none": "nothing more", "eccentricity": "j1 eccentricity 1 mrad",
                          "lateral": "j2 off-axis compliance 5 kN m/rad (gravity)",
                          "gain": "j2 encoder gain 1e-3", "coupling": "wrist reads 2e-3 of the elbow",
                          "tracker-scale": "instrument 0.1 % long"}[name])
    J = c.desc.n_joints
    if name == "gain":
        q = c.points.q.copy()
        q[:, 1] /= 1.0 + 1e-3
        c = _with_reading_effect(c, JointGain(joints=(1,)), 1e-3, q)
    elif name == "coupling":
        q = c.points.q.copy()
        q[:, J - 2] -= 2e-3 * q[:, J - 3]
        c = _with_reading_effect(c, JointGain(joints=(J - 2,), source=J - 3), 2e-3, q)
    elif name == "tracker-scale":
        pts = dataclasses.replace(c.points, ref=c.points.ref * (1.0 + 1e-3))
        c = dataclasses.replace(c, points=pts, truth_points=pts)
    if kind == "mocap":
        last = sorted(set(c.points.session))[-1]
        held = tuple(sorted(set(c.points.measurement[c.points.session == last])))
        return dataclasses.replace(c, holdout=held, weights=Weights(probe=NOISE, reference=NOISE))
    return dataclasses.replace(c, weights=Weights(probe=NOISE))


def figures(case: Case, loop) -> dict:
    """Held-out RMS [um] of the nominal, the base model calibrated on the design set, the loop's model and the
    truth on the outer test set, each with the torques at its own static equilibrium (as ``aacmm tip`` applies a
    model file; the loop's own table, ``loop_table_um``, takes them at the readings)."""
    # every held-out measurement, the test set's outliers included (the loop's own table leaves them out)
    held = set(case.holdout) or set(loop.test) | {d["measurement"] for d in loop.dropped.get("test", [])}
    mask = np.isin(loop.data.points.measurement, sorted(held))
    data = loop.data.select(mask)
    nominal = ArmModel(case.desc, ())
    out = {"nominal": heldout_figures(nominal, np.zeros(nominal.spec.size),
                                      make_data(data.points, data.artefacts, nominal,
                                                marker_offsets=data.marker_offsets), case.weights)["rms_um"]}
    for key, st in (("calibrated", loop.stages[0]), ("loop", loop.final)):
        out[key] = heldout_figures(st.model, st.result.p, with_fitted_torques(data, st.result), case.weights)["rms_um"]
    tpts = case.truth_points.select(mask[: len(case.points.measurement)])
    tdata = make_data(tpts, data.artefacts, case.truth_model, marker_offsets=data.marker_offsets)
    out["floor"] = heldout_figures(case.truth_model, case.p_true, at_equilibrium(case.truth_model, case.p_true, tdata),
                                   case.weights)["rms_um"]
    out["loop_table_um"] = [loop.stages[0].heldout["rms_um"], loop.final.heldout["rms_um"]]
    return out


def model_file_check(loop, case: Case) -> tuple[str, list]:
    """Write the loop's model file as ``aacmm close-loop`` does (its read-back check included) and list the
    joint compliances it holds below zero [rad/(N m)]."""
    result = refine_torques(loop.model_fit if loop.model_fit is not None else loop.stages[-1].result)
    neg = [(n, result.value(n)) for n in result.model.spec.names
           if n.endswith(".compliance") or "lateral_compliance" in n]
    neg = [(n, v) for n, v in neg if v < 0]
    with tempfile.TemporaryDirectory() as tmp:
        try:
            write_model(result, Path(tmp), loop_model_name(loop), written_by="robot_hidden_study")
        except Exception as exc:                       # the study reports it: a file tip would refuse
            return f"refused: {str(exc)[:200]}", neg
    return "ok", neg


def run_one(robot: str, kind: str, name: str, seed: int, out: Path | None) -> dict:
    t0 = time.time()
    case = make_case(robot, kind, name, seed)
    loop = close_loop(case.points, case.artefacts, case.desc, reference=case.reference, weights=case.weights,
                      holdout=case.holdout, progress=lambda s: None, **cli_defaults(case.desc))
    fig = figures(case, loop)
    status, neg = model_file_check(loop, case)
    row = {"robot": robot, "kind": kind, "case": name, "what": case.what, "campaign_seed": seed, **fig,
           **loop_row(loop), **judge(fig, loop), "model_file": status,
           "negative_compliances": neg, "seconds": round(time.time() - t0, 1)}
    print(f"[{robot} {kind} {name} c{seed}] nominal {fig['nominal']:.0f} / calibrated {fig['calibrated']:.0f} / loop "
          f"{fig['loop']:.0f} / truth {fig['floor']:.0f} um; {effects_text(row)}; model file {status}; negative "
          f"{neg or '-'}; honest {row['honest']} ({row['seconds']:.0f} s)", flush=True)
    save_row(out, f"{robot}-{kind}-{name}-c{seed}", row)
    return row


def table(rows: list[dict]) -> str:
    cells = [[f"{r['robot']}, {r['kind']} (seed {r['campaign_seed']})", f"{r['case']}: {r['what']}", rms_cell(r, 0),
              f"{r['loop'] / r['calibrated']:.2f}", listed(r["added"]), listed(r["remaining"]),
              r["model_file"] + ("; negative compliance" if r["negative_compliances"] else "")] for r in rows]
    columns = ["robot, kind", "hidden effect", RMS_COLUMN, "loop / calibrated", "added (* built)", "structure left",
               "model file"]
    return markdown_table(columns, cells, ["---"] * 3 + ["---:"] + ["---"] * 3) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--robots", default=",".join(ROBOTS))
    ap.add_argument("--kinds", default=",".join(KINDS))
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--campaign-seeds", default="1")
    ap.add_argument("-o", "--output", type=Path, default=None)
    a = ap.parse_args(argv)
    rows = []
    for seed in (int(s) for s in a.campaign_seeds.split(",")):
        for robot in a.robots.split(","):
            for kind in a.kinds.split(","):
                for name in a.cases.split(","):
                    if name == "tracker-scale" and kind != "mocap":
                        continue
                    rows.append(run_one(robot, kind, name, seed, a.output))
    text = table(rows)
    print(text)
    if a.output is not None:
        (a.output / "table.md").write_text(text)
        (a.output / "results.json").write_text(json.dumps(rows, indent=1, default=str))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
