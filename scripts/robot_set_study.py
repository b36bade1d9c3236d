#!/usr/bin/env python3
"""The default estimation on the field's robot set: for each arm-like chain of example-robot-data (4.1.0, the
copy tests/test_robot_set.py downloads), a simulated motion-capture campaign with a known truth, then the
commands a user runs, with the URDF as it ships (docs/robots.md, "The default estimation on the robot set").

The truth: every joint origin of the chain off by random errors (0.5 mm, 0.0573 deg = 1 mrad per axis, so the
joint offsets too), joints sagging under the URDF's masses (20 000 N m/rad each). The instrument: one marker at
50 mm from the tip frame's origin, in a frame 3 m away, 0.15 mm of noise per axis; 50 postures within the joint
limits. Then ``aacmm calibrate points.csv --arm URDF --tip-frame LINK --holdout 0.3`` (the defaults), ``aacmm
tip`` with the model file it writes, and, for the floor, ``calibrate`` of the truth itself (its geometry and
compliance as a model file, every parameter held: only the instrument's frame and the marker fitted) on the
same split. Each figure is the held-out postures' RMS 3D error with the training fit's frame and marker
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

[[task]]
kind = "mocap"
postures = {postures}
noise_mm = 0.15
"""


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
    log.write_text(f"$ aacmm {' '.join(map(str, args))}\n# exit {code} in {dt:.1f} s\n{out.getvalue()}{err.getvalue()}")
    return code, dt


def held_out_rms(summary: Path, which: str) -> float:
    """The held-out RMS 3D error [um] with the training fit's frames and markers, ``before`` (the nominal) or
    ``after`` (the model fitted)."""
    rows = json.loads(summary.read_text())["validation_holdout"]
    return float(next(r for r in rows if r["key"] == "reference_rms_predicted")[which])


def study(name: str, robots: Path, out: Path, seed: int, postures: int, stiffness: float) -> dict:
    """One chain: simulate, calibrate with the defaults, read the model back, the truth's floor."""
    rel, tip, base = CHAINS[name]
    d = out / name
    d.mkdir(parents=True, exist_ok=True)
    urdf = robots / rel
    campaign = d / "campaign.toml"
    campaign.write_text(CAMPAIGN.format(name=name, seed=seed, urdf=urdf, tip=tip, postures=postures,
                                        stiffness=stiffness, base=f'base_frame = "{base}"\n' if base else ""))
    res: dict = {"chain": name, "urdf": rel, "tip": tip, "base": base}
    code, _ = command(["simulate", campaign, "-o", d / "sim"], d / "simulate.log")
    if code:
        return {**res, "simulate_exit": code}
    points = d / "sim" / "points.csv"
    base_args = ["--base-frame", base] if base else []
    code, dt = command(["calibrate", points, "--arm", urdf, "--tip-frame", tip, *base_args, "--holdout", "0.3",
                        "-o", d / "cal"], d / "calibrate.log")
    res.update(calibrate_exit=code, calibrate_s=round(dt, 1))
    if code == 0:
        s = d / "cal" / "summary.json"
        res.update(nominal_um=held_out_rms(s, "before"), default_um=held_out_rms(s, "after"),
                   fixed=len(json.loads(s.read_text())["fixed"]))
        model = next((d / "cal").glob("*-calibrated.toml"))
        res["tip_exit"], _ = command(["tip", points, "--arm", model, "--reference-frame", "-o", d / "tips.csv"],
                                     d / "tip.log")
    truth = simulate(load_campaign(campaign)).truth
    (d / "truth.toml").write_text(format_model(truth["description"], truth["model"].effects, truth["p"]))
    code, _ = command(["calibrate", points, "--arm", d / "truth.toml", "--holdout", "0.3", "--hold", "*",
                       "-o", d / "floor"], d / "floor.log")
    res["floor_exit"] = code
    if code == 0:
        res["truth_um"] = held_out_rms(d / "floor" / "summary.json", "before")
    return res


def table(results: list) -> str:
    """The Markdown table of the results."""
    lines = ["| chain | calibrate exit | time [s] | nominal [um] | default [um] | truth [um] | default / truth |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    for r in results:
        um = [f"{r[k]:.0f}" if k in r else "-" for k in ("nominal_um", "default_um", "truth_um")]
        ratio = f"{r['default_um'] / r['truth_um']:.2f}" if "default_um" in r and "truth_um" in r else "-"
        lines.append(f"| {r['chain']} | {r.get('calibrate_exit', r.get('simulate_exit'))} | "
                     f"{r.get('calibrate_s', '-')} | {' | '.join(um)} | {ratio} |")
    return "\n".join(lines) + "\n"


def main_study(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("chains", nargs="*", help=f"names of CHAINS (default all: {', '.join(CHAINS)})")
    ap.add_argument("-o", "--output", type=Path, required=True)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--postures", type=int, default=50)
    ap.add_argument("--stiffness", type=float, default=20000.0, help="joint stiffness of the truth [N m/rad]")
    a = ap.parse_args(argv)
    unknown = [c for c in a.chains if c not in CHAINS]
    if unknown:
        ap.error(f"unknown chain(s) {', '.join(unknown)}; known: {', '.join(CHAINS)}")
    robots = robot_set()
    a.output.mkdir(parents=True, exist_ok=True)
    results = []
    for name in a.chains or list(CHAINS):
        results.append(study(name, robots, a.output, a.seed, a.postures, a.stiffness))
        print(json.dumps(results[-1]), flush=True)
    (a.output / "results.json").write_text(json.dumps(results, indent=1) + "\n")
    (a.output / "table.md").write_text(table(results))
    print(table(results))
    return 0


if __name__ == "__main__":
    raise SystemExit(main_study())
