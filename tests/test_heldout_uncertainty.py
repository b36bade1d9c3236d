"""The standard uncertainties of the held-out figures (bootstrap over measurements) against the
sampling distribution of an RMS derived by hand: for n independent errors e with E[e^2] = v and
Var(e^2) = k v^2, RMS = sqrt(mean e^2) has, to first order, u = sqrt(k / n) v / (2 sqrt(v))."""
import numpy as np
import pytest

from calibration.loop import bootstrap_rows
from calibration.validation import Validation, bootstrap, with_u


def _lengths(errors):
    return [{"measurement": f"m{i:03d}", "between": ["a", "b"], "certified": 0.5, "measured": 0.5 + e, "error": e}
            for i, e in enumerate(errors)]


def test_length_rms_uncertainty_is_the_chi_square_spread():
    # normal errors: Var(e^2) = 2 sigma^4 -> u(RMS) = sigma / sqrt(2 n)
    rng = np.random.default_rng(3)
    sigma, n = 5e-6, 400
    val = Validation(lengths=_lengths(sigma * rng.standard_normal(n)))
    u = bootstrap(val, samples=2000)
    assert u["length_error_rms"] == pytest.approx(sigma / np.sqrt(2 * n), rel=0.15)
    assert u["length_error_max"] > 0


def test_reference_rms_uncertainty_resamples_whole_measurements():
    # 3D errors |N(0, sigma^2 I)|: e^2 = sigma^2 chi^2_3, Var(e^2) = 6 sigma^4, E = 3 sigma^2
    # -> u(RMS) = sqrt(6/n) sigma^2 / (2 sqrt(3) sigma) = sigma / sqrt(2 n); 150 measurements of 4 points
    rng = np.random.default_rng(4)
    sigma, m, k = 10e-6, 150, 4
    e = np.linalg.norm(sigma * rng.standard_normal((m * k, 3)), axis=1)
    meas = np.repeat([f"r{i}" for i in range(m)], k)
    val = Validation(reference={"n": len(e), "rms": float(np.sqrt(np.mean(e ** 2))), "max": float(e.max())},
                     reference_errors=(e, meas))
    u = bootstrap(val, samples=2000)
    assert u["reference_rms"] == pytest.approx(sigma / np.sqrt(2 * m * k), rel=0.15)
    # the close-loop rows: the same estimator on residual rows
    u_rms, _ = bootstrap_rows(e, meas, samples=2000)
    assert u_rms == pytest.approx(sigma / np.sqrt(2 * m * k), rel=0.15)


def test_one_measurement_gives_no_uncertainty_and_seeded_is_repeatable():
    val = Validation(lengths=_lengths([3e-6]))
    assert bootstrap(val) == {"length_error_max": None, "length_error_rms": None}
    assert bootstrap_rows(np.array([1e-6, 2e-6]), np.array(["a", "a"])) is None
    val = Validation(lengths=_lengths([3e-6, -1e-6, 2e-6, 4e-6]))
    assert bootstrap(val) == bootstrap(val)
    assert with_u(12.3, 0.456) == "12.30 ± 0.46" and with_u(1.0, None) == "1.00"
