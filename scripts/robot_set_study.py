#!/usr/bin/env python3
"""The default estimation on the field's robot set: for each arm-like chain of example-robot-data (4.1.0, the
copy tests/test_robot_set.py downloads), a simulated motion-capture campaign with a known truth, then the
commands a user runs, with the URDF as it ships (docs/robots.md, "The default estimation on the robot set").

The truth: every joint origin of the chain off by random errors (0.5 mm, 0.0573 deg = 1 mrad per axis, so the
joint offsets too), joints sagging under the URDF's masses (20 000 N m/rad each). The instrument: one marker at
50 mm from the tip frame's origin, in a frame 3 m away, 0.15 mm of noise per axis; 50 postures within the joint
limits. Then ``aacmm calibrate points.csv --arm URDF --tip-frame LINK --holdout 0.3`` (the defaults), ``aacmm
tip`` with the model file it writes, and, for the floor, ``calibrate`` of the truth itself (its geometry and
compliance as a model file) on the same split: its figure before the fit (only the instrument's frame and the
marker fitted). Each figure is the held-out postures' RMS 3D error with the training fit's frame and marker
[um]: the nominal URDF (its own frame and marker fitted), the calibration, the truth.

    python scripts/robot_set_study.py -o out/robot-set            # every chain of CHAINS
    python scripts/robot_set_study.py -o out/robot-set ur5 tiago  # some of them

Writes ``results.json`` and ``table.md`` into the output folder, each command's console beside its outputs.
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from arm_model.cli import main  # noqa: E402
from arm_model.model_file import format_model  # noqa: E402
from arm_model.sim import load_campaign, simulate  # noqa: E402

#: name: (URDF under robots/, tip link, base link or None: the root)
CHAINS = {
    "ur3": ("ur_description/urdf/ur3_robot.urdf", "tool0", None),
    "ur5": ("ur_description/urdf/ur5_robot.urdf", "tool0", None),
    "ur10": ("ur_description/urdf/ur10_robot.urdf", "tool0", None),
    "panda": ("panda_description/urdf/panda.urdf", "panda_hand_tcp", None),
    "panda-finger": ("panda_description/urdf/panda.urdf", "panda_rightfinger", None),
    "kinova": ("kinova_description/robots/kinova.urdf", "j2s6s200_end_effector", None),
    "kinova-finger": ("kinova_description/robots/kinova.urdf", "j2s6s200_link_finger_tip_1", None),
    "z1": ("z1_description/urdf/z1.urdf", "link06", None),
    "tiago": ("tiago_description/robots/tiago.urdf", "arm_7_link", None),
    "tiago-no-hand": ("tiago_description/robots/tiago_no_hand.urdf", "arm_7_link", None),
    "talos-left-arm": ("talos_data/robots/talos_left_arm.urdf", "arm_left_7_link", None),
    "talos-torso-arm": ("talos_data/robots/talos_reduced.urdf", "gripper_left_base_link", None),
    "talos-arm-on-torso": ("talos_data/robots/talos_reduced.urdf", "gripper_left_base_link", "torso_2_link"),
    "talos-fingertip": ("talos_data/robots/talos_full_v2.urdf", "gripper_left_fingertip_1_link", None),
    "baxter": ("baxter_description/urdf/baxter.urdf", "right_gripper", None),
    "anymal-kinova": ("anymal_b_simple_description/robots/anymal-kinova.urdf", "j2s6s200_end_effector", None),
    "b1-z1": ("b1_description/urdf/b1-z1.urdf", "gripperStator", None),
    "icub-arm": ("icub_description/robots/icub.urdf", "r_hand", None),
    "romeo-arm": ("romeo_description/urdf/romeo_small.urdf", "r_wrist", None),
    "romeo-finger": ("romeo_description/urdf/romeo.urdf", "RFinger13Link", None),
    "talos-leg": ("talos_data/robots/talos_reduced.urdf", "left_sole_link", None),
    "talos-sole-to-pelvis": ("talos_data/robots/talos_reduced.urdf", "base_link", "left_sole_link"),
    "solo12-leg": ("solo_description/robots/solo12.urdf", "FL_FOOT", None),
    "anymal-leg": ("anymal_c_simple_description/urdf/anymal.urdf", "LF_FOOT", None),
    "go1-leg": ("go1_description/urdf/go1.urdf", "FL_foot", None),
}

CAMPAIGN = """name = "{name}"
seed = {seed}
arm = "{urdf}"
tip_frame = "{tip}"
{base}sensor = "none"

[truth]
length_error_mm = 0.5
angle_error_deg = 0.0573

[truth.joint_compliance]
stiffness_Nm_per_rad = {stiffness}
gravity = true
contact = false

{task}"""

#: the instrument of each kind of campaign: a motion-capture marker, or seat pairs a bar apart probed by the ball
TASKS = {
    "mocap": """[[task]]
kind = "mocap"
postures = {postures}
noise_mm = 0.15
""",
    "seats": """[noise]
probing_repeatability_mm = 0.1

[[task]]
kind = "ballbar"
ends = "seat"
length_mm = {bar_mm}
positions = {positions}
articulations = {articulations}
""",
}


def robot_set() -> Path:
    """The URDFs of example-robot-data 4.1.0 as tests/test_robot_set.py caches them."""
    cache = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "aacmm-toolkit"
    path = cache / "example-robot-data-4.1.0" / "robots"
    if not path.is_dir():
        sys.exit(f"{path} not found: run `pytest -m slow tests/test_robot_set.py -k quick` once to download it")
    return path


def command(args: list, log: Path) -> tuple[int, float]:
    """``aacmm ARGS`` in this process: (exit status, wall time [s]); its console to ``log``."""
    out, err = io.StringIO(), io.StringIO()
    t = time.perf_counter()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in args])
    dt = time.perf_counter() - t
    if code in (130, 143):          # Ctrl-C or SIGTERM ended the command (the CLI catches them): end the study too
        raise SystemExit(code)
    log.write_text(f"$ aacmm {' '.join(map(str, args))}\n# exit {code} in {dt:.1f} s\n{out.getvalue()}{err.getvalue()}")
    return code, dt


#: the held-out figure of each kind of campaign (a key of summary.json's ``validation_holdout``) [um]
FIGURE = {"mocap": "reference_rms_predicted", "seats": "articulation_2sigma"}
#: a second held-out figure reported beside it, where there is one
SECOND = {"seats": "length_error_rms"}


def held_out(summary: Path, which: str, key: str) -> float:
    """A held-out figure [um] (``key``; for motion capture the RMS 3D error with the training fit's frames and
    markers), ``before`` (the nominal) or ``after`` (the model fitted)."""
    rows = json.loads(summary.read_text())["validation_holdout"]
    return float(next(r for r in rows if r["key"] == key)[which])


def study(name: str, robots: Path, out: Path, a: argparse.Namespace) -> dict:
    """One chain of :data:`CHAINS`: :func:`study_chain` of its URDF under ``robots``."""
    rel, tip, base = CHAINS[name]
    return study_chain(name, robots / rel, rel, tip, base, out, a)


def study_chain(name: str, urdf: Path, rel: str, tip: str, base: str | None, out: Path, a: argparse.Namespace) -> dict:
    """One chain (``rel``: the URDF's name in the results): simulate, calibrate with the defaults, read the model
    back, the truth's floor. ``a``: the options of :func:`main_study` (seed, postures, stiffness, campaign ...)."""
    d = out / name
    d.mkdir(parents=True, exist_ok=True)
    campaign = d / "campaign.toml"
    task = TASKS[a.campaign].format(postures=a.postures, bar_mm=a.bar_mm, positions=a.positions,
                                    articulations=a.articulations)
    campaign.write_text(CAMPAIGN.format(name=name, seed=a.seed, urdf=urdf, tip=tip, stiffness=a.stiffness, task=task,
                                        base=f'base_frame = "{base}"\n' if base else ""))
    res: dict = {"chain": name, "urdf": rel, "tip": tip, "base": base}
    code, dt = command(["simulate", campaign, "-o", d / "sim"], d / "simulate.log")
    res["simulate_s"] = round(dt, 1)
    if code:
        return {**res, "simulate_exit": code}
    points = d / "sim" / "points.csv"
    inputs = [points] + ([d / "sim" / "artefacts.toml"] if a.campaign == "seats" else [])
    keys = [FIGURE[a.campaign]] + ([SECOND[a.campaign]] if a.campaign in SECOND else [])
    base_args = ["--base-frame", base] if base else []
    code, dt = command(["calibrate", *inputs, "--arm", urdf, "--tip-frame", tip, *base_args, "--holdout", "0.3",
                        "-o", d / "cal"], d / "calibrate.log")
    res.update(calibrate_exit=code, calibrate_s=round(dt, 1))
    if code == 0:
        s = d / "cal" / "summary.json"
        for n, key in enumerate(keys):
            tag = "" if n == 0 else "_2"
            res.update({f"nominal{tag}_um": held_out(s, "before", key), f"default{tag}_um": held_out(s, "after", key)})
        res["fixed"] = len(json.loads(s.read_text())["fixed"])
        model = next((d / "cal").glob("*-calibrated.toml"))
        ref = ["--reference-frame"] if a.campaign == "mocap" else []
        res["tip_exit"], _ = command(["tip", points, "--arm", model, *ref, "-o", d / "tips.csv"], d / "tip.log")
    truth = simulate(load_campaign(campaign)).truth
    (d / "truth.toml").write_text(format_model(truth["description"], truth["model"].effects, truth["p"]))
    # the floor is the truth's "before" figure (its geometry and compliances as they are, only the instrument's frame
    # and marker fitted); calibrate refuses a fit with nothing free, so the compliances are left free beside it
    code, _ = command(["calibrate", *inputs, "--arm", d / "truth.toml", "--holdout", "0.3", "--free", "*.compliance",
                       "-o", d / "floor"], d / "floor.log")
    res["floor_exit"] = code
    if code == 0:
        for n, key in enumerate(keys):
            res["truth_um" if n == 0 else "truth_2_um"] = held_out(d / "floor" / "summary.json", "before", key)
    return res


def table(results: list) -> str:
    """The Markdown table of the results (seats: the length test's held-out RMS beside the articulation's 2 s)."""
    second = any("default_2_um" in r for r in results)
    head = "| chain | calibrate exit | time [s] | nominal [um] | default [um] | truth [um] | default / truth |"
    lines = [head + (" length RMS: nominal / default / truth [um] |" if second else ""),
             "|---|---:|---:|---:|---:|---:|---:|" + ("---:|" if second else "")]
    for r in results:
        um = [f"{r[k]:.0f}" if k in r else "-" for k in ("nominal_um", "default_um", "truth_um")]
        ratio = f"{r['default_um'] / r['truth_um']:.2f}" if "default_um" in r and "truth_um" in r else "-"
        status = r["calibrate_exit"] if "calibrate_exit" in r else f"simulate {r.get('simulate_exit')}"
        extra = " / ".join(f"{r[k]:.0f}" if k in r else "-" for k in ("nominal_2_um", "default_2_um", "truth_2_um"))
        lines.append(f"| {r['chain']} | {status} | {r.get('calibrate_s', '-')} | {' | '.join(um)} | {ratio} |"
                     + (f" {extra} |" if second else ""))
    return "\n".join(lines) + "\n"


def main_study(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("chains", nargs="*", help=f"names of CHAINS (default all: {', '.join(CHAINS)})")
    ap.add_argument("-o", "--output", type=Path, required=True)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--postures", type=int, default=50)
    ap.add_argument("--stiffness", type=float, default=20000.0, help="joint stiffness of the truth [N m/rad]")
    ap.add_argument("--campaign", choices=sorted(TASKS), default="mocap",
                    help="motion capture (one marker, unknown frame), or seat pairs a bar apart (docs/robots.md)")
    ap.add_argument("--bar-mm", type=float, default=100.0, help="seats: the bar's length [mm]")
    ap.add_argument("--positions", type=int, default=12, help="seats: the bar's positions")
    ap.add_argument("--articulations", type=int, default=6, help="seats: articulations a seat and position")
    a = ap.parse_args(argv)
    unknown = [c for c in a.chains if c not in CHAINS]
    if unknown:
        ap.error(f"unknown chain(s) {', '.join(unknown)}; known: {', '.join(CHAINS)}")
    robots = robot_set()
    a.output.mkdir(parents=True, exist_ok=True)
    results = []
    for name in a.chains or list(CHAINS):
        results.append(study(name, robots, a.output, a))
        print(json.dumps(results[-1]), flush=True)
    write_results(a.output, results, table(results))
    return 0


def write_results(out: Path, results: list, text: str) -> None:
    """A study's ``results.json`` (one object a chain) and ``table.md`` (``text``, also printed)."""
    (out / "results.json").write_text(json.dumps(results, indent=1) + "\n")
    (out / "table.md").write_text(text)
    print(text)


if __name__ == "__main__":
    raise SystemExit(main_study())
