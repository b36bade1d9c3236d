"""The arm's uniform scale in the prior's centre (``FitOptions.arm_scale``, ``--arm-scale``,
:func:`calibration.prior.uniform_scale`, :func:`calibration.prior.scale_step`): the direction scales every point the
arm reaches about its base (checked against the scaled points, not the code's own derivative), the Newton step is
the joint maximum a posteriori of a linear Gaussian problem with a flat scale (checked against that problem solved
as one least-squares system with the scale an unknown), and the options refuse what they do not know."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from arm_model.model import ArmModel
from arm_model.urdf_import import load_arm
from calibration import FitOptions
from calibration.prior import scale_step, uniform_scale

PANDA = Path(__file__).resolve().parents[1] / "examples" / "data" / "real-panda-seats" / "panda-with-inertials.urdf"


@pytest.mark.parametrize("arm", ["dh", "urdf"])
def test_the_uniform_scale_scales_every_point_about_the_base(nominal, arm):
    """``p + s * uniform_scale`` moves every ball centre to ``(1 + s)`` times itself (base frame): a rigid DH arm
    and the Panda URDF, 20 random poses, s = 1e-6 (the first-order statement; 1e-12 m of second order)."""
    desc = nominal if arm == "dh" else load_arm(PANDA, "ball_link")
    model = ArmModel(desc)
    rng = np.random.default_rng(3)
    q = rng.uniform(-2.0, 2.0, (20, desc.n_joints))
    d = uniform_scale(model)
    assert np.all(d[[i for i, u in enumerate(model.spec.units) if u != "m"]] == 0)
    s = 1e-6
    x0 = model.ball_centres(q, None, np.zeros(model.spec.size))
    x1 = model.ball_centres(q, None, s * d)
    np.testing.assert_allclose(x1, (1 + s) * x0, rtol=0, atol=1e-11)


def test_the_scale_step_is_the_joint_map_of_a_flat_scale():
    """A linear problem ``y = A p + e`` (unit noise) with the prior ``p ~ N(c0 + s d, diag(size^2))`` and ``s`` flat:
    one step of :func:`scale_step` from ``s = 0`` (the fit at the prior centred on ``c0``) gives the ``s`` of the
    joint least squares in ``(p, s)``, and its ``u`` that least squares' standard uncertainty of ``s``."""
    rng = np.random.default_rng(7)
    n, m = 6, 40
    a = rng.normal(size=(m, n))
    size = rng.uniform(0.5, 2.0, n)
    d = rng.normal(size=n)
    c0 = rng.normal(size=n) * 0.1
    y = a @ (c0 + 0.8 * d + rng.normal(size=n) * size) + rng.normal(size=m)
    # the fit at s = 0: data rows and prior rows (p - c0) / size
    big = np.vstack([a, np.diag(1 / size)])
    p = np.linalg.lstsq(big, np.concatenate([y, c0 / size]), rcond=None)[0]
    cov = np.linalg.inv(big.T @ big)
    step, u = scale_step(d, size, p - c0, cov)
    # the joint least squares: unknowns (p, s), prior rows (p - c0 - s d) / size
    joint = np.block([[a, np.zeros((m, 1))], [np.diag(1 / size), -(d / size)[:, None]]])
    sol = np.linalg.lstsq(joint, np.concatenate([y, c0 / size]), rcond=None)[0]
    u_joint = np.sqrt(np.linalg.inv(joint.T @ joint)[-1, -1])
    assert step == pytest.approx(sol[-1], rel=1e-9)
    assert u == pytest.approx(u_joint, rel=1e-9)


def test_a_direction_the_data_do_not_see_has_no_scale():
    """Where the posterior along the direction is the prior's (no data), the step is 0 and its u infinite."""
    size = np.array([1.0, 2.0])
    d = np.array([1.0, 1.0])
    assert scale_step(d, size, np.zeros(2), np.diag(size ** 2)) == (0.0, np.inf)


def test_unknown_arm_scale_is_refused():
    with pytest.raises(ValueError, match="arm_scale"):
        FitOptions(arm_scale="free")


def test_a_certified_scale_error_is_the_scale_not_the_lengths_prior(nominal):
    """A simulated campaign of ball bars, seats and a sphere (5 um noise) on an arm 0.2 % larger than its description
    plus 0.1 mm / 0.1 mrad random errors (about 1.6 s CPU): with ``arm_scale="data"`` the fit gives the scale 0.2 %
    within 0.02 % (u below 0.01 %), and the lengths' prior scale stays at the random errors' size (at most 0.15; the
    default, which shrinks the scale with the lengths, widens their group to 0.38 to reach it)."""
    from arm_model.sim.quick import SynthSpec, make_campaign, random_truth
    from calibration import Weights, calibrate, make_data
    model = ArmModel(nominal)
    spec = SynthSpec(ballbars=6, ballbar_points=5, seats=3, articulations=8, spheres=1, sphere_points=10, rings=0,
                     ring_points=0, planes=0, plane_points=0, reference_points=0, force=0.0, noise=5e-6,
                     reference_noise=5e-6)
    truth = random_truth(model, np.random.default_rng(1), length=1e-4, angle=1e-4, probe=1e-4)
    c = make_campaign(model, spec, seed=1, p_true=truth + 2e-3 * uniform_scale(model))
    res = calibrate(model, make_data(c.points, c.artefacts, model),
                    FitOptions(arm_scale="data", weights=Weights(probe=5e-6, reference=5e-6)))
    assert res.arm_scale["set_by_data"] and res.arm_scale["u"] < 1e-4
    assert abs(res.arm_scale["value"] - 2e-3) < 2e-4, res.arm_scale
    assert res.prior_scales["lengths"] <= 0.15, res.prior_scales
