"""validate_poses groups the residual rows by point in one pass (it kept a mask per point: quadratic in the rows)."""
from types import SimpleNamespace

import numpy as np

from calibration import validation
from calibration.validation import _point_norms


def _mask_per_point(e, point):
    """The figures as validate_poses computed them before (the independent reference)."""
    idx = np.unique(point[point >= 0])
    return idx, np.array([np.sqrt(np.sum(e[point == i] ** 2)) for i in idx])


def test_point_norms_are_bit_for_bit_the_mask_per_point_sums():
    rng = np.random.default_rng(5)
    for trial in range(300):
        n = int(rng.integers(0, 40))
        rows = rng.integers(1, (4, 12, 200)[trial % 3], n)          # numpy sums 8 rows and more pairwise
        point = np.r_[np.repeat(rng.permutation(100)[:n], rows), -np.ones(int(rng.integers(0, 4)), int)]
        rng.shuffle(point)
        e = rng.normal(size=len(point)) * 10.0 ** rng.uniform(-9, -3, len(point))
        (want_idx, want), (idx, got) = _mask_per_point(e, point), _point_norms(e, point)
        assert np.array_equal(idx, want_idx) and got.dtype == want.dtype and np.array_equal(got, want), trial


def test_validate_poses_on_30000_points_matches_the_reference(monkeypatch):
    """30 000 held-out points of 3 rows (and 40 lengths): the figures are those of the independent reference (the
    mask per point took about 1.2 s of CPU here, the one pass a few ms; speed is a benchmark's matter, not a test's)."""
    n = 30000
    rng = np.random.default_rng(0)
    point = np.r_[np.repeat(np.arange(n), 3), -np.ones(40, int)]
    e = rng.normal(size=len(point)) * 1e-5
    monkeypatch.setattr(validation, "heldout_residuals", lambda *a, **k: {"e": e, "point": point})
    data = SimpleNamespace(points=SimpleNamespace(measurement=np.array([f"m{i % 7}" for i in range(n)])))
    val = validation.validate_poses(None, None, data, None)
    want = _mask_per_point(e[:3000], point[:3000])[1]            # the reference on a slice (it is quadratic)
    assert val.poses["n"] == n and np.array_equal(val.pose_errors[0][:1000], want)
    assert val.poses["max"] == float(np.max(val.pose_errors[0]))
    assert list(val.pose_errors[1][:8]) == [f"m{i % 7}" for i in range(8)]
