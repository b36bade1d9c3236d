"""Uncertainty of the corrected ball centres against the centres alone: linear propagation with exact
Jacobians (every base parameter in the covariance, encoders, force sensor, compliance, probing) for N
points, as a multiple of the time of the deflection-corrected centres (target: under 10x at 10^6)."""
from __future__ import annotations

import time

import numpy as np

from arm_model import ball_centres, load_description
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


QUICK = {"sizes": (10**4, 10**5)}   # make bench BENCH=--quick


def main(sizes=(10**4, 10**5, 10**6)) -> dict:
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
    return dict(rows=rows, monte_carlo_s=t)


if __name__ == "__main__":
    main()
