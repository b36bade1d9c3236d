"""Simulator speed: each example campaign end to end (plan, settle, operator, inverse kinematics on the
true arm, readings, files in memory), the time of each stage, inverse kinematics per point, and the
truth residual (distance of the true deflected ball centre from its surface)."""
from __future__ import annotations

import time
from pathlib import Path

from arm_model.sim import load_campaign, simulate

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "campaigns"


QUICK = {"names": ("paper-ring", "calibration")}   # make bench BENCH=--quick


def main(names=("paper-ring", "paper-ring-xyz", "calibration", "hidden-eccentricity")) -> dict:
    print(f"{'campaign':22s} {'points':>7s} {'signal rows':>12s} {'total s':>8s} {'plan+settle s':>13s} "
          f"{'final IK s':>10s} {'starts/pt':>9s} {'truth residual':>15s}")
    rows = {}
    for name in names:
        campaign = load_campaign(EXAMPLES / f"{name}.toml")
        stages = []
        t0 = time.perf_counter()
        result = simulate(campaign, progress=lambda msg: stages.append((time.perf_counter() - t0, msg)))
        total = time.perf_counter() - t0
        k = next(i for i, (_, m) in enumerate(stages) if m.startswith("inverse"))
        t_plan, t_ik = stages[0][0], stages[k + 1][0] - stages[k][0]
        n = len(result.points) + (0 if result.reference_points is None else len(result.reference_points))
        samples = sum(len(s.time) for s in result.signals.values())
        s = result.stats
        rows[name] = dict(points=n, samples=samples, seconds=total, plan_seconds=t_plan, ik_seconds=t_ik,
                          starts=s["ik_attempts_mean"], residual=s["truth_residual_max_m"])
        print(f"{name:22s} {n:>7d} {samples:>12,d} {total:>8.2f} {t_plan:>13.2f} {t_ik:>10.2f} "
              f"{s['ik_attempts_mean']:>9.2f} {s['truth_residual_max_m'] * 1e12:>12.2f} pm")
    print("total: plan + settle (an articulation for every point, no force) + operator + final inverse kinematics "
          "with the contact forces (warm-started) + readings + every file's text in memory (no disk)")
    return rows


if __name__ == "__main__":
    main()
