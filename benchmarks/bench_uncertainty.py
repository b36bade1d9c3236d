"""Uncertainty of the corrected ball centres against the centres alone: linear propagation with exact
Jacobians (every base parameter in the covariance, encoders, force sensor, compliance, probing) for N
points, as a multiple of the time of the deflection-corrected centres (target: under 10x at 10^6).

Then ``aacmm tip --uncertainty`` end to end (a subprocess: reading, propagating, writing) on 10^4 points with a
model file whose discrepancy grows away from 10^3 and 10^4 training poses (each point's distance from the nearest
of them: :func:`arm_model.discrepancy.pose_distance`), against the same model file with a constant discrepancy,
and the distance search alone in process."""
from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from arm_model import ball_centres, load_description
from arm_model.checks import limit_bounds
from arm_model.model import ArmModel
from arm_model.uncertainty import ParameterCovariance, default_inputs, monte_carlo, propagate

ARM = "urdf/aacmm7.dh.toml"


def _best(fun, repeats: int) -> tuple[float, float]:
    """Best wall-clock and best CPU time (all threads) of ``repeats`` calls [s]."""
    wall = cpu = np.inf
    for _ in range(repeats):
        t, c = time.perf_counter(), time.process_time()
        fun()
        wall, cpu = min(wall, time.perf_counter() - t), min(cpu, time.process_time() - c)
    return wall, cpu


QUICK = {"sizes": (10**4, 10**5), "tip_points": 10**3, "training": (10**3,)}   # make bench BENCH=--quick


def _tip(points: Path, model: Path, out: Path) -> tuple[float, float]:
    """(wall [s], CPU [s] of the process) of ``aacmm tip POINTS --arm MODEL --uncertainty -o OUT``."""
    cmd = [sys.executable, "-m", "arm_model.cli", "tip", str(points), "--arm", str(model), "--uncertainty", "-o",
           str(out), "-q"]
    t0 = time.perf_counter()
    pid = os.spawnv(os.P_NOWAIT, sys.executable, cmd)
    _, status, usage = os.wait4(pid, 0)
    wall = time.perf_counter() - t0
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"bench_uncertainty: {' '.join(cmd)} failed")
    return wall, usage.ru_utime + usage.ru_stime


def tip_growth(n_points: int, training: tuple) -> dict:
    """``aacmm tip --uncertainty`` on ``n_points`` random poses within the joint limits (2 N forces) with a model
    discrepancy growing away from each number of ``training`` poses, and constant (the model file without the
    growth); the distance search alone (levers and nearest pose) in process."""
    from arm_model.discrepancy import joint_levers, pose_distance
    from arm_model.model_file import load_model

    from .bench_live import growth_model
    rows = {}
    with tempfile.TemporaryDirectory(prefix="bench-tip-growth-") as tmp:
        tmp = Path(tmp)
        const = growth_model(tmp, 1)
        const.write_text(const.read_text().replace("model_discrepancy_growth_um_per_mm = 20.0\n", ""))
        arm = load_model(str(const), None)
        q = np.random.default_rng(1).uniform(*np.clip(np.array(limit_bounds(arm.desc)).T, -np.pi, np.pi),
                                             (n_points, arm.desc.n_joints))
        w = np.random.default_rng(2).normal(0.0, 2.0, (n_points, 3))
        cols = ",".join(f"q{k + 1}_rad" for k in range(arm.desc.n_joints))
        (tmp / "points.csv").write_text(f"measurement,feature,{cols},fx_N,fy_N,fz_N\n" + "".join(
            "m,p," + ",".join(map(repr, [*a.tolist(), *b.tolist()])) + "\n" for a, b in zip(q, w, strict=True)))
        wall, cpu = _tip(tmp / "points.csv", const, tmp / "tips.csv")
        rows[0] = dict(wall_s=wall, cpu_s=cpu)
        print(f"aacmm tip --uncertainty, {n_points:,} points, model discrepancy constant: {wall:.2f} s wall, "
              f"{cpu:.2f} s CPU")
        for t in training:
            (tmp / f"t{t}").mkdir()
            model = growth_model(tmp / f"t{t}", t)
            wall, cpu = _tip(tmp / "points.csv", model, tmp / "tips.csv")
            disc = load_model(str(model), None).discrepancy
            lev_s = _best(lambda: joint_levers(arm.desc, q), 1)[0]
            lev = joint_levers(arm.desc, q)
            d_s = _best(lambda: pose_distance(arm.desc, q, disc.training, lev), 1)[0]
            rows[t] = dict(wall_s=wall, cpu_s=cpu, levers_s=lev_s, nearest_s=d_s)
            print(f"  growing away from {t:,} training poses: {wall:.2f} s wall, {cpu:.2f} s CPU; in process the "
                  f"levers {lev_s:.3f} s and the nearest training pose {d_s:.3f} s "
                  f"({d_s / (n_points * t) * 1e9:.1f} ns a pair)")
    return rows


def discrepancy_folds(n_points: int = 10**5, exhaustive_folds: int = 1) -> dict:
    """The nearest-pose search of ``calibrate``'s model discrepancy on ``n_points`` random poses of the arm within its
    joint limits: each extrapolative fold (:func:`calibration.discrepancy.extreme_folds`, 15 % of the poses at an
    end of a joint's range) against the other poses, by the k-d trees (every fold) and by the exhaustive search
    (the first ``exhaustive_folds``), CPU seconds; the results compared bit for bit."""
    import arm_model.discrepancy as dm
    from calibration.discrepancy import extreme_folds
    desc = load_description(ARM)
    q = np.random.default_rng(5).uniform(*np.clip(np.array(limit_bounds(desc)).T, -np.pi, np.pi),
                                         (n_points, desc.n_joints))
    lev = dm.joint_levers(desc, q)
    folds = extreme_folds(q)
    keep, rows = dm._TREE_PAIRS, []
    try:
        for k, fold in enumerate(folds):
            rest = np.setdiff1d(np.arange(n_points), fold)
            train = dm.TrainingPoses.of(desc, q[rest])
            got = {}
            for how, pairs in (("trees", 0), ("exhaustive", 10**30)):
                if how == "exhaustive" and k >= exhaustive_folds:
                    continue
                dm._TREE_PAIRS = pairs
                t0 = time.process_time()
                got[how] = dm.nearest_pose(desc, q[fold], train, lev[fold])
                got[how + "_s"] = time.process_time() - t0
            same = None if "exhaustive" not in got else all(
                np.array_equal(a, b) for a, b in zip(got["trees"], got["exhaustive"], strict=True))
            rows.append(dict(fold=k, queries=len(fold), training=len(rest), trees_s=got["trees_s"],
                             exhaustive_s=got.get("exhaustive_s"), identical=same))
            print(f"fold {k + 1}/{len(folds)}: {len(fold):,} poses against {len(rest):,}: trees {got['trees_s']:.2f} s"
                  + ("" if same is None else f", exhaustive {got['exhaustive_s']:.2f} s, identical {same}"))
    finally:
        dm._TREE_PAIRS = keep
    total = sum(r["trees_s"] for r in rows)
    print(f"{len(rows)} folds of {n_points:,} poses by the trees: {total:.1f} s CPU")
    return dict(rows=rows, trees_total_s=total)


def main(sizes=(10**4, 10**5, 10**6), tip_points: int = 10**4, training: tuple = (10**3, 10**4)) -> dict:
    desc = load_description(ARM)
    model = ArmModel(desc)
    names = tuple(n for n in model.spec.names if not n.startswith("probe.compliance"))
    rng = np.random.default_rng(0)
    a = rng.normal(size=(len(names), len(names)))
    scale = np.full(len(names), 1e-6)          # 1 um, 1 urad
    pc = ParameterCovariance(names, (a @ a.T / len(names)) * np.outer(scale, scale))
    inputs = default_inputs(desc, encoder=np.radians(1e-4) / np.sqrt(12), probing=1e-6)
    print(f"{len(names)} parameters in the covariance, encoders, force sensor, compliance, probing")
    print("time of the centres alone and with their uncertainty; the ratio also in CPU time, which a busy machine "
          "disturbs less")
    print(f"{'N':>9} {'centres s':>10} {'u s':>8} {'ratio':>6} {'CPU ratio':>10} {'points/s':>12}")
    rows = {}
    for n in sizes:
        q = rng.uniform(-np.pi, np.pi, (n, 7))
        w = rng.normal(0, 2.0, (n, 3))
        reps = 3 if n <= 10**5 else 2
        tc, cc = _best(lambda: ball_centres(desc, q, w), reps)
        tu, cu = _best(lambda: propagate(model, None, q, w, parameters=pc, inputs=inputs), reps)
        rows[n] = dict(centres_s=tc, uncertainty_s=tu, ratio=tu / tc, cpu_ratio=cu / cc, rate=n / tu)
        print(f"{n:>9,} {tc:>10.3f} {tu:>8.3f} {tu / tc:>6.1f} {cu / cc:>10.1f} {n / tu:>12,.0f}")
    n, samples = 10**3, 1000
    q = rng.uniform(-np.pi, np.pi, (n, 7))
    w = rng.normal(0, 2.0, (n, 3))
    t = _best(lambda: monte_carlo(model, None, q, w, parameters=pc, inputs=inputs, samples=samples), 1)[0]
    print(f"Monte Carlo, {n} points x {samples} samples: {t:.2f} s")
    return dict(rows=rows, monte_carlo_s=t, tip_growth=tip_growth(tip_points, training))


if __name__ == "__main__":
    main()
