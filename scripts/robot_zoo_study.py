#!/usr/bin/env python3
"""Robot descriptions as other packages ship them, loaded and calibrated (docs/robots.md, "Robots from other
packages"): the URDFs of pybullet (``pybullet_data``), the Robotics Toolbox's data (``rtb-data``), Hello Robot's
Stretch (``hello-robot-stretch-urdf``) and AIRO's models (``airo-models``), read where a Python environment has them
installed. None of them is a dependency of the toolkit, and nothing is copied from them.

For each chain: the load time (``load_arm``, best of 3), its moving joints, the largest distance between the
toolkit's tip and Pinocchio's placement of the same frame in the same file at 8 random joint values within the
limits, then the motion-capture study of ``scripts/robot_set_study.py`` (a truth with every origin off by 0.5 mm and
1 mrad and the joints sagging under the URDF's masses, 50 postures, 0.15 mm of noise; ``aacmm calibrate --holdout
0.3`` with the defaults; the truth's floor): held-out RMS [um] of the nominal URDF, the calibration and the truth.

    python -m venv /tmp/descr && /tmp/descr/bin/pip install pybullet rtb-data hello-robot-stretch-urdf airo-models
    python scripts/robot_zoo_study.py --python /tmp/descr/bin/python -o out/robot-zoo
    python scripts/robot_zoo_study.py --python /tmp/descr/bin/python -o out/robot-zoo iiwa-pybullet kr16

A package that environment lacks is skipped, saying so (without ``--python``: the packages this interpreter can
import). Writes ``results.json`` and ``table.md`` into the output folder, each command's console beside its outputs.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "scripts"))

from robot_set_study import study_chain, write_results  # noqa: E402

from arm_model.errors import InputError  # noqa: E402

#: name: (Python package holding the file, URDF under its folder, tip link, what the file holds)
CHAINS = {
    "panda-pybullet": ("pybullet_data", "franka_panda/panda.urdf", "panda_grasptarget", "7 joints, grasp target"),
    "iiwa-pybullet": ("pybullet_data", "kuka_iiwa/model.urdf", "lbr_iiwa_link_7", "7 joints"),
    "xarm6-pybullet": ("pybullet_data", "xarm/xarm6_robot.urdf", "link6", "tip at the last joint"),
    "xarm6-finger": ("pybullet_data", "xarm/xarm6_with_gripper.urdf", "left_finger", "gripper behind <mimic>"),
    "minitaur-leg": ("pybullet_data", "quadruped/minitaur.urdf", "lower_leg_front_rightR_link",
                     "<?xml version=\"0.0\"?>"),
    "laikago-leg": ("pybullet_data", "laikago/laikago_toes.urdf", "toeFR", "toe sphere of radius 0"),
    "humanoid-arm": ("pybullet_data", "humanoid/humanoid.urdf", "right_wrist", "NUL byte, spherical joints"),
    "irb140": ("rtbdata", "xacro/abb_irb140_description/urdf/irb140.urdf", "tool0", "ABB, 6 joints"),
    "kr16": ("rtbdata", "xacro/kuka_description/kuka_kr16/urdf/kr16_2.urdf", "tool0", "KUKA, 6 joints"),
    "kr210": ("rtbdata", "xacro/kuka_description/kuka_kr210/urdf/kr210l150.urdf", "tool0", "KUKA, 6 joints"),
    "iiwa14-rtb": ("rtbdata", "xacro/kuka_description/kuka_lbr_iiwa/urdf/lbr_iiwa_14_r820.urdf", "tool0", "7 joints"),
    "puma560": ("rtbdata", "xacro/unimation_puma560_description/urdf/puma560_robot.urdf", "link7", "6 joints"),
    "al5d": ("rtbdata", "xacro/lynxmotion_al5d_description/urdf/al5d_robot.urdf", "link4", "hobby arm, 4 joints"),
    "ur5e-airo": ("airo_models", "arms/ur5e/ur5e.urdf", "tool0", "undeclared drake: prefix"),
    "ur3e-airo": ("airo_models", "arms/ur3e/ur3e.urdf", "tool0", "undeclared drake: prefix"),
    "stretch-se3": ("stretch_urdf", "SE3/stretch_description_SE3_eoa_wrist_dw3_tool_sg3.urdf",
                    "link_gripper_fingertip_right", "prismatic lift and telescope"),
}


def package_dirs(python: str | None, packages: set) -> dict:
    """package -> its folder, in the environment of ``python`` (default this interpreter); absent ones left out."""
    code = ("import importlib.util, json, sys\nout = {}\nfor p in sys.argv[1:]:\n    s = importlib.util.find_spec(p)\n"
            "    if s and s.submodule_search_locations: out[p] = list(s.submodule_search_locations)[0]\n"
            "print(json.dumps(out))")
    r = subprocess.run([python or sys.executable, "-c", code, *sorted(packages)], capture_output=True, text=True)
    if r.returncode:
        sys.exit(f"cannot ask {python or sys.executable} for its packages: {r.stderr.strip()[-300:]}")
    return {k: Path(v) for k, v in json.loads(r.stdout).items()}


def against_pinocchio(urdf: Path, tip: str, seed: int) -> tuple[float, float, int, str]:
    """(load time [s], largest |toolkit - Pinocchio| tip distance [m] at 8 random values, moving joints, kinds)."""
    import pinocchio as pin

    from arm_model.kinematics import ball_centres
    from arm_model.urdf_import import load_arm
    times = []
    for _ in range(3):
        t = time.perf_counter()
        desc = load_arm(urdf, tip)
        times.append(time.perf_counter() - t)
    rng = np.random.default_rng(seed)
    lo = np.array([j.lower if j.lower is not None else -np.pi for j in desc.encoders])
    hi = np.array([j.upper if j.upper is not None else np.pi for j in desc.encoders])
    q = rng.uniform(lo, hi, size=(8, len(lo)))
    model = pin.buildModelFromUrdf(str(urdf))
    data = model.createData()
    frame = model.getFrameId(tip)
    names = [j.name for j in desc.encoders]
    ours = ball_centres(desc, q)
    worst = 0.0
    for k, qk in enumerate(q):
        x, value = pin.neutral(model), dict(zip(names, qk, strict=True))
        for row in desc.joints:                      # a mimic joint set by the URDF's formula from its master
            if row.mimic is not None:
                value[row.name] = row.mimic.multiplier * value[row.mimic.joint] + row.mimic.offset
        for name, v in value.items():
            jm = model.joints[model.getJointId(name)]
            x[jm.idx_q:jm.idx_q + jm.nq] = (np.cos(v), np.sin(v)) if jm.nq == 2 else v   # continuous: (cos, sin)
        pin.framesForwardKinematics(model, data, x)
        worst = max(worst, float(np.abs(data.oMf[frame].translation - ours[k]).max()))
    kinds = "+".join(sorted({j.kind for j in desc.joints}))
    return min(times), worst, len(desc.joints), kinds


def zoo_table(results: list) -> str:
    lines = ["| chain | file (package) | holds | moving joints | load [ms] | vs Pinocchio [m] | calibrate exit | "
             "nominal [um] | default [um] | truth [um] | default / truth |",
             "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in results:
        if "skipped" in r:
            lines.append(f"| {r['chain']} | `{r['urdf']}` ({r['package']}) | {r['holds']} | | | | {r['skipped']} "
                         "| | | | |")
            continue
        um = [f"{r[k]:.0f}" if k in r else "-" for k in ("nominal_um", "default_um", "truth_um")]
        ratio = f"{r['default_um'] / r['truth_um']:.2f}" if "default_um" in r and "truth_um" in r else "-"
        status = r.get("calibrate_exit", f"simulate {r['simulate_exit']}" if "simulate_exit" in r else "-")
        lines.append(f"| {r['chain']} | `{r['urdf']}` ({r['package']}) | {r['holds']} | {r['joints']} ({r['kinds']}) "
                     f"| {r['load_ms']:.1f} | {r['vs_pinocchio_m']:.0e} | {status} | {' | '.join(um)} | {ratio} |")
    return "\n".join(lines) + "\n"


def main_study(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("chains", nargs="*", help=f"names of CHAINS (default all: {', '.join(CHAINS)})")
    ap.add_argument("-o", "--output", type=Path, required=True)
    ap.add_argument("--python", help="the Python of an environment where the description packages are installed")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--postures", type=int, default=50)
    ap.add_argument("--stiffness", type=float, default=20000.0, help="joint stiffness of the truth [N m/rad]")
    ap.add_argument("--load-only", action="store_true", help="load and compare with Pinocchio, no calibration")
    a = ap.parse_args(argv)
    a.campaign, a.bar_mm, a.positions, a.articulations = "mocap", 100.0, 12, 6    # (the seats' options: unused)
    unknown = [c for c in a.chains if c not in CHAINS]
    if unknown:
        ap.error(f"unknown chain(s) {', '.join(unknown)}; known: {', '.join(CHAINS)}")
    names = a.chains or list(CHAINS)
    dirs = package_dirs(a.python, {CHAINS[n][0] for n in names})
    a.output.mkdir(parents=True, exist_ok=True)
    results = []
    for name in names:
        package, rel, tip, holds = CHAINS[name]
        res = {"chain": name, "package": package, "urdf": rel, "tip": tip, "holds": holds}
        if package not in dirs:
            res["skipped"] = f"skipped: {package} not installed"
            print(f"{name}: {res['skipped']} in {a.python or sys.executable}", flush=True)
        else:
            urdf = dirs[package] / rel
            try:
                load_s, worst, n, kinds = against_pinocchio(urdf, tip, a.seed)
            except InputError as exc:
                res["skipped"] = f"refused: {exc}"
            else:
                res.update(load_ms=1e3 * load_s, vs_pinocchio_m=worst, joints=n, kinds=kinds)
            if not a.load_only and "skipped" not in res:
                res.update({k: v for k, v in study_chain(name, urdf, rel, tip, None, a.output, a).items()
                            if k not in res})
            print(json.dumps(res), flush=True)
        results.append(res)
    write_results(a.output, results, zoo_table(results))
    return 0


if __name__ == "__main__":
    raise SystemExit(main_study())
