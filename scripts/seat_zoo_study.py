#!/usr/bin/env python3
"""The seat data set's shape on robot types as they ship: does a default chosen with the real Panda in view lose to
least squares on another robot?

Robots: the KUKA LBR iiwa 14 (pybullet 3.2.7's ``kuka_iiwa/model.urdf``), Kinova's Gen3 (``ros_kortex``'s
``GEN3_URDF_V12.urdf``, 7 joints), the UR5 (example-robot-data 4.1.0's ``ur5_robot.urdf``, 6 joints) and the
Panda (the data set's own URDF, ``examples/data/real-panda-seats``); each file read as it ships, from a scratch
environment (none is a dependency, nothing is copied into the project), with a ball fixed to its flange
(``sim_seats_study.ball_urdf``).

The hidden truth of each robot: every joint origin off by random errors (``origins``: 1 sigma per axis of the
translation [um] and of the rotation [mrad], so the joint offsets too), a 1 mm tool offset, the joints sagging
under the URDF's link masses (``stiffness`` [N m/rad]), encoder noise, and a probing scatter of the size the real
Panda shows (:func:`panda_scatter`: the noise default ``calibrate`` finds in each of its placements, 1 sigma per
axis). The capture as in the real files: per placement hole-0's 30 articulations, then hole-1's, each hole's
poses swept in order (:func:`sweep_order`: a nearest-neighbour path through joint space, consecutive poses
close as a hand-guided sweep's), and a small drift of the plate along that order (``drift_um`` over the
placement's 60 points, in a random direction; the real Panda's distance errors carry a trend along the order of
0.4-0.75 mm, docs/studies/calibration.md). Three plate placements within each robot's reach: the real plate's,
their horizontal distances scaled by the robot's reach over the Panda's and ``back-high`` kept at its height above
the shoulder (:func:`places`).

Each robot is trained on each placement in turn and predicts the two others (calibration/placements.py: seat
spread 2 sigma per hole, distance error, coverage of u), with

* ``nominal``: the URDF applied as it ships, nothing fitted,
* ``least-squares``: the geometry by least squares, ``FitOptions(prior_scale=None)`` through the Python API
  (the project's stand-in for the published tool MUKCa, docs/studies/calibration.md),
* ``calibrate`` and ``close-loop@S`` (``--seed S``, S = 0, 1, 2): the commands with their defaults; every model
  file each writes is applied by ``aacmm tip`` (a file ``tip`` cannot read fails the study).

``--variants`` re-runs ``calibrate`` and ``close-loop --seed 0`` with a threshold of calibration/prior.py set
otherwise (``BARELY_SEEN=0.5``, ``MIN_SIDE_VISITS=2``, ...; set in this process for the run).

    python -m venv /tmp/descr && /tmp/descr/bin/pip install pybullet     # the iiwa's URDF (not a dependency)
    nice python scripts/seat_zoo_study.py --python /tmp/descr/bin/python --urdf gen3=PATH/GEN3_URDF_V12.urdf \\
        -o out/seat-zoo                                                   # every robot
    nice python scripts/seat_zoo_study.py --robots ur5 --trains front --variants BARELY_SEEN=0.5 -o out/z

Writes ``results.json`` (every row) and ``table.md`` into the output folder.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "scripts"))

import sim_seats_study as seats  # noqa: E402

from calibration.placements import placement_study, seat_figures  # noqa: E402

HOLES, LENGTH, TIP, URDF = seats.HOLES, seats.LENGTH, seats.TIP, seats.URDF

PANDA_DATA = ROOT / "examples" / "data" / "real-panda-seats"
PANDA_REACH = 0.855      # [m] the Panda's reach, the scale of the real plate's placements
#: the real plate's placements: (hole-0 centre [m], direction to hole-1, seat axis out of the seat), the
#: Panda's shoulder at 0.333 m (sim_seats_study.PLACES)
PANDA_PLACES = {"front": ([0.383, 0.003, 0.001], [0, -1, 0], [0, 0, 1]),
                "right": ([0.382, 0.432, 0.007], [0, 1, 0], [0, 0, 1]),
                "back-high": ([-0.450, -0.009, 0.880], [0, 1, 0], [1, 0, 0])}


def _robot_set() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "aacmm-toolkit" / "example-robot-data-4.1.0" / "robots"


@dataclass(frozen=True)
class ZooArm:
    """A robot type of the zoo: its ball tool (:class:`sim_seats_study.ArmSpec`) and its reach [m]."""
    spec: seats.ArmSpec
    reach_m: float


ARMS = {
    "panda": ZooArm(seats.ARMS["panda"], 0.855),
    "iiwa14": ZooArm(seats.ARMS["iiwa14"], 0.82),
    "gen3": ZooArm(seats.ARMS["gen3"], 0.902),
    "ur5": ZooArm(seats.ArmSpec("ur5", "tool0", (0.0004, 0.0003, 0.125), 0.089159,
                          "example-robot-data 4.1.0, robots/ur_description/urdf/ur5_robot.urdf (UR5, 6 joints)"), 0.85),
}


@dataclass(frozen=True)
class ZooRobot:
    """One simulated robot of a type of :data:`ARMS`: its hidden truth (besides the scatter, the Panda's)."""
    name: str
    arm: str
    seed: int
    origins: tuple = (500.0, 1.0)         # 1 sigma of the joint-origin errors [um], [mrad]
    stiffness: float | list = 15000.0     # joint stiffness under gravity [N m/rad]
    encoder_urad: float = 10.0            # encoder noise, 1 sigma [urad]
    drift_um: float = 100.0               # the plate's drift over a placement's capture [um]

    def truth_text(self, noise_um: float) -> str:
        k = (f"{self.stiffness / 1e3:.0f}" if np.ndim(self.stiffness) == 0
             else "/".join(f"{s / 1e3:.0f}" for s in self.stiffness))
        return (f"origins {self.origins[0]:.0f} um / {self.origins[1]:.2f} mrad, stiffness {k} kN m/rad, "
                f"noise {noise_um:.0f} um, encoders {self.encoder_urad:.0f} urad, drift {self.drift_um:.0f} um")


ROBOTS = (
    ZooRobot("panda-a", "panda", 51, (500.0, 1.0), 12000.0),
    ZooRobot("iiwa-a", "iiwa14", 52, (500.0, 1.0), [30000, 20000, 25000, 15000, 10000, 10000, 8000]),
    ZooRobot("gen3-a", "gen3", 53, (500.0, 1.0), [10000, 6000, 8000, 5000, 3000, 3000, 3000]),
    ZooRobot("ur5-a", "ur5", 54, (500.0, 1.0), [30000, 20000, 15000, 5000, 5000, 5000]),
    ZooRobot("panda-b", "panda", 61, (1000.0, 2.0), 8000.0, drift_um=200.0),
    ZooRobot("iiwa-b", "iiwa14", 62, (1000.0, 2.0), 15000.0, drift_um=200.0),
    ZooRobot("gen3-b", "gen3", 63, (1000.0, 2.0), 5000.0, drift_um=200.0),
    ZooRobot("ur5-b", "ur5", 64, (1000.0, 2.0), 12000.0, drift_um=200.0),
    # stiff joints (the real Panda's compliance buys 15 % of spread, the simulated ones' above 3x), large origin
    # errors (the real Panda's nominal spreads its seats over 17-22 mm) and a drift of the real trend's size
    ZooRobot("panda-c", "panda", 71, (1000.0, 3.0), 60000.0, drift_um=500.0),
    ZooRobot("iiwa-c", "iiwa14", 72, (1000.0, 3.0), 80000.0, drift_um=500.0),
    ZooRobot("gen3-c", "gen3", 73, (1000.0, 3.0), 30000.0, drift_um=500.0),
    ZooRobot("ur5-c", "ur5", 74, (1000.0, 3.0), 80000.0, drift_um=500.0),
)


def places(arm: ZooArm) -> dict:
    """placement -> (hole-0 centre [m], direction to hole-1, seat axis) for ``arm``: the real plate's, its
    horizontal distances scaled by the arm's reach over the Panda's, on the base's plane at ``front`` and ``right``,
    ``back-high`` as high above the shoulder (scaled) as the Panda's."""
    r, s = arm.reach_m / PANDA_REACH, arm.spec.shoulder_m
    out = {}
    for name, (p, d, axis) in PANDA_PLACES.items():
        x, y, z = p
        z = s + (z - 0.333) * r if name == "back-high" else z
        out[name] = ([x * r, y * r, z], d, axis)
    return out


def panda_scatter(out: Path) -> float:
    """The real Panda's probing scatter [m], 1 sigma per axis: the seat noise default ``calibrate`` (through the
    Python API, the URDF's joint compliance) finds in each placement alone, their mean."""
    from arm_model.effects import JointCompliance
    from arm_model.io import read_artefacts, read_points
    from arm_model.model import ArmModel
    from arm_model.urdf_import import load_arm
    from calibration import FitOptions, calibrate, make_data
    desc = load_arm(URDF, TIP)
    model = ArmModel(desc, (JointCompliance(gravity=True),))
    art = read_artefacts(PANDA_DATA / "artefacts.toml")
    sig = []
    for pl in PANDA_PLACES:
        res = calibrate(model, make_data(read_points(PANDA_DATA / pl / "points.csv", 7), art, model),
                        FitOptions(weights_from_data=True))
        sig.append(next(v["sigma_um"] for v in res.variance if v["group"] == "seat"))
    out.mkdir(parents=True, exist_ok=True)
    (out / "panda-scatter.json").write_text(json.dumps({"sigma_um": sig}) + "\n")
    return float(np.mean(sig)) * 1e-6


def sweep_order(q: np.ndarray) -> np.ndarray:
    """Indices of the poses ``q`` (N, J) [rad] in a sweep: from the pose with the smallest first joint, each next the
    nearest in joint space not yet taken (a hand-guided sweep's order; the simulator draws them at random)."""
    left = list(range(len(q)))
    order = [left.pop(int(np.argmin(q[:, 0])))]
    while left:
        d = np.linalg.norm(q[left] - q[order[-1]], axis=1)
        order.append(left.pop(int(np.argmin(d))))
    return np.array(order)


def campaign_dict(robot: ZooRobot, noise_m: float) -> dict:
    """The simulator's campaign of ``robot``: its truth and the two seats of each placement (``<place>.<hole>``)."""
    tasks = []
    for place, (p, d, axis) in places(ARMS[robot.arm]).items():
        for h, off in zip(HOLES, (0.0, LENGTH), strict=True):
            c = np.asarray(p, float) + off * np.asarray(d, float)
            tasks.append({"kind": "seat", "id": f"{place}.{h}", "axis": axis, "articulations": 30,
                          "position_mm": (c * 1e3).tolist(), "stylus_cone_deg": 50.0})
    truth = {"length_error_um": robot.origins[0], "angle_error_deg": float(np.degrees(robot.origins[1] * 1e-3)),
             "probe_error_um": 1000.0, "probe_compliance": {"bending_um_per_N": 0.0, "axial_um_per_N": 0.0},
             "joint_compliance": {"stiffness_Nm_per_rad": robot.stiffness, "gravity": True, "contact": False}}
    noise = {"probing_repeatability_um": noise_m * 1e6,
             "encoder_noise_deg": float(np.degrees(robot.encoder_urad * 1e-6))}
    return {"seed": robot.seed, "sensor": "none", "signals": {"enabled": False}, "truth": truth, "noise": noise,
            "operator": {"force_mean_N": 0.3, "max_force_N": 1.0}, "task": tasks}


def _truth_centres(model, p, q: np.ndarray) -> np.ndarray:
    """(N, 3) [m] the truth's ball centres at the joint angles ``q``, sagging under gravity."""
    from arm_model import PinocchioArm
    from arm_model.model import AuxData
    aux = AuxData(None, *PinocchioArm(model.desc).torques(q, None))
    return model.ball_centres(q, None, p, aux)


def _drifted(model, p, q: np.ndarray, shift: np.ndarray) -> np.ndarray:
    """``q`` (N, J) [rad] moved so that the truth's ball centres move by ``shift`` (N, 3) [m] (one Gauss-Newton step
    with the truth's own Jacobian by central differences: exact to second order in a sub-millimetre shift)."""
    h = 1e-6
    jac = np.stack([(_truth_centres(model, p, q + h * e) - _truth_centres(model, p, q - h * e)) / (2 * h)
                    for e in np.eye(q.shape[1])], axis=2)
    return q + np.einsum("nij,nj->ni", np.linalg.pinv(jac), shift)


def simulate_robot(robot: ZooRobot, urdf: Path, folder: Path, noise_m: float) -> dict:
    """Write ``folder/<placement>/points.csv`` (hole-0's poses swept, then hole-1's, the plate drifting) and
    ``folder/artefacts.toml``; return the truth's own figures per placement (the hidden model on the readings)."""
    from arm_model.sim import campaign_from_dict, simulate
    from arm_model.urdf_import import load_arm
    sim = simulate(campaign_from_dict(campaign_dict(robot, noise_m), arm=load_arm(urdf, TIP)))
    model, p = sim.truth["model"], sim.truth["p_vector"]
    q, feature = sim.points.q, np.asarray(sim.points.feature)
    rng = np.random.default_rng(robot.seed + 1000)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "artefacts.toml").write_text(
        "".join(f'[[feature]]\nid = "{h}"\nkind = "seat"\n\n' for h in HOLES)
        + f'[[distance]]\nbetween = ["{HOLES[0]}", "{HOLES[1]}"]\nlength_mm = {LENGTH * 1e3}\nu_length_mm = 0.05\n')
    figures, moves = {}, {}
    for pl in PANDA_PLACES:
        idx = np.concatenate([np.flatnonzero(feature == f"{pl}.{h}")[sweep_order(q[feature == f"{pl}.{h}"])]
                              for h in HOLES])
        direction = rng.normal(size=3)
        shift = np.outer(np.linspace(0.0, 1.0, len(idx)), direction / np.linalg.norm(direction)) * robot.drift_um * 1e-6
        qp = _drifted(model, p, q[idx], shift) if robot.drift_um else q[idx]
        holes = np.array([f.split(".", 1)[1] for f in feature[idx]])
        (folder / pl).mkdir(exist_ok=True)
        lines = ["measurement,feature," + ",".join(f"q{j + 1}_rad" for j in range(q.shape[1]))]
        lines += [f"{pl},{h}," + ",".join(f"{v:.17g}" for v in row) for h, row in zip(holes, qp, strict=True)]
        (folder / pl / "points.csv").write_text("\n".join(lines) + "\n")
        figures[pl] = seat_figures(_truth_centres(model, p, qp), holes, HOLES, LENGTH)
        moves[pl] = float(np.median(np.linalg.norm(np.diff(qp, axis=0), axis=1)))
    return {"figures": figures, "step_rad": moves}


def least_squares_rows(data: Path, urdf: Path, train: list[str]) -> list[dict]:
    """The geometry by least squares (``FitOptions(prior_scale=None)``, the noise's weights from the data) trained
    on each placement of ``train``, its figures on the others (rows as :meth:`PlacementRow.to_dict`)."""
    from arm_model.io import read_artefacts, read_points
    from arm_model.model import ArmModel
    from arm_model.urdf_import import load_arm
    from calibration import FitOptions, calibrate, make_data
    desc = load_arm(urdf, TIP)
    model = ArmModel(desc, ())
    art = read_artefacts(data / "artefacts.toml")
    sets = {pl: make_data(read_points(data / pl / "points.csv", desc.n_joints), art, model) for pl in PANDA_PLACES}
    rows = []
    for tr in train:
        res = calibrate(model, sets[tr], FitOptions(weights_from_data=True, prior_scale=None))
        for te, d in sets.items():
            if te != tr:
                x = model.ball_centres(d.points.q, d.wrench, res.p, d.aux)
                rows.append({"train": tr, "method": "least-squares", "test": te, "effects": [],
                             **seat_figures(x, d.points.feature, HOLES, LENGTH)})
    return rows


LOOP_SEEDS = (0, 1, 2)


#: the methods of ``--methods``: the nominal, the commands with their defaults (the loop at each of LOOP_SEEDS), and
#: with ``--region-effect`` (calibration/region.py; the loop at seed 0)
METHODS = ("nominal", "calibrate") + tuple(f"close-loop@{s}" for s in LOOP_SEEDS)
REGION_METHODS = ("calibrate-region", "close-loop-region")


def study_robot(robot: ZooRobot, urdfs: tuple[Path, Path], out: Path, noise_m: float, train: list[str],
                variants: list[str], say, methods=METHODS) -> dict:
    """Simulate ``robot`` on ``urdfs[0]`` (its URDF with masses and the ball tool), run every method of ``methods``
    (:data:`METHODS`, :data:`REGION_METHODS`) from the nominal ``urdfs[1]`` (the same, or without ``<inertial>``)
    trained on each placement of ``train``, and each threshold variant (``NAME=VALUE`` of calibration/prior.py)."""
    import calibration.prior as prior
    sim = simulate_robot(robot, urdfs[0], out / "data", noise_m)
    urdf = urdfs[1]
    options = {**{f"close-loop@{s}": ["--seed", str(s)] for s in LOOP_SEEDS},
               "calibrate-region": ["--region-effect"], "close-loop-region": ["--region-effect"]}
    rows = [r.to_dict() for r in placement_study(out / "data", urdf, TIP, out / "runs", train=train, progress=say,
                                                 methods=tuple(methods), options=options)]
    rows += least_squares_rows(out / "data", urdf, train)
    for v in variants:
        name, _, value = v.partition("=")
        before = getattr(prior, name)
        setattr(prior, name, type(before)(value))
        try:
            got = placement_study(out / "data", urdf, TIP, out / f"runs-{name}-{value}", train=train, progress=say,
                                  methods=("calibrate", "close-loop@0"), options={"close-loop@0": ["--seed", "0"]})
        finally:
            setattr(prior, name, before)
        rows += [{**r.to_dict(), "method": f"{r.method} {v}"} for r in got]
    return {"robot": robot.name, "arm": robot.arm, "truth_text": robot.truth_text(noise_m * 1e6),
            "truth": sim["figures"], "step_rad": sim["step_rad"], "rows": rows}


def summary(results: list[dict]) -> list[dict]:
    """Per robot and method: mean held-out spread and |distance error| [mm] over its predictions, the pooled coverage
    of u and of the deviation's u [%], and per loop seed the effects added on each training placement."""
    out = []
    for r in results:
        line = {"robot": r["robot"], "arm": r["arm"], "truth_text": r["truth_text"], "methods": {},
                "truth": {"spread_mm": float(np.mean([f["spread_mean_mm"] for f in r["truth"].values()]))}}
        for m in dict.fromkeys(x["method"] for x in r["rows"]):
            fs = [x for x in r["rows"] if x["method"] == m]
            v = {"spread_mm": float(np.mean([f["spread_mean_mm"] for f in fs])),
                 "distance_mm": float(np.mean([abs(f["distance_error_mm"]) for f in fs])),
                 "predictions": len(fs)}
            for key, name in (("inside", "coverage"), ("inside_dev", "coverage_dev")):
                if all(key in f for f in fs):
                    v[name] = 100.0 * sum(f[key] for f in fs) / sum(f["values"] for f in fs)
            if m.startswith("close-loop"):
                v["added"] = {f["train"]: f["effects"] for f in fs}
            line["methods"][m] = v
        out.append(line)
    return out


def table(lines: list[dict]) -> str:
    """Markdown of :func:`summary`: one row per robot, the truth's own spread (the scatter's floor), spread /
    |distance error| per method, the coverage of the deviation's u of ``calibrate`` and ``close-loop@0``, the
    loop's effects at each seed."""
    cols = list(dict.fromkeys(m for ln in lines for m in ln["methods"] if not m.startswith("close-loop@")
                              or m == "close-loop@0"))
    md = ["| robot | truth | truth's spread | " + " | ".join(cols) + " | u covers (calibrate / loop) [%] | loop added "
          "(seeds " + "/".join(map(str, LOOP_SEEDS)) + ") |", "|---|---|---:|" + "---:|" * len(cols) + "---|---|"]
    for ln in lines:
        ms = ln["methods"]
        cells = [f"{ln['truth']['spread_mm']:.3f}"]
        cells += [f"{ms[c]['spread_mm']:.3f} / {ms[c]['distance_mm']:.3f}" if c in ms else "-" for c in cols]
        cov = " / ".join(f"{ms[m]['coverage_dev']:.1f}" if "coverage_dev" in ms.get(m, {}) else "-"
                         for m in ("calibrate", "close-loop@0"))
        added = [ms[f"close-loop@{s}"]["added"] for s in LOOP_SEEDS if f"close-loop@{s}" in ms]
        same = all(a == added[0] for a in added)
        eff = "; ".join(f"{t}: {', '.join(e) or '-'}" for t, e in added[0].items()) if added else "-"
        md.append(f"| {ln['robot']} | {ln['truth_text']} | " + " | ".join(cells) + f" | {cov} | {eff}"
                  + (" (the same at every seed)" if same else " (NOT the same at every seed)") + " |")
    return "\n".join(md)


def arm_files(names: list[str], specs: list[str], python: str | None, out: Path) -> dict:
    """robot type -> its URDF with the ball tool (with its masses, without ``<inertial>``), written under ``out``."""
    arms = {ARMS[n].spec.name for n in names}
    shipped = seats.shipped_files([s for s in specs if not s.startswith("ur5=")], python, arms - {"panda", "ur5"})
    ur5 = [s.partition("=")[2] for s in specs if s.startswith("ur5=")]
    shipped["ur5"] = Path(ur5[0]) if ur5 else _robot_set() / "ur_description" / "urdf" / "ur5_robot.urdf"
    return {a: seats.nominal_urdfs(ARMS[a].spec, shipped.get(a), out / "arms" / a) for a in arms}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--robots", default=None, help="comma-separated robot names (default every one: "
                   + ", ".join(f"{r.name}" for r in ROBOTS) + ")")
    p.add_argument("--trains", default=",".join(PANDA_PLACES), help="comma-separated training placements")
    p.add_argument("--variants", default="", help="comma-separated NAME=VALUE of calibration/prior.py thresholds "
                   "(BARELY_SEEN=0.5, MIN_SIDE_VISITS=2, ...): calibrate and close-loop --seed 0 re-run with each")
    p.add_argument("--urdf", action="append", default=[], metavar="ARM=PATH",
                   help="an arm's URDF as shipped (gen3: Kinova ros_kortex's GEN3_URDF_V12.urdf; iiwa14: pybullet's "
                   "kuka_iiwa/model.urdf; ur5: default example-robot-data 4.1.0 in the tests' cache)")
    p.add_argument("--python", default=None, help="the Python of an environment with pybullet (the iiwa's URDF)")
    p.add_argument("--noise-um", type=float, default=None,
                   help="probing scatter, 1 sigma per axis [um] (default: the real Panda's, panda_scatter)")
    p.add_argument("--nominal", choices=("masses", "no-inertials"), default="masses",
                   help="the nominal URDF the methods start from: with its link masses, or without <inertial> (the "
                   "truth always sags under the masses)")
    p.add_argument("--methods", default=",".join(METHODS),
                   help="comma-separated methods (default: " + ", ".join(METHODS) + "; also "
                   + ", ".join(REGION_METHODS) + ": the commands with --region-effect)")
    p.add_argument("-o", "--output", type=Path, default=Path("out/seat-zoo"), help="output folder")
    args = p.parse_args(argv)
    known = {r.name: r for r in ROBOTS}
    names = args.robots.split(",") if args.robots else list(known)
    if unknown := [n for n in names if n not in known]:
        p.error(f"unknown robot(s): {', '.join(unknown)}")
    def say(m):
        print("  " + m, file=sys.stderr, flush=True)
    noise = args.noise_um * 1e-6 if args.noise_um else panda_scatter(args.output)
    print(f"probing scatter {noise * 1e6:.0f} um per axis", file=sys.stderr, flush=True)
    urdfs = arm_files([known[n].arm for n in names], args.urdf, args.python, args.output)
    variants = [v for v in args.variants.split(",") if v]
    results = []
    for n in names:
        robot = known[n]
        print(f"{n} ({robot.arm}): {robot.truth_text(noise * 1e6)}", file=sys.stderr, flush=True)
        files = urdfs[robot.arm]
        results.append(study_robot(robot, (files[0], files[0] if args.nominal == "masses" else files[1]),
                                   args.output / n, noise, args.trains.split(","),
                                   variants, say, args.methods.split(",")))
        (args.output / "results.json").write_text(json.dumps(results, indent=1) + "\n")
    lines = summary(results)
    (args.output / "results.json").write_text(json.dumps({"noise_um": noise * 1e6, "nominal": args.nominal,
                                                          "robots": results,
                                                          "summary": lines}, indent=1) + "\n")
    md = table(lines)
    (args.output / "table.md").write_text(md + "\n")
    print(md)
    return 0


if __name__ == "__main__":
    sys.exit(main())
