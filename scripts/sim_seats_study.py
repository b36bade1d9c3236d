#!/usr/bin/env python3
"""Simulated Panda robots in the real seat study's shape: how the defaults carry over to robots we do not have.

Each robot is the Panda URDF with link masses (``panda-with-inertials.urdf``) plus a hidden truth of plausible
size: random joint-origin errors (0.1-0.5 mm, 0.1-0.5 mrad), a tool offset, joint compliance under gravity
(or none), on some an encoder eccentricity or a gain error, and a probing scatter of 0.1-0.15 mm per axis as
the real data show. A plate with two seats 50 mm apart is measured at three placements like the real ones
(``front``, ``right``: seats facing up in front of and beside the robot; ``back-high``: facing the robot
from behind, 0.88 m up), 30 articulations a seat. Trained on one placement, each model is applied by
``aacmm tip`` to the other two (calibration/placements.py): seat spread (2 sigma per hole), distance error and
the coverage of u (axis deviations from the seat's mean within 1.96 u: tip's u of each centre, and the
deviation's own u, calibration.placements.deviation_u), for

* ``close-loop`` and ``calibrate`` with their default options,
* ``geometry``: ``calibrate --effect none`` (the geometry alone, no joint compliance),
* ``nominal-tip``: the nominal URDF with only the tool offset (probe.x/y/z) and the seats fitted,
* ``oracle``: ``calibrate`` told the truth's effects (joint compliance if the truth has it, the eccentricity or
  gain of the truth's joints only): what the right structure gives on these data,
* ``truth``: the hidden truth applied to the same readings (the figures' floor: the scatter alone).

A gain error ``q_true = (1 + g) q_enc`` is put into the readings after the simulation (``q_enc / (1 + g)``
for the simulator's exact readings), independent of the effect code.

    python scripts/sim_seats_study.py -o out/sim-seats                 # every robot
    python scripts/sim_seats_study.py --robots r1,r4 -o out/sim-seats
"""
from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from calibration.placements import placement_study, seat_figures  # noqa: E402

URDF = ROOT / "examples" / "data" / "real-panda-seats" / "panda-with-inertials.urdf"
TIP = "ball_link"
HOLES = ("hole-0", "hole-1")
LENGTH = 0.05            # [m] certified distance between the seats
#: placement -> (hole-0 centre [m], direction to hole-1, seat axis out of the seat), as the real plate's
#: (the real seats' centres through the nominal URDF; the tool points down at front/right, along -x at back-high)
PLACES = {"front": ([0.383, 0.003, 0.001], [0, -1, 0], [0, 0, 1]),
          "right": ([0.382, 0.432, 0.007], [0, 1, 0], [0, 0, 1]),
          "back-high": ([-0.450, -0.009, 0.880], [0, 1, 0], [1, 0, 0])}
METHODS = ("close-loop", "calibrate", "geometry", "nominal-tip", "oracle")


@dataclass(frozen=True)
class Robot:
    """One simulated robot: its hidden truth and the placement it is trained on."""
    name: str
    train: str
    seed: int
    length_um: float                      # 1 sigma of the joint-origin translation errors
    angle_mrad: float                     # 1 sigma of the joint-origin rotation errors
    noise_um: float                       # probing scatter, 1 sigma per axis
    stiffness: float | list | None = None     # joint stiffness under gravity [N m/rad], None: rigid joints
    eccentricity: tuple = ()              # ({"joint": ..., "amplitude_mrad": ..., "phase_deg": ...}, ...)
    gain: dict = field(default_factory=dict)  # joint index (0-based) -> gain error [1]

    def truth_text(self) -> str:
        out = [f"origins {self.length_um:.0f} um / {self.angle_mrad:.2f} mrad"]
        if self.stiffness is None:
            out.append("rigid joints")
        elif np.ndim(self.stiffness) == 0:
            out.append(f"stiffness {self.stiffness / 1e3:.0f} kN m/rad")
        else:
            out.append("stiffness " + "/".join(f"{k / 1e3:.0f}" for k in self.stiffness) + " kN m/rad")
        for e in self.eccentricity:
            out.append(f"eccentricity {e['joint'].replace('panda_joint', 'j')} {e['amplitude_mrad']} mrad")
        for j, g in self.gain.items():
            out.append(f"gain j{j + 1} {g:.0e}")
        out.append(f"noise {self.noise_um:.0f} um")
        return ", ".join(out)


ROBOTS = (
    Robot("r1", "front", 11, 300.0, 0.30, 120.0),
    Robot("r2", "right", 12, 300.0, 0.20, 120.0, stiffness=12000.0),
    Robot("r3", "back-high", 13, 200.0, 0.30, 100.0, stiffness=[15000, 9000, 12000, 7000, 5000, 5000, 5000]),
    Robot("r4", "front", 14, 250.0, 0.25, 120.0, stiffness=10000.0,
          eccentricity=({"joint": "panda_joint1", "amplitude_mrad": 0.3, "phase_deg": 30.0},)),
    Robot("r5", "right", 15, 200.0, 0.20, 150.0,
          eccentricity=({"joint": "panda_joint2", "amplitude_mrad": 0.4, "phase_deg": -60.0},)),
    Robot("r6", "back-high", 16, 400.0, 0.40, 120.0, stiffness=15000.0, gain={3: 5e-4}),
    Robot("r7", "right", 17, 500.0, 0.50, 150.0, stiffness=25000.0),
    Robot("r8", "front", 18, 300.0, 0.30, 150.0, stiffness=12000.0,      # the real Panda's j1 eccentricity (1 mrad)
          eccentricity=({"joint": "panda_joint1", "amplitude_mrad": 1.0, "phase_deg": 120.0},
                        {"joint": "panda_joint3", "amplitude_mrad": 0.3, "phase_deg": 0.0})),
    Robot("r9", "front", 21, 300.0, 0.30, 150.0, stiffness=12000.0,      # joint 1's alone
          eccentricity=({"joint": "panda_joint1", "amplitude_mrad": 1.0, "phase_deg": 120.0},)),
)


def campaign_dict(robot: Robot) -> dict:
    """The simulator's campaign: the truth and two seats a placement (feature ids ``<place>.<hole>``)."""
    tasks = []
    for place, (p, d, axis) in PLACES.items():
        for h, off in zip(HOLES, (0.0, LENGTH), strict=True):
            tasks.append({"kind": "seat", "id": f"{place}.{h}", "axis": axis, "articulations": 30,
                          "position_mm": ((np.asarray(p) + off * np.asarray(d, float)) * 1e3).tolist(),
                          "stylus_cone_deg": 50.0})
    truth = {"length_error_um": robot.length_um, "angle_error_deg": float(np.degrees(robot.angle_mrad * 1e-3)),
             "probe_error_um": 1000.0,
             "probe_compliance": {"bending_um_per_N": 0.0, "axial_um_per_N": 0.0}}    # a rigid tool
    if robot.stiffness is not None:
        truth["joint_compliance"] = {"stiffness_Nm_per_rad": robot.stiffness, "gravity": True, "contact": False}
    if robot.eccentricity:
        truth["eccentricity"] = [{"joint": e["joint"], "amplitude_deg": float(np.degrees(e["amplitude_mrad"] * 1e-3)),
                                  "phase_deg": e["phase_deg"]} for e in robot.eccentricity]
    return {"seed": robot.seed, "sensor": "none", "signals": {"enabled": False}, "truth": truth,
            "noise": {"probing_repeatability_um": robot.noise_um},
            "operator": {"force_mean_N": 0.3, "max_force_N": 1.0}, "task": tasks}


def simulate_robot(robot: Robot, folder: Path, urdf: Path = URDF) -> dict:
    """Write ``folder/<placement>/points.csv`` and ``folder/artefacts.toml``; return the truth's own figures
    per placement (the hidden model on the same readings) and its parameters."""
    from arm_model import PinocchioArm
    from arm_model.model import AuxData
    from arm_model.sim import campaign_from_dict, simulate
    from arm_model.urdf_import import load_arm

    desc = load_arm(urdf, TIP)
    sim = simulate(campaign_from_dict(campaign_dict(robot), arm=desc))
    q_sim = sim.points.q
    q_read = q_sim.copy()
    for j, g in robot.gain.items():               # the encoder reads q_true / (1 + g)
        q_read[:, j] = q_sim[:, j] / (1.0 + g)
    model, p = sim.truth["model"], sim.truth["p_vector"]
    aux = AuxData(None, *PinocchioArm(model.desc).torques(q_sim, None)) if model.needs() else None
    x_truth = model.ball_centres(q_sim, None, p, aux)
    place = np.array([f.split(".", 1)[0] for f in sim.points.feature])
    hole = np.array([f.split(".", 1)[1] for f in sim.points.feature])
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "artefacts.toml").write_text(
        "".join(f'[[feature]]\nid = "{h}"\nkind = "seat"\n\n' for h in HOLES)
        + f'[[distance]]\nbetween = ["{HOLES[0]}", "{HOLES[1]}"]\nlength_mm = {LENGTH * 1e3}\nu_length_mm = 0.05\n')
    figures = {}
    for pl in PLACES:
        sel = place == pl
        (folder / pl).mkdir(exist_ok=True)
        lines = ["measurement,feature," + ",".join(f"q{j + 1}_rad" for j in range(q_read.shape[1]))]
        lines += [f"{pl},{h}," + ",".join(f"{v:.17g}" for v in row)
                  for h, row in zip(hole[sel], q_read[sel], strict=True)]
        (folder / pl / "points.csv").write_text("\n".join(lines) + "\n")
        figures[pl] = seat_figures(x_truth[sel], hole[sel], HOLES, LENGTH)
    return {"figures": figures, "p": {k: float(v) for k, v in sim.truth["p"].items()}}


OPTIONS = {"close-loop": [], "calibrate": [], "geometry": ["--effect", "none"],
           "nominal-tip": ["--effect", "none", "--free", "probe.x", "--free", "probe.y", "--free", "probe.z"]}


def oracle_options(robot: Robot) -> list[str]:
    """``calibrate`` options of the truth's own effects (each effect's parameters on the truth's joints only)."""
    out = ["--effect", "joint_compliance"] if robot.stiffness is not None else []
    for key, joints, pattern in (("eccentricity", {e["joint"] for e in robot.eccentricity}, "ecc*"),
                                 ("joint_gain", {f"panda_joint{j + 1}" for j in robot.gain}, "gain")):
        if joints:
            out += ["--effect", key] + [a for j in range(1, 8) if f"panda_joint{j}" not in joints
                                        for a in ("--hold", f"panda_joint{j}.{pattern}")]
    return out or ["--effect", "none"]


def study_robot(robot: Robot, out: Path, methods=METHODS, train=None, progress=None) -> dict:
    """Simulate ``robot``, train every method on its training placement (``train``: these placements
    instead), predict the others."""
    truth = simulate_robot(robot, out / "data")
    train = train or [robot.train]
    rows = placement_study(out / "data", URDF, TIP, out / "runs", train=train, progress=progress,
                           methods=tuple(methods), options={**OPTIONS, "oracle": oracle_options(robot)})
    return {"robot": robot.name, "truth_text": robot.truth_text(), "train": "/".join(train),
            "truth": truth["figures"], "rows": [r.to_dict() for r in rows]}


def summary_rows(results: list[dict]) -> list[dict]:
    """One row per robot and training placement: the effects the loop added and, per method (and the truth
    on the same held-out placements), the mean held-out spread [mm], the mean |distance error| [mm] and the
    pooled coverage of u [%]."""
    out = []
    for r in results:
        for tr in dict.fromkeys(x["train"] for x in r["rows"]):
            rows = [x for x in r["rows"] if x["train"] == tr]
            tests = list(dict.fromkeys(x["test"] for x in rows))
            figs = {"truth": [r["truth"][t] for t in tests]}
            figs.update({m: [x for x in rows if x["method"] == m] for m in METHODS})
            line = {"robot": r["robot"], "truth_text": r["truth_text"], "train": tr, "tests": tests,
                    "added": next((x["effects"] for x in rows if x["method"] == "close-loop"), [])}
            for m, fs in figs.items():
                if not fs:
                    continue
                line[m] = {"spread_mm": float(np.mean([f["spread_mean_mm"] for f in fs])),
                           "distance_mm": float(np.mean([abs(f["distance_error_mm"]) for f in fs]))}
                for key, name in (("inside", "coverage"), ("inside_dev", "coverage_dev")):
                    if key in fs[0]:
                        line[m][name] = 100.0 * sum(f[key] for f in fs) / sum(f["values"] for f in fs)
            out.append(line)
    return out


def summary_table(lines: list[dict]) -> str:
    """Markdown of :func:`summary_rows`."""
    cols = ["truth"] + [m for m in METHODS if any(m in ln for ln in lines)]
    head = (f"| robot | truth | trained on | loop added | spread 2σ [mm]: {' / '.join(cols)} "
            f"| abs. distance error [mm]: {' / '.join(cols)} | within 1.96 u [%]: {' / '.join(cols[1:])} "
            f"| within 1.96 u of the deviation [%]: {' / '.join(cols[1:])} |")
    md = [head, "|---|---|---|---|---|---|---|---|"]
    def val(ln, m, k, fmt):
        return fmt.format(ln[m][k]) if m in ln and k in ln[m] else "-"
    for ln in lines:
        md.append(f"| {ln['robot']} | {ln['truth_text']} | {ln['train']} | "
                  + (", ".join(e.replace("panda_joint", "j") for e in ln["added"]) or "-") + " | "
                  + " / ".join(val(ln, m, "spread_mm", "{:.3f}") for m in cols) + " | "
                  + " / ".join(val(ln, m, "distance_mm", "{:.3f}") for m in cols) + " | "
                  + " / ".join(val(ln, m, "coverage", "{:.1f}") for m in cols[1:]) + " | "
                  + " / ".join(val(ln, m, "coverage_dev", "{:.1f}") for m in cols[1:]) + " |")
    return "\n".join(md)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--robots", default=None, help="comma-separated robot names (default every one: "
                   + ", ".join(r.name for r in ROBOTS) + ")")
    p.add_argument("--methods", default=",".join(METHODS), help="comma-separated subset of " + ", ".join(METHODS))
    p.add_argument("--every-placement", action="store_true",
                   help="train each robot on each placement in turn (default: its own training placement)")
    p.add_argument("-o", "--output", type=Path, default=Path("out/sim-seats"), help="output folder")
    args = p.parse_args(argv)
    names = args.robots.split(",") if args.robots else [r.name for r in ROBOTS]
    known = {r.name: r for r in ROBOTS}
    unknown = [n for n in names if n not in known]
    if unknown:
        p.error(f"unknown robot(s): {', '.join(unknown)}")
    results = []
    for n in names:
        robot = known[n]
        print(f"{n}: {robot.truth_text()}; trained on {robot.train}", file=sys.stderr, flush=True)
        results.append(study_robot(robot, args.output / n, args.methods.split(","),
                                   train=list(PLACES) if args.every_placement else None,
                                   progress=lambda m: print("  " + m, file=sys.stderr, flush=True)))
        (args.output / "results.json").write_text(json.dumps(results, indent=1) + "\n")
    lines = summary_rows(results)
    (args.output / "summary.json").write_text(json.dumps(lines, indent=1) + "\n")
    print(summary_table(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
