"""Deflection-aware ball centres per second: batch path vs a Python loop over Pinocchio doing the
same computation (elastic joint statics + forward kinematics), and peak memory against N."""
from __future__ import annotations

import time
import tracemalloc

import numpy as np

from arm_model import PinocchioArm, ball_centres, load_description

ARM = "urdf/aacmm7.dh.toml"


def _inputs(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    return rng.uniform(-np.pi, np.pi, (n, 7)), rng.normal(0, 2.0, (n, 3))


def _best(fun, repeats: int) -> float:
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        fun()
        best = min(best, time.perf_counter() - t)
    return best


QUICK = {"sizes": (10**3, 10**4, 10**5, 10**6)}   # make bench BENCH=--quick


def main(sizes=(10**3, 10**4, 10**5, 10**6, 10**7), loop_n: int = 20_000) -> dict:
    desc = load_description(ARM)
    arm = PinocchioArm(desc)
    q, w = _inputs(loop_n)
    t = _best(lambda: [arm.ball_centre(q[i], w[i]) for i in range(loop_n)], 1)
    loop_rate = loop_n / t
    print(f"Python loop over Pinocchio (elastic statics + FK), N={loop_n}: {loop_rate:,.0f} centres/s")
    print(f"{'N':>9} {'batch centres/s':>16} {'x loop':>8} {'1 thread/s':>12} {'peak MiB':>9} {'bytes/pt':>9}")
    rows = {}
    for n in sizes:
        q, w = _inputs(n)
        reps = 5 if n <= 10**5 else (3 if n <= 10**6 else 1)
        t2 = _best(lambda: ball_centres(desc, q, w), reps)
        t1 = _best(lambda: ball_centres(desc, q, w, threads=1), reps)
        tracemalloc.start()
        ball_centres(desc, q, w)
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        rate = n / t2
        rows[n] = dict(rate=rate, rate_1thread=n / t1, speedup=rate / loop_rate, peak_bytes=peak)
        print(f"{n:>9,} {rate:>16,.0f} {rate / loop_rate:>8.0f} {n / t1:>12,.0f} {peak / 2**20:>9.1f} {peak / n:>9.0f}")
    print("peak memory = output (24 B/point) + chunk temporaries (constant); inputs not counted")
    return dict(loop_rate=loop_rate, rows=rows)


if __name__ == "__main__":
    main()
