"""Studies: executors (local processes, Dask), Monte Carlo aggregation, the observability index."""
from __future__ import annotations

import math

import numpy as np
import pytest

from arm_model.sim.quick import SynthSpec
from calibration import FitOptions, Weights
from calibration.study import RunSettings, SynthSource, monte_carlo, observability_index, run_tasks
from conftest import assert_close


def _square(x):
    return x * x


def test_run_tasks_in_processes_keeps_order():
    assert run_tasks(_square, range(7), workers=2, progress=False) == [x * x for x in range(7)]
    assert run_tasks(_square, [3], workers=2, progress=False) == [9]


def test_observability_index_by_hand():
    # singular values 4 and 1 (information eigenvalues 16, 1), 4 poses: O1 = sqrt(4 * 1) / sqrt(4) = 1
    assert_close(observability_index(np.diag([16.0, 1.0]), 4), 1.0, atol=1e-15)
    assert observability_index(np.diag([1.0, 0.0]), 4) == 0.0
    rot = np.linalg.qr(np.random.default_rng(0).normal(size=(3, 3)))[0]
    assert_close(observability_index(rot @ np.diag([9.0, 4.0, 1.0]) @ rot.T, 9), (3 * 2 * 1) ** (1 / 3) / 3,
                 atol=1e-12)


SOURCE_SPEC = SynthSpec(ballbars=6, ballbar_points=5, seats=3, articulations=8, spheres=1, sphere_points=10,
                        noise=2e-6)


def test_monte_carlo_local(nominal):
    """Three runs in local processes: every run succeeds, held-out figures improve, and the reported
    uncertainties are of the size of the actual errors."""
    mc = monte_carlo(SynthSource(nominal, SOURCE_SPEC), 3, seed=40, workers=2, progress=False,
                     settings=RunSettings(fit=FitOptions(weights=Weights(probe=2e-6)), holdout=0.3))
    assert not mc.failures
    assert [r["seed"] for r in mc.runs] == [40, 41, 42]
    assert mc.accuracy["length_error_max"]["after_median"] < mc.accuracy["length_error_max"]["before_median"] / 5
    ratios = np.array([v["ratio"] for v in mc.parameters.values()])
    assert len(ratios) >= 15 and 0.3 < np.median(ratios) < 2.5
    assert all(math.isfinite(v["mean_u"]) and v["mean_u"] > 0 for v in mc.parameters.values())


def test_a_failed_run_is_reported_not_raised(nominal):
    """A run that fails numerically (far too little data for the fit) is reported; the study's check says that
    no run succeeded. A held-out set the campaign cannot give is bad input, the same in every run: raised."""
    from arm_model import InputError, NumericalError
    spec = SynthSpec(ballbars=0, seats=1, articulations=3, spheres=0)    # far too little data
    mc = monte_carlo(SynthSource(nominal, spec), 1, workers=1, progress=False,
                     settings=RunSettings(holdout=0.0, fit=FitOptions(prior_scale=None)))
    assert len(mc.failures) == 1 and "NumericalError" in mc.failures[0]["error"]
    with pytest.raises(NumericalError, match=r"no run succeeded \(1 run\): NumericalError"):
        mc.check()
    with pytest.raises(InputError, match=r"--holdout 0.25: the held-out set is empty"):
        monte_carlo(SynthSource(nominal, spec), 1, workers=1, progress=False)


# in make test-slow: a local dask cluster starts worker processes (about 10 s); the serial and process pool paths stay
@pytest.mark.slow
def test_monte_carlo_on_a_dask_local_cluster(nominal):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        with distributed.Client(cluster) as client:
            mc = monte_carlo(SynthSource(nominal, SOURCE_SPEC), 2, seed=50, scheduler=client, progress=False,
                             settings=RunSettings(fit=FitOptions(weights=Weights(probe=2e-6)), holdout=0.3))
            by_address = monte_carlo(SynthSource(nominal, SOURCE_SPEC), 1, seed=50, scheduler=cluster.scheduler_address,
                                     progress=False,
                                     settings=RunSettings(fit=FitOptions(weights=Weights(probe=2e-6)), holdout=0.3))
    assert not mc.failures and [r["seed"] for r in mc.runs] == [50, 51]
    # the same seed gives the same result wherever it runs
    assert_close(by_address.runs[0]["p"], mc.runs[0]["p"], atol=1e-15)
    local = monte_carlo(SynthSource(nominal, SOURCE_SPEC), 1, seed=50, workers=1, progress=False,
                        settings=RunSettings(fit=FitOptions(weights=Weights(probe=2e-6)), holdout=0.3))
    assert_close(local.runs[0]["p"], mc.runs[0]["p"], atol=1e-15)


def test_rms_z_interval_and_verdicts():
    """The interval RMS z of R runs falls in when the uncertainties are right (chi distribution; checked
    by sampling), and the verdicts on a biased, an overstated and a right set of z."""
    from calibration.study import _verdict, rms_z_interval

    lo, hi = rms_z_interval(20)
    assert abs(lo - 0.692) < 0.002 and abs(hi - 1.307) < 0.002
    rng = np.random.default_rng(0)
    rms = np.sqrt(np.mean(rng.standard_normal((20000, 20)) ** 2, axis=1))
    assert abs(np.mean((rms >= lo) & (rms <= hi)) - 0.95) < 0.005
    assert _verdict(np.full(20, 2.0), lo, hi) == "biased"
    assert _verdict(0.4 * rng.standard_normal(20), lo, hi) == "u too large"
    assert _verdict(np.tile([1.0, -1.0], 10), lo, hi) == "ok"
