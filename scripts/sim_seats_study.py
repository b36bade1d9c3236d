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
* ``drift`` (asked by ``--methods``): ``calibrate --effect joint_compliance --effect artefact_drift``,
* ``close-loop-drift`` (asked by ``--methods``): ``close-loop --effect joint_compliance --effect artefact_drift``,
* ``calibrate-region``, ``close-loop-region`` (asked by ``--methods``): the commands with ``--region-effect``,
* ``truth``: the hidden truth applied to the same readings (the figures' floor: the scatter alone, and with
  ``--capture sweep-drift`` the plate's creep).

``--capture sweep`` takes each seat's poses in a sweep round it (the real files' order), ``sweep-drift`` also lets
the plate creep at a constant velocity (0.3-0.8 mm over a placement, drawn per robot): a known truth for the
capture-order trend of the real data (docs/studies/calibration.md).

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
PANDA_SHOULDER = 0.333   # [m] height of the Panda's shoulder (joint 2's axis) above its base: PLACES are for it


@dataclass(frozen=True)
class ArmSpec:
    """A robot type: where its URDF comes from (as its maker or a package ships it, never copied here), the link
    a ball tool is fixed to and where the ball sits in that link's frame, as the seat data set's tools are, and
    the height of its shoulder (joint 2's axis) [m], so that each plate placement keeps its place relative to the
    shoulder (:data:`PLACES` are the Panda's)."""
    name: str
    flange: str | None                    # None: the file has its ball_link (the Panda of the data set)
    tool_m: tuple = (0.0, 0.0, 0.0)       # ball centre in the flange frame [m]
    shoulder_m: float = PANDA_SHOULDER
    source: str = ""                      # where the shipped file is found
    package: tuple | None = None          # (Python package, file under it) that ships it


ARMS = {
    "panda": ArmSpec("panda", None, source="examples/data/real-panda-seats (the data set's own)"),
    "iiwa14": ArmSpec("iiwa14", "lbr_iiwa_link_7", (0.0004, -0.0003, 0.131), 0.36,
                      "pybullet 3.2.7, pybullet_data/kuka_iiwa/model.urdf (KUKA LBR iiwa 14 R820)",
                      ("pybullet_data", "kuka_iiwa/model.urdf")),
    "gen3": ArmSpec("gen3", "EndEffector_Link", (0.0003, 0.0002, 0.098), 0.15643 + 0.12838,
                    "Kinova's ros_kortex, kortex_description/arms/gen3/7dof/urdf/GEN3_URDF_V12.urdf (Gen3, 7 joints)"),
}


def ball_urdf(text: str, arm: ArmSpec) -> str:
    """The shipped URDF ``text`` with a ball tool: link ``ball_link`` fixed to ``arm.flange`` at ``arm.tool_m``
    (a visual sphere of 5 mm radius, as the data set's), and one more fixed link after it (a tool's cap: the
    tip is not a leaf). Everything else stays as shipped."""
    x, y, z = arm.tool_m
    tool = (f'  <link name="ball_link">\n    <visual>\n      <geometry>\n        <sphere radius="0.005"/>\n'
            f'      </geometry>\n    </visual>\n  </link>\n'
            f'  <joint name="ball_joint" type="fixed">\n    <origin rpy="0 0 0" xyz="{x} {y} {z}"/>\n'
            f'    <parent link="{arm.flange}"/>\n    <child link="ball_link"/>\n  </joint>\n'
            f'  <link name="ball_cap"/>\n  <joint name="ball_cap_joint" type="fixed">\n'
            f'    <origin rpy="0 0 0" xyz="0 0 0.005"/>\n    <parent link="ball_link"/>\n'
            f'    <child link="ball_cap"/>\n  </joint>\n')
    end = text.rindex("</robot>")
    return text[:end] + tool + text[end:]


def without_inertials(text: str) -> str:
    """``text`` with every ``<inertial>`` block removed (a nominal URDF as the data set ships it)."""
    import re
    return re.sub(r"\s*<inertial>.*?</inertial>", "", text, flags=re.S)


def nominal_urdfs(arm: ArmSpec, shipped: Path | None, folder: Path) -> tuple[Path, Path]:
    """(the URDF with its masses, the same without ``<inertial>``) of ``arm`` with the ball tool; for a shipped
    file, both written into ``folder``."""
    if arm.flange is None:
        return URDF, URDF.with_name("panda.urdf")
    if shipped is None:
        raise SystemExit(f"arm {arm.name}: give its URDF (--urdf {arm.name}=PATH; {arm.source})")
    folder.mkdir(parents=True, exist_ok=True)
    text = ball_urdf(Path(shipped).read_text(), arm)
    out = folder / f"{arm.name}-ball.urdf", folder / f"{arm.name}-ball-no-inertials.urdf"
    out[0].write_text(text)
    out[1].write_text(without_inertials(text))
    return out
HOLES = ("hole-0", "hole-1")
LENGTH = 0.05            # [m] certified distance between the seats
#: placement -> (hole-0 centre [m], direction to hole-1, seat axis out of the seat), as the real plate's
#: (the real seats' centres through the nominal URDF; the tool points down at front/right, along -x at back-high)
PLACES = {"front": ([0.383, 0.003, 0.001], [0, -1, 0], [0, 0, 1]),
          "right": ([0.382, 0.432, 0.007], [0, 1, 0], [0, 0, 1]),
          "back-high": ([-0.450, -0.009, 0.880], [0, 1, 0], [1, 0, 0])}
METHODS = ("close-loop", "calibrate", "geometry", "nominal-tip", "oracle")
#: methods run when asked (``--methods``): ``drift``, calibrate with the artefact's drift beside the joint compliance;
#: ``close-loop-drift``, close-loop from that base model; ``calibrate-region`` and ``close-loop-region``, the commands
#: with ``--region-effect`` (calibration/region.py)
EXTRA_METHODS = ("drift", "close-loop-drift", "calibrate-region", "close-loop-region")
#: how the seats' articulations are captured (``--capture``): in random order; in sweeps (each seat's poses in turn
#: round it, as a robot program takes them, the real files' order); in sweeps while the plate creeps; in random order
#: while it creeps (the creep then unlike any pose's error)
CAPTURES = ("random", "sweep", "sweep-drift", "random-drift")
#: the plate's creep over one placement's capture of ``sweep-drift`` [mm]: drawn per robot (its seed) in this range,
#: in a random direction; the real Panda's capture-order trends are 0.4-0.75 mm a placement
DRIFT_MM = (0.3, 0.8)


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
    arm: str = "panda"                    # a key of ARMS
    encoder_noise_urad: float = 0.0       # encoder noise, 1 sigma per reading [urad]

    def truth_text(self) -> str:
        out = [f"origins {self.length_um:.0f} um / {self.angle_mrad:.2f} mrad"]
        if self.stiffness is None:
            out.append("rigid joints")
        elif np.ndim(self.stiffness) == 0:
            out.append(f"stiffness {self.stiffness / 1e3:.0f} kN m/rad")
        else:
            out.append("stiffness " + "/".join(f"{k / 1e3:.0f}" for k in self.stiffness) + " kN m/rad")
        for e in self.eccentricity:
            out.append(f"eccentricity j{joint_number(e['joint'])} {e['amplitude_mrad']} mrad")
        for j, g in self.gain.items():
            out.append(f"gain j{j + 1} {g:.0e}")
        out.append(f"noise {self.noise_um:.0f} um")
        if self.encoder_noise_urad:
            out.append(f"encoders {self.encoder_noise_urad:.0f} urad")
        return ", ".join(out)


def joint_number(joint) -> int:
    """1-based joint number of an eccentricity's ``joint``: a number, or a name ending in one (``panda_joint3``)."""
    import re
    return int(joint) if isinstance(joint, int) else int(re.findall(r"\d+", joint)[-1])


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
#: robots of the other types of ARMS (their URDFs as shipped, given by --urdf / --python): origins off by 0.1-1 mm and
#: 0.5-2 mrad, play 0.1-0.3 mm, encoder noise
OTHER_ROBOTS = (
    Robot("i1", "front", 31, 500.0, 1.0, 150.0, stiffness=20000.0, arm="iiwa14", encoder_noise_urad=10.0),
    Robot("i2", "right", 32, 800.0, 1.5, 250.0, stiffness=[30000, 20000, 25000, 15000, 10000, 10000, 8000],
          eccentricity=({"joint": 1, "amplitude_mrad": 0.5, "phase_deg": 45.0},), arm="iiwa14",
          encoder_noise_urad=20.0),
    Robot("i3", "back-high", 33, 200.0, 0.5, 100.0, arm="iiwa14", encoder_noise_urad=5.0),
    Robot("g1", "front", 41, 500.0, 1.0, 200.0, stiffness=8000.0, arm="gen3", encoder_noise_urad=10.0),
    Robot("g2", "right", 42, 1000.0, 2.0, 300.0, stiffness=[10000, 6000, 8000, 5000, 3000, 3000, 3000],
          arm="gen3", encoder_noise_urad=20.0),
    Robot("g3", "back-high", 43, 100.0, 0.5, 150.0, arm="gen3",
          eccentricity=({"joint": 2, "amplitude_mrad": 0.6, "phase_deg": -30.0},), encoder_noise_urad=5.0),
)


def drift_velocity(robot: Robot, period_s: float, articulations: int) -> np.ndarray:
    """(3,) [m/s] the plate's creep of ``sweep-drift`` (:data:`DRIFT_MM` over one placement's ``2 articulations``
    points, one every ``period_s``), drawn from the robot's seed."""
    rng = np.random.default_rng([robot.seed, 7])
    d = rng.normal(size=3)
    size = rng.uniform(*DRIFT_MM) * 1e-3
    return d / np.linalg.norm(d) * size / (2 * articulations * period_s)


def campaign_dict(robot: Robot, joints: list[str] | None = None, capture: str = "random") -> dict:
    """The simulator's campaign: the truth and two seats a placement (feature ids ``<place>.<hole>``); ``joints``:
    the arm's joint names (an eccentricity's joint given by number); ``capture``: one of :data:`CAPTURES` (a sweep
    takes the next seat at once, a point period later: the capture's time follows the rows)."""
    tasks = []
    lift = ARMS[robot.arm].shoulder_m - PANDA_SHOULDER
    for place, (p, d, axis) in PLACES.items():
        for h, off in zip(HOLES, (0.0, LENGTH), strict=True):
            c = np.asarray(p, float) + off * np.asarray(d, float) + [0.0, 0.0, lift]
            tasks.append({"kind": "seat", "id": f"{place}.{h}", "axis": axis, "articulations": 30,
                          "position_mm": (c * 1e3).tolist(), "stylus_cone_deg": 50.0,
                          "order": "sweep" if capture.startswith("sweep") else "random"})
    truth = {"length_error_um": robot.length_um, "angle_error_deg": float(np.degrees(robot.angle_mrad * 1e-3)),
             "probe_error_um": 1000.0,
             "probe_compliance": {"bending_um_per_N": 0.0, "axial_um_per_N": 0.0}}    # a rigid tool
    if robot.stiffness is not None:
        truth["joint_compliance"] = {"stiffness_Nm_per_rad": robot.stiffness, "gravity": True, "contact": False}
    if robot.eccentricity:
        truth["eccentricity"] = [{"joint": e["joint"] if joints is None else joints[joint_number(e["joint"]) - 1],
                                  "amplitude_deg": float(np.degrees(e["amplitude_mrad"] * 1e-3)),
                                  "phase_deg": e["phase_deg"]} for e in robot.eccentricity]
    noise = {"probing_repeatability_um": robot.noise_um}
    if robot.encoder_noise_urad:
        noise["encoder_noise_deg"] = float(np.degrees(robot.encoder_noise_urad * 1e-6))
    operator = {"force_mean_N": 0.3, "max_force_N": 1.0}
    out = {"seed": robot.seed, "sensor": "none", "signals": {"enabled": False}, "truth": truth, "noise": noise,
           "operator": operator, "task": tasks}
    if capture != "random":
        period = 1.2
        operator.update(point_period_s=period, measurement_gap_s=period)
    if capture.endswith("-drift"):
        v = drift_velocity(robot, 1.2, 30)
        out["environment"] = {"artefact_drift_mm_per_h": (v * 1e3 * 3600).tolist()}
    return out


def simulate_robot(robot: Robot, folder: Path, urdf: Path = URDF, capture: str = "random") -> dict:
    """Write ``folder/<placement>/points.csv`` and ``folder/artefacts.toml``; return the truth's own figures
    per placement (the hidden model on the same readings) and its parameters."""
    from arm_model import PinocchioArm
    from arm_model.model import AuxData
    from arm_model.sim import campaign_from_dict, simulate
    from arm_model.urdf_import import load_arm

    desc = load_arm(urdf, TIP)
    sim = simulate(campaign_from_dict(campaign_dict(robot, [j.name for j in desc.encoders], capture), arm=desc))
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
           "drift": ["--effect", "joint_compliance", "--effect", "artefact_drift"],
           "close-loop-drift": ["--effect", "joint_compliance", "--effect", "artefact_drift"],
           "calibrate-region": ["--region-effect"], "close-loop-region": ["--region-effect"],
           "nominal-tip": ["--effect", "none", "--free", "probe.x", "--free", "probe.y", "--free", "probe.z"]}


def oracle_options(robot: Robot, joints: list[str] | None = None) -> list[str]:
    """``calibrate`` options of the truth's own effects (each effect's parameters on the truth's joints only);
    ``joints``: the arm's joint names (default the Panda's)."""
    joints = joints or [f"panda_joint{j}" for j in range(1, 8)]
    out = ["--effect", "joint_compliance"] if robot.stiffness is not None else []
    for key, numbers, pattern in (("eccentricity", {joint_number(e["joint"]) for e in robot.eccentricity}, "ecc*"),
                                  ("joint_gain", {j + 1 for j in robot.gain}, "gain")):
        if numbers:
            out += ["--effect", key] + [a for k, name in enumerate(joints, 1) if k not in numbers
                                        for a in ("--hold", f"{name}.{pattern}")]
    return out or ["--effect", "none"]


def loop_seeds(methods) -> dict:
    """Options of the seeded loop methods: ``close-loop@S`` runs ``close-loop --seed S``."""
    return {m: ["--seed", m.split("@", 1)[1]] for m in methods if m.startswith("close-loop@")}


def study_robot(robot: Robot, out: Path, methods=METHODS, train=None, progress=None, shipped: Path | None = None,
                nominal: str = "masses", capture: str = "random") -> dict:
    """Simulate ``robot``, train every method on its training placement (``train``: these placements
    instead), predict the others. ``shipped``: the arm's URDF as shipped (not the Panda); ``nominal``: the
    nominal every method starts from, the URDF with its masses (``masses``) or without ``<inertial>``
    (``no-inertials``); the truth is always simulated with the masses (a real arm sags); ``capture``: one of
    :data:`CAPTURES`."""
    from arm_model.urdf_import import load_arm
    with_masses, bare = nominal_urdfs(ARMS[robot.arm], shipped, out / "arm")
    truth = simulate_robot(robot, out / "data", with_masses, capture)
    joints = [j.name for j in load_arm(with_masses, TIP).encoders]
    train = train or [robot.train]
    rows = placement_study(out / "data", with_masses if nominal == "masses" else bare, TIP, out / "runs",
                           train=train, progress=progress, methods=tuple(methods),
                           options={**OPTIONS, "oracle": oracle_options(robot, joints), **loop_seeds(methods)})
    return {"robot": robot.name, "arm": robot.arm, "nominal": nominal, "capture": capture,
            "truth_text": robot.truth_text(),
            "train": "/".join(train), "truth": truth["figures"], "rows": [r.to_dict() for r in rows]}


def _methods(rows: list[dict]) -> list[str]:
    """The methods of ``rows`` in :data:`METHODS` order, the seeded loops and the plain nominal first."""
    got = list(dict.fromkeys(x["method"] for x in rows))
    order = ["nominal"] + [m for m in got if m.startswith("close-loop")] + list(METHODS + EXTRA_METHODS)
    return [m for m in dict.fromkeys(order) if m in got]


def summary_rows(results: list[dict]) -> list[dict]:
    """One row per robot and training placement: the effects each loop added (``added``: the first loop's;
    ``added_by``: per loop method, e.g. per ``--seed``) and, per method (and the truth on the same held-out
    placements), the mean held-out spread [mm], the mean |distance error| [mm] and the pooled coverage of u [%]."""
    out = []
    for r in results:
        for tr in dict.fromkeys(x["train"] for x in r["rows"]):
            rows = [x for x in r["rows"] if x["train"] == tr]
            tests = list(dict.fromkeys(x["test"] for x in rows))
            methods = _methods(rows)
            figs = {"truth": [r["truth"][t] for t in tests]}
            figs.update({m: [x for x in rows if x["method"] == m] for m in methods})
            added_by = {m: next(x["effects"] for x in rows if x["method"] == m)
                        for m in methods if m.startswith("close-loop")}
            line = {"robot": r["robot"], "arm": r.get("arm", "panda"), "nominal_file": r.get("nominal", "masses"),
                    "truth_text": r["truth_text"], "train": tr, "tests": tests, "methods": methods,
                    "added": next(iter(added_by.values()), []), "added_by": added_by}
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


def _short(effect: str) -> str:
    """An effect's name with a joint's name shortened to its number (``eccentricity j1``)."""
    import re
    return re.sub(r"\b[A-Za-z_]+?_?(\d+)\b", lambda m: f"j{m.group(1)}", effect)


def summary_table(lines: list[dict]) -> str:
    """Markdown of :func:`summary_rows`: the first loop method's effects, whether every loop method (seed) added
    the same, and per method the spread, the distance error and the coverage."""
    cols = ["truth"] + list(dict.fromkeys(m for ln in lines for m in ln["methods"]))
    head = (f"| robot | truth | trained on | loop added | same at every seed | spread 2σ [mm]: {' / '.join(cols)} "
            f"| abs. distance error [mm]: {' / '.join(cols)} | within 1.96 u [%]: {' / '.join(cols[1:])} "
            f"| within 1.96 u of the deviation [%]: {' / '.join(cols[1:])} |")
    md = [head, "|---|---|---|---|---|---|---|---|---|"]
    def val(ln, m, k, fmt):
        return fmt.format(ln[m][k]) if m in ln and k in ln[m] else "-"
    for ln in lines:
        same = len({tuple(v) for v in ln["added_by"].values()}) <= 1
        md.append(f"| {ln['robot']} | {ln['truth_text']} | {ln['train']} | "
                  + (", ".join(_short(e) for e in ln["added"]) or "-") + " | "
                  + (f"{'yes' if same else 'NO'} ({len(ln['added_by'])})" if ln["added_by"] else "-") + " | "
                  + " / ".join(val(ln, m, "spread_mm", "{:.3f}") for m in cols) + " | "
                  + " / ".join(val(ln, m, "distance_mm", "{:.3f}") for m in cols) + " | "
                  + " / ".join(val(ln, m, "coverage", "{:.1f}") for m in cols[1:]) + " | "
                  + " / ".join(val(ln, m, "coverage_dev", "{:.1f}") for m in cols[1:]) + " |")
    return "\n".join(md)


def shipped_files(specs: list[str], python: str | None, arms: set) -> dict:
    """arm -> its URDF as shipped: ``NAME=PATH`` of ``--urdf``, else the file of the package that ships it, found in
    the environment of ``python`` (scripts/robot_zoo_study.py's look-up)."""
    out = {}
    for spec in specs:
        name, _, path = spec.partition("=")
        if name not in ARMS or not path:
            raise SystemExit(f"--urdf {spec}: expected NAME=PATH with NAME one of {', '.join(ARMS)}")
        out[name] = Path(path)
    wanted = {ARMS[a].package[0] for a in arms if a not in out and ARMS[a].package}
    if wanted:
        sys.path.insert(0, str(ROOT / "scripts"))
        from robot_zoo_study import package_dirs
        dirs = package_dirs(python, wanted)
        for a in arms:
            pkg = ARMS[a].package
            if a not in out and pkg and pkg[0] in dirs:
                out[a] = dirs[pkg[0]] / pkg[1]
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--robots", default=None, help="comma-separated robot names (default every Panda one: "
                   + ", ".join(r.name for r in ROBOTS) + "; other types: "
                   + ", ".join(f"{r.name} ({r.arm})" for r in OTHER_ROBOTS) + ")")
    p.add_argument("--methods", default=",".join(METHODS), help="comma-separated subset of "
                   + ", ".join(METHODS + EXTRA_METHODS)
                   + ", nominal (the nominal URDF applied as it is), close-loop@S (close-loop --seed S)")
    p.add_argument("--loop-seeds", default=None,
                   help="comma-separated seeds: close-loop is run once per seed (close-loop@S) in place of once")
    p.add_argument("--every-placement", action="store_true",
                   help="train each robot on each placement in turn (default: its own training placement)")
    p.add_argument("--nominal", choices=("masses", "no-inertials"), default="masses",
                   help="the nominal URDF the methods start from: with its link masses, or without <inertial> "
                   "(the truth always sags under the masses)")
    p.add_argument("--urdf", action="append", default=[], metavar="ARM=PATH",
                   help="the URDF of an arm of another robot type as shipped (" + "; ".join(
                       f"{a.name}: {a.source}" for a in ARMS.values() if a.flange) + ")")
    p.add_argument("--python", default=None, help="the Python of an environment where the packages shipping the "
                   "URDFs are installed (pybullet for iiwa14)")
    p.add_argument("--capture", choices=CAPTURES, default="random",
                   help="the seats' poses in random order, in sweeps, or in sweeps while the plate creeps by "
                   f"{DRIFT_MM[0]:g}-{DRIFT_MM[1]:g} mm a placement")
    p.add_argument("-o", "--output", type=Path, default=Path("out/sim-seats"), help="output folder")
    args = p.parse_args(argv)
    known = {r.name: r for r in ROBOTS + OTHER_ROBOTS}
    names = args.robots.split(",") if args.robots else [r.name for r in ROBOTS]
    unknown = [n for n in names if n not in known]
    if unknown:
        p.error(f"unknown robot(s): {', '.join(unknown)}")
    methods = args.methods.split(",")
    if args.loop_seeds:
        methods = [m for m in methods if m != "close-loop"] + [f"close-loop@{s}" for s in args.loop_seeds.split(",")]
    shipped = shipped_files(args.urdf, args.python, {known[n].arm for n in names} - {"panda"})
    results = []
    for n in names:
        robot = known[n]
        print(f"{n} ({robot.arm}): {robot.truth_text()}; trained on {robot.train}", file=sys.stderr, flush=True)
        results.append(study_robot(robot, args.output / n, methods,
                                   train=list(PLACES) if args.every_placement else None,
                                   progress=lambda m: print("  " + m, file=sys.stderr, flush=True),
                                   shipped=shipped.get(robot.arm), nominal=args.nominal, capture=args.capture))
        (args.output / "results.json").write_text(json.dumps(results, indent=1) + "\n")
    lines = summary_rows(results)
    (args.output / "summary.json").write_text(json.dumps(lines, indent=1) + "\n")
    print(summary_table(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
