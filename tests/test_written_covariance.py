"""The covariance file beside a calibrated URDF model is the fit's covariance in the model file's parameters.

A URDF origin's angle errors turn it about its own axes (``R(rpy) Rz Ry Rx`` of the errors). The fit's errors
turn the nominal origin; the model file holds the calibrated origin (the errors folded into its roll, pitch and
yaw), whose own axes are turned by the errors themselves, and its covariance file is read as turns about those
(:func:`arm_model.model_file.parameters_of`). Written as the fit's, the point uncertainties read back were off
by the order of the angle errors (0.4 % at 20 mrad: the defect this file holds); written through
:func:`arm_model.params.folded_jacobian` (``T C T^T``) they are the fit's to numerical precision.

The references are independent of the code checked: central finite differences of the ball centres (no
Jacobian code, no dual numbers), and the folding's own rotations for the Jacobian of the fold.
"""
from __future__ import annotations

import numpy as np
import pytest

from conftest import ROOT, assert_close, fd_jacobian

#: the truth's angle errors [rad]: large, so that turns about the nominal and the calibrated origin's axes differ
#: (by about this, relative) far beyond the tolerances below
ANGLE = 2e-2


def _written(tmp: str):
    """A simulated URDF campaign with large angle errors, its fit, and the model file written and read back."""
    from pathlib import Path

    from arm_model.model import ArmModel
    from arm_model.model_file import load_model, parameters_of
    from arm_model.output import output_folder
    from arm_model.sim.quick import SynthSpec, make_campaign, random_truth
    from arm_model.urdf_import import load_arm
    from calibration import calibrate, make_data
    from calibration.model_output import write_model
    model = ArmModel(load_arm(ROOT / "urdf" / "aacmm7.urdf", "ball"))
    truth = random_truth(model, np.random.default_rng(1), length=2e-4, angle=ANGLE)
    c = make_campaign(model, SynthSpec(ballbars=5, seats=2, spheres=1), seed=1, p_true=truth)
    fit = calibrate(model, make_data(c.points, c.artefacts, model))
    with output_folder(Path(tmp) / "out", (), "calibrate") as out:
        files = write_model(fit, out.dir, "arm")
    back = load_model(out.published(files["model"]))
    return fit, back, parameters_of(back)


def _fd_point_cov(model, p0, names, cov, q) -> np.ndarray:
    """(n, 3, 3) covariance of the ball centres at ``q`` from the named parameters' ``cov``, by central finite
    differences of the model's ball centres (step 1e-7 in SI: truncation ~1e-14, rounding ~1e-9 relative)."""
    idx = [model.spec.index(n) for n in names]

    def centres(x):
        p = np.array(p0, dtype=float)
        p[idx] = x
        return model.ball_centres(q, None, p).ravel()
    jac = fd_jacobian(centres, np.asarray(p0, dtype=float)[idx], eps=1e-7).reshape(len(q), 3, len(idx))
    return np.einsum("nik,kl,njl->nij", jac, cov, jac)


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    return _written(str(tmp_path_factory.mktemp("cov")))


def test_model_file_and_covariance_give_the_fits_point_uncertainty(written):
    """Ball-centre covariance from the parameters on the fitted poses: the written model file (its
    description, the calibrated origins) with its covariance file read back, against the fit's own model at
    its estimate with its covariance, both by finite differences; and by the propagation ``aacmm tip`` runs."""
    from arm_model.uncertainty import InputUncertainty, propagate
    fit, back, pc = written
    q = fit.data.points.q[:40]
    own = _fd_point_cov(fit.model, fit.p, fit.free, fit.cov, q)
    got = _fd_point_cov(back.model, back.p, pc.names, pc.cov, q)
    scale = np.abs(own).max()
    assert_close(got / scale, own / scale, atol=1e-7)        # before the fix: 4e-3
    none = InputUncertainty(np.zeros(q.shape[1]), np.zeros(3), np.zeros(3), np.zeros(3))
    tip = propagate(back.model, back.p, q, parameters=pc, inputs=none).cov
    assert_close(tip / scale, own / scale, atol=1e-7)
    # the angle errors were large enough to tell the two parameterisations apart
    assert any(abs(fit.value(n)) > ANGLE / 4 for n in fit.free if "origin_r" in n or "origin_p" in n)


def test_what_is_written_is_what_the_fit_estimated_where_the_axes_agree(written):
    """Lengths (and every parameter of a DH chain) are written as the fit estimated them; an angle row of an origin
    is the fit's turned into the calibrated origin's axes, so its u moves by no more than the angle errors."""
    fit, _, pc = written
    u = dict(zip(pc.names, np.sqrt(np.diag(pc.cov)), strict=True))
    for n in fit.free:
        if n.split(".")[-1] in ("origin_x", "origin_y", "origin_z") or n.startswith("probe."):
            assert u[n] == pytest.approx(fit.uncertainty(n), rel=1e-12)
        else:
            assert u[n] == pytest.approx(fit.uncertainty(n), rel=4 * ANGLE)


@pytest.mark.parametrize("angles", [(0.0, 0.0, 0.0), (0.03, -0.02, 0.05), (0.4, 1.2, -2.0)])
def test_folded_jacobian_is_the_folds_own(angles):
    """``folded_jacobian`` against the fold itself: the origin turned by ``p + dp`` about the nominal origin's axes
    is the folded origin turned by ``dp'`` about its own axes; ``dp'`` from the rotations, central differences."""
    from arm_model.geometry import rotation_xyz, rpy_from_matrix
    from arm_model.params import folded_jacobian, param_spec
    from arm_model.urdf_import import load_arm
    desc = load_arm(ROOT / "urdf" / "aacmm7.urdf", "ball")
    spec = param_spec(desc)
    p = np.zeros(spec.size)
    j = "j4"
    k = [spec.index(f"{j}.origin_{a}") for a in ("roll", "pitch", "yaw")]
    p[k] = angles

    def turn(a):            # E(a) = Rz(yaw) Ry(pitch) Rx(roll) of the errors (roll, pitch, yaw)
        return rotation_xyz((0.0, 0.0, a[2])) @ rotation_xyz((0.0, a[1], 0.0)) @ rotation_xyz((a[0], 0.0, 0.0))

    def in_folded_axes(a):  # E(p)^T E(a) as the errors (roll, pitch, yaw) of the folded origin
        return np.array(rpy_from_matrix(turn(angles).T @ turn(a)))
    want = fd_jacobian(in_folded_axes, np.array(angles), eps=1e-6)
    t = folded_jacobian(desc, p)
    assert_close(t[np.ix_(k, k)], want, atol=1e-9)
    rest = np.setdiff1d(np.arange(spec.size), k)
    assert_close(t[np.ix_(rest, rest)], np.eye(len(rest)), atol=0.0)
    assert_close(t[np.ix_(rest, k)], np.zeros((len(rest), 3)), atol=0.0)
