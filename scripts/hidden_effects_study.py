#!/usr/bin/env python3
"""Red-team the loop: campaigns that hide an effect the project was never told of (none of them in the effect
library or among the beyond-library effects of tests/test_loop_synthesis.py), run through the DEFAULT
``close_loop`` (``aacmm close-loop``'s defaults but the stated probing noise) with a held-out set, and what it
reports.

Per case and per loop seed: the held-out (outer test set) RMS of the nominal model (the same nuisance unknowns
solved on the test points: centres, axes, ``T_ref_base``, marker offsets), of the base model calibrated on the
design set, of the loop's final model, and of the truth itself (its floor: the scatter alone, the same
nuisance unknowns); the effects added, those built and not added, the structure left, the verdict's claim.
"honest" checks two things: no "No structured residual remains" while the loop's held-out RMS stays above
1.5 x the truth's floor, and no effect kept when the held-out RMS went up.

    python scripts/hidden_effects_study.py                       # every case, loop seeds 0-2 (5 min on 2 loaded cores)
    python scripts/hidden_effects_study.py --cases harmonic4 --seeds 0 -o out/hidden
    python scripts/hidden_effects_study.py --seeds 0 --campaign-seeds 4,5     # other draws of every campaign

Cases (the simulator's truth unless said; 2 um probing noise on the measuring arm):

* ``harmonic4``: a fourth harmonic of the base joint's encoder error, 0.004 deg (an encoder with four-fold
  symmetric errors; the library holds harmonics 1-2, the structure tests 1-3);
* ``no-thermometer``: every link grows 23 ppm/K, the room drifts 8 K/h, but the arm logs no temperature (the
  ``temperature_C`` column dropped, ``time_s`` kept);
* ``base-tilt``: the arm's base (a tripod, a magnetic base) tilts isotropically under the moment of the arm's
  weight and of the contact force, 1e6 N m/rad (the truth's lateral compliance of j1 with equal x and y);
* ``coupling``: the wrist's j6 reading carries 2e-4 of j5's angle (a differential wrist, a coupled cable):
  a linear, not periodic, cross-coupling (fast path, a study-local effect: the simulator's campaigns hold only
  the library's);
* ``two-bars``: two ball bars, 600 mm as certified and 400 mm whose true length is 40 um longer than its
  certificate;
* ``bent-stylus``: the stylus bent 5 deg about the probe y axis: its compliance's axes turned (bending along x
  and axial along z mixed, xz coupling 1.22 um/N), 4 N mean force;
* ``tracker-scale``: a robot (the Panda URDF with its masses, joint stiffness 12 kN m/rad) by motion capture,
  three sessions, 0.1 mm noise, the instrument reading every length 0.1 % long (a wand calibration off);
  the third session held out.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from arm_model import load_description  # noqa: E402
from arm_model.effects import Effect  # noqa: E402
from arm_model.model import ArmModel  # noqa: E402
from arm_model.sim import campaign_from_dict, simulate  # noqa: E402
from arm_model.sim.quick import SynthSpec, make_campaign, random_truth  # noqa: E402
from calibration.calibrate import default_effects  # noqa: E402
from calibration.candidates import DEFAULT_FAMILIES  # noqa: E402
from calibration.data import Weights, make_data  # noqa: E402
from calibration.loop import close_loop, heldout_figures  # noqa: E402

NOISE_UM = 2.0
#: the measuring arm's campaign (as tests/test_loop_effects.py): ball bar, seats, spheres, 19 measurements
ARM_TASKS = [{"kind": "ballbar", "positions": 10, "length_mm": 600.0, "points_per_sphere": 4},
             {"kind": "seat", "articulations": 8, "measurements": 4},
             {"kind": "sphere", "points": 8, "measurements": 5}]
PANDA = ROOT / "examples/data/real-panda-seats/panda-with-inertials.urdf"


@dataclasses.dataclass(frozen=True)
class LinearCoupling(Effect):
    """Study-local truth: joint ``joints[0]``'s reading error ``c q_source`` (a linear cross-coupling)."""
    source: int = 0
    key: str = dataclasses.field(default="study_linear_coupling", init=False, repr=False)
    acts_on_readings = True

    def param_defs(self, desc):
        return [(f"{desc.joint_names[i]}.coupling_by_q{self.source + 1}", "1") for i in self.joint_indices(desc)]

    def apply(self, desc, params, inputs, geom, ops):
        q = list(inputs.q)
        for k, i in enumerate(self.joint_indices(desc)):
            q[i] = q[i] + params[k] * inputs.q[self.source]
        inputs.q = q


@dataclasses.dataclass
class Case:
    """A simulated campaign and its truth: what the study hands the loop and what it compares with."""
    points: object
    artefacts: object
    desc: object
    truth_model: ArmModel
    p_true: np.ndarray
    reference: object = None
    holdout: tuple = ()
    weights: Weights = Weights(probe=NOISE_UM * 1e-6)
    what: str = ""
    truth_points: object = None       # the rows as the truth sees them (a column the arm does not log kept)


def _arm_campaign(sections: dict, seed: int = 3, tasks=None, force: float | None = None) -> dict:
    d = {"seed": seed, "sensor": "xyz", "signals": {"enabled": False},
         "noise": {"probing_repeatability_um": NOISE_UM}, "task": tasks or ARM_TASKS}
    if force is not None:
        d["operator"] = {"force_mean_N": force}
    for k, v in sections.items():
        d[k] = {**d.get(k, {}), **v}
    return d


def _from_sim(camp_dict: dict, what: str, strip=()) -> Case:
    camp = campaign_from_dict(camp_dict)
    sim = simulate(camp)
    pts = sim.points
    if strip:
        pts = dataclasses.replace(pts, **{k: None for k in strip})
    return Case(pts, sim.artefacts, camp.arm, sim.truth["model"], np.asarray(sim.truth["p_vector"]),
                sim.reference_points, what=what, truth_points=sim.points)


def case_harmonic4(seed: int = 3) -> Case:
    return _from_sim(_arm_campaign({"truth": {"harmonics": [{"joint": "j1", "harmonic": 4, "amplitude_deg": 0.004,
                                                              "phase_deg": 20.0}]}}, seed),
                     "4th harmonic of j1's encoder, 0.004 deg")


def case_no_thermometer(seed: int = 3) -> Case:
    c = _from_sim(_arm_campaign({"truth": {"thermal": {"alpha_per_K": [2.3e-5]}}, "environment": {"drift_C_per_h": 8.0},
                                 "operator": {"measurement_gap_s": 300.0}}, seed),
                  "links grow 23 ppm/K, 8 K/h drift, no temperature column", strip=("temperature",))
    return c


def case_base_tilt(seed: int = 3) -> Case:
    return _from_sim(_arm_campaign({"truth": {"lateral_compliance": {"joints": ["j1"], "stiffness_x_Nm_per_rad": 1e6,
                                                                     "stiffness_y_Nm_per_rad": 1e6}}}, seed),
                     "base tilts under the arm's moment, 1e6 N m/rad isotropic")


def case_coupling(seed: int = 3) -> Case:
    nominal = load_description(ROOT / "urdf/aacmm7.dh.toml")
    truth = ArmModel(nominal, (LinearCoupling(joints=(5,), source=4),))
    p = random_truth(truth, np.random.default_rng(seed), length=30e-6, angle=5e-5, probe=30e-6)
    p[truth.base_size:] = 2e-4
    spec = SynthSpec(ballbars=10, ballbar_points=4, seats=4, articulations=8, spheres=5, sphere_points=8,
                     noise=NOISE_UM * 1e-6)
    c = make_campaign(truth, spec, seed=seed, p_true=p)
    return Case(c.points, c.artefacts, nominal, truth, p, what="j6 reading += 2e-4 q5 (linear coupling)")


def case_two_bars(seed: int = 3) -> Case:
    tasks = [{"kind": "ballbar", "id": "bar600", "positions": 6, "length_mm": 600.0, "points_per_sphere": 4},
             {"kind": "ballbar", "id": "bar400", "positions": 6, "length_mm": 400.0, "true_length_mm": 400.04,
              "points_per_sphere": 4},
             *ARM_TASKS[1:]]
    return _from_sim(_arm_campaign({}, seed, tasks=tasks), "400 mm bar 40 um longer than its certificate")


def case_bent_stylus(seed: int = 3) -> Case:
    th = np.radians(5.0)
    cb, ca = 0.0142, 0.0000876                      # the declared bending and axial compliance [mm/N]
    pc = {"bending_x_mm_per_N": cb * np.cos(th) ** 2 + ca * np.sin(th) ** 2, "bending_y_mm_per_N": cb,
          "axial_mm_per_N": cb * np.sin(th) ** 2 + ca * np.cos(th) ** 2,
          "coupling_xz_mm_per_N": (cb - ca) * np.sin(th) * np.cos(th)}
    return _from_sim(_arm_campaign({"truth": {"probe_compliance": pc}}, seed, force=4.0),
                     "stylus bent 5 deg: compliance axes turned (xz 1.22 um/N), 4 N")


def case_tracker_scale(seed: int = 3) -> Case:
    d = {"seed": seed, "arm": str(PANDA), "tip_frame": "panda_link8", "sensor": "none",
         "truth": {"length_error_mm": 0.5, "angle_error_deg": 0.1,
                   "joint_compliance": {"stiffness_Nm_per_rad": 12000.0, "gravity": True, "contact": False}},
         "task": [{"kind": "mocap", "postures": 60, "markers": 1, "sessions": 3, "noise_mm": 0.1}]}
    c = _from_sim(d, "motion capture reads 0.1 % long, 3 sessions, the third held out")
    pts = c.points
    ref = pts.ref * (1.0 + 1e-3)                     # about the instrument's origin, every session
    pts = dataclasses.replace(pts, ref=ref)
    c.truth_points = pts
    held = tuple(sorted(set(pts.measurement[pts.session == sorted(set(pts.session))[-1]])))
    return dataclasses.replace(c, points=pts, holdout=held, weights=Weights(probe=1e-4, reference=1e-4))


CASES = {"harmonic4": case_harmonic4, "no-thermometer": case_no_thermometer, "base-tilt": case_base_tilt,
         "coupling": case_coupling, "two-bars": case_two_bars, "bent-stylus": case_bent_stylus,
         "tracker-scale": case_tracker_scale}


def cli_defaults(desc) -> dict:
    """``aacmm close-loop``'s default base model (calibration/loop_cli.py): the joint compliance of a URDF robot
    with masses (its family then no candidate), else nothing."""
    effects = default_effects(ArmModel(desc, ()))
    if not effects:
        return {}
    return {"effects": effects, "families_": tuple(f for f in DEFAULT_FAMILIES if f not in {e.key for e in effects})}


def test_rows(case: Case, loop) -> np.ndarray:
    """Mask of the outer test set's rows in the loop's data."""
    return np.isin(loop.data.points.measurement, list(loop.test))


def figures(case: Case, loop) -> dict:
    """Held-out RMS [um] of the nominal, the calibrated base model, the loop's model and the truth."""
    mask = test_rows(case, loop)
    nominal = ArmModel(case.desc, ())
    data = loop.data.select(mask)
    w = case.weights
    nom = heldout_figures(nominal, np.zeros(nominal.spec.size), make_data(data.points, data.artefacts, nominal,
                                                                        marker_offsets=data.marker_offsets), w)
    tpts = (case.truth_points or case.points).select(mask[: len(case.points.measurement)])
    tdata = make_data(tpts, data.artefacts, case.truth_model, marker_offsets=data.marker_offsets)
    floor = heldout_figures(case.truth_model, case.p_true, tdata, w)
    return {"nominal": nom["rms_um"], "calibrated": loop.stages[0].heldout["rms_um"],
            "loop": loop.final.heldout["rms_um"], "floor": floor["rms_um"]}


def loop_row(loop) -> dict:
    """What a study row records of a loop's result: the effects added (* built from the residual), built and not
    added, vetoed, the structure left, the verdict, the test set, the judgement of the test set (``heldout_check``)
    and the opt-in families offered when it was worse (``escalated``)."""
    return {"added": [c.name + ("*" if c.origin == "residual" else "") for c in loop.added],
            "built_not_added": [b["name"] for b in loop.built if not b.get("added")],
            "vetoed": [v["name"] for v in loop.vetoed], "remaining": [f.name for f, *_ in loop.remaining],
            "verdict": loop.verdict, "test": list(loop.test),
            "heldout_check": loop.heldout_check,
            "escalated": None if loop.escalated is None else loop.escalated["families"]}


def judge(fig: dict, loop) -> dict:
    v = loop.verdict
    claims_clean = "No structured residual remains" in v
    honest = not (claims_clean and fig["loop"] > 1.5 * fig["floor"]) and not (loop.added and
                                                                             fig["loop"] > fig["calibrated"])
    return {"claims_clean": claims_clean, "honest": honest}


def run_case(name: str, seeds, out: Path | None, campaign_seed: int = 3) -> list[dict]:
    t0 = time.time()
    case = CASES[name](campaign_seed)
    print(f"[{name}, campaign seed {campaign_seed}] {case.what}: {len(case.points.measurement)} points, simulated in "
          f"{time.time() - t0:.0f} s", flush=True)
    rows = []
    for seed in seeds:
        t1 = time.time()
        loop = close_loop(case.points, case.artefacts, case.desc, reference=case.reference, weights=case.weights,
                          holdout=case.holdout, seed=seed, progress=lambda s: None, **cli_defaults(case.desc))
        fig = figures(case, loop)
        row = {"case": name, "what": case.what, "campaign_seed": campaign_seed, "seed": seed, **fig,
               **loop_row(loop), **judge(fig, loop), "seconds": round(time.time() - t1, 1)}
        rows.append(row)
        print(f"  seed {seed}: nominal {fig['nominal']:.2f} -> calibrated {fig['calibrated']:.2f} -> loop "
              f"{fig['loop']:.2f} um (floor {fig['floor']:.2f}); {effects_text(row)}; honest {row['honest']} "
              f"({row['seconds']:.0f} s)", flush=True)
        save_row(out, f"{name}-c{campaign_seed}-seed{seed}", row)
    return rows


#: the columns every study's table shares: the held-out RMS of the four models (:func:`rms_cell`)
RMS_COLUMN = "held-out RMS [um]: nominal / calibrated / loop / truth"


def effects_text(row: dict) -> str:
    """What the loop did, for a case's console line: the effects added, built but not added, and remaining."""
    return (f"added {row['added'] or '-'}; built not added {row['built_not_added'] or '-'}; remaining "
            f"{row['remaining'] or '-'}")


def save_row(out: Path | None, name: str, row: dict) -> None:
    """A case's row as ``out/name.json`` (nothing without ``out``)."""
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        (out / f"{name}.json").write_text(json.dumps(row, indent=1, default=str))


def listed(names) -> str:
    """A table cell of names: comma-separated, "-" for none."""
    return ", ".join(names) or "-"


def rms_cell(row: dict, digits: int) -> str:
    """The :data:`RMS_COLUMN` cell of a study's row [um]."""
    return " / ".join(f"{row[k]:.{digits}f}" for k in ("nominal", "calibrated", "loop", "floor"))


def markdown_table(columns: list[str], cells: list[list[str]], align: list[str] | None = None) -> str:
    """The markdown table of the studies (this one, ``robot_hidden_study``, ``redteam_study``): a header of
    ``columns``, the separator (``align``: each column's, default ``---``), a line a row of ``cells``."""
    lines = ["| " + " | ".join(columns) + " |", "|" + "|".join(align or ["---"] * len(columns)) + "|"]
    return "\n".join(lines + ["| " + " | ".join(c) + " |" for c in cells])


def table(rows: list[dict]) -> str:
    cells = []
    for name, cs in dict.fromkeys((r["case"], r["campaign_seed"]) for r in rows):
        rs = [r for r in rows if (r["case"], r["campaign_seed"]) == (name, cs)]
        r = rs[0]
        agree = all((x["added"], x["remaining"]) == (r["added"], r["remaining"]) for x in rs)
        cells.append([f"{name} ({cs})", r["what"], rms_cell(r, 2), listed(r["added"]), listed(r["built_not_added"]),
                      listed(r["remaining"]), f"{'yes' if agree else 'no'} ({len(rs)})",
                      "yes" if all(x["honest"] for x in rs) else "no"])
    return markdown_table(["case (campaign seed)", "hidden effect", RMS_COLUMN, "added (* built)", "built, not added",
                           "structure left", "seeds agree", "honest"], cells)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", default=",".join(CASES), help="comma-separated: " + ", ".join(CASES))
    ap.add_argument("--seeds", default="0,1,2", help="the loop's seeds (default 0,1,2)")
    ap.add_argument("--campaign-seeds", default="3", help="the campaigns' seeds (default 3; each a new draw of the "
                    "errors, poses and noise)")
    ap.add_argument("-o", "--output", type=Path, default=None, help="folder for one JSON a run")
    a = ap.parse_args(argv)
    seeds = [int(s) for s in a.seeds.split(",")]
    rows = []
    for cs in (int(s) for s in a.campaign_seeds.split(",")):
        for name in a.cases.split(","):
            rows += run_case(name.strip(), seeds, a.output, cs)
    print(table(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
