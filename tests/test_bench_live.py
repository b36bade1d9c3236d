"""The live benchmark's verdict on the latency target: a distribution-free interval of the 99th percentile."""
from __future__ import annotations

import numpy as np

from benchmarks.bench_live import p99_interval, verdict


def test_p99_interval_covers_the_percentile_at_its_level():
    # exponential latencies (a long tail): the interval of 1000 values holds the true p99 in at least 95 % of
    # draws (order statistics: a little more, the ranks are whole)
    rng = np.random.default_rng(4)
    true = -np.log(0.01)
    draws = 400
    cover = np.mean([lo <= true <= hi for lo, hi in (p99_interval(rng.exponential(size=1000)) for _ in range(draws))])
    assert 0.95 - 3 * np.sqrt(0.05 * 0.95 / draws) <= cover <= 0.995
    # the verdict: met only when the whole interval is below the target
    x = rng.exponential(size=1000) * 1e-3
    lo, hi = p99_interval(x)
    assert verdict(x, target=hi * 1.01).startswith("met")
    assert verdict(x, target=lo * 0.99).startswith("missed")
    assert verdict(x, target=0.5 * (lo + hi)).startswith("not resolved")
    assert p99_interval(np.arange(10.0)) == (8.0, 9.0)       # too few values: the largest is the upper end
