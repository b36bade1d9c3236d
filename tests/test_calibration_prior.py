"""The Gaussian prior on the free parameters (``prior_scale``, ``--prior-scale``): its limits (a wide prior is
the plain fit, a narrow one the nominal), the MAP estimate as the minimum of data plus prior cost, the
empirical-Bayes choice of its scale against campaigns whose parameter errors are drawn at a known scale,
and the command line."""
from __future__ import annotations

import json
import numpy as np
import pytest

from arm_model.model import ArmModel
from arm_model.sim.quick import SynthSpec, make_campaign, random_truth
from calibration import FitOptions, Weights, calibrate, make_data
from calibration.calibrate import EVIDENCE_GRID, evidence_scale
from calibration.identifiability import prior_scales

SPEC = SynthSpec(ballbars=6, ballbar_points=5, seats=3, articulations=8, spheres=1, sphere_points=10, rings=0,
                 ring_points=0, planes=0, plane_points=0, reference_points=0, force=0.0, noise=5e-6,
                 reference_noise=5e-6)
W = Weights(probe=5e-6, reference=5e-6)


@pytest.fixture(scope="module")
def model(nominal):
    return ArmModel(nominal)


def _campaign(model, scale, seed):
    """A campaign whose length and probe errors are N(0, scale mm) and angle errors N(0, scale x 0.01 rad):
    ``scale`` times the plausible sizes of calibration.identifiability (1 mm, 0.01 rad at this noise)."""
    rng = np.random.default_rng(seed)
    p = random_truth(model, rng, length=scale * 1e-3, angle=scale * 1e-2, probe=scale * 1e-3)
    c = make_campaign(model, SPEC, seed=seed, p_true=p)
    return make_data(c.points, c.artefacts, model), p


def test_wide_prior_is_the_plain_fit_and_narrow_prior_the_nominal(model):
    data, _ = _campaign(model, 0.1, 3)
    plain = calibrate(model, data, FitOptions(weights=W, min_resolution=None))
    wide = calibrate(model, data, FitOptions(free=list(plain.free), weights=W, prior_scale=1e4))
    idx = [model.spec.index(n) for n in plain.free]
    # a prior 1e4 times the plausible sizes moves the estimate by a negligible share of its uncertainty
    assert np.max(np.abs(wide.p[idx] - plain.p[idx]) / plain.u) < 1e-3
    assert np.allclose(wide.u, plain.u, rtol=1e-3)
    narrow = calibrate(model, data, FitOptions(free=list(plain.free), weights=W, prior_scale=1e-6))
    size = prior_scales(model, list(plain.free), noise=5e-6)
    assert np.max(np.abs(narrow.p[idx]) / size) < 1e-5
    # the posterior uncertainty cannot exceed the prior's
    assert np.all(narrow.u <= 1e-6 * size * (1 + 1e-6) * max(1.0, narrow.s0))


def test_map_is_the_minimum_of_data_plus_prior_cost(model):
    """Each free parameter moved by +-0.3 of its posterior uncertainty (the others and the artefacts'
    unknowns refitted) raises data plus prior cost: checked with fits holding that one parameter."""
    data, _ = _campaign(model, 0.1, 5)
    res = calibrate(model, data, FitOptions(weights=W, prior_scale=0.3))
    total = res.cost + 0.5 * float(np.sum(((res.p - res.prior_centre)[[model.spec.index(n) for n in res.free]]
                                          / (0.3 * prior_scales(model, list(res.free), noise=5e-6))) ** 2))
    rng = np.random.default_rng(0)
    for name in rng.choice(list(res.free), 4, replace=False):
        k = list(res.free).index(name)
        for sign in (-1, 1):
            values = dict(zip(model.spec.names, res.p))
            values[name] += sign * 0.3 * res.u[k]
            others = [n for n in res.free if n != name]
            r2 = calibrate(model, data, FitOptions(free=others, values=values, weights=W, prior_scale=0.3,
                                                   prior_centre=res.prior_centre, min_resolution=None))
            size = 0.3 * prior_scales(model, list(res.free), noise=5e-6)
            d = np.array([r2.p[model.spec.index(n)] - res.prior_centre[model.spec.index(n)] for n in res.free])
            assert r2.cost + 0.5 * float(np.sum((d / size) ** 2)) > total


@pytest.mark.parametrize("scale,seed", [(0.05, 11), (0.2, 12)])
def test_evidence_finds_the_scale_the_errors_were_drawn_at(model, scale, seed):
    data, _ = _campaign(model, scale, seed)
    tau, rows = evidence_scale(model, data, FitOptions(weights=W))
    assert [r["scale"] for r in rows] == list(EVIDENCE_GRID)
    grid = list(EVIDENCE_GRID)
    assert abs(grid.index(tau) - grid.index(scale)) <= 1, (tau, rows)


def test_command_line_prior_scale(tmp_path, capsys):
    """On the real robot data: --prior-scale evidence reports the scale chosen and the scales tried, the
    model reads back in tip; a bad value is a usage error (exit 2) and writes nothing."""
    from arm_model.cli import main
    from conftest import ROOT
    real = ROOT / "examples" / "data" / "real-panda-seats"
    args = ["calibrate", str(real / "right" / "points.csv"), str(real / "artefacts.toml"),
            "--arm", str(real / "panda-with-inertials.urdf"), "--tip-frame", "ball_link", "--no-plots"]
    for bad in ("0", "-1", "nan", "often"):
        with pytest.raises(SystemExit) as exc:
            main(args + ["-o", str(tmp_path / "bad"), "--prior-scale", bad])
        assert exc.value.code == 2 and "--prior-scale" in capsys.readouterr().err
    assert not (tmp_path / "bad").exists()
    assert main(args + ["-o", str(tmp_path / "cal"), "--prior-scale", "evidence"]) == 0
    assert "the scale of the largest evidence among" in capsys.readouterr().out
    s = json.loads((tmp_path / "cal" / "summary.json").read_text())
    tried = [r["scale"] for r in s["prior"]["scales_tried"]]
    assert tried == list(EVIDENCE_GRID) and s["prior"]["scale"] in tried
    best = max(s["prior"]["scales_tried"], key=lambda r: r["log_evidence"] if r["log_evidence"] is not None else -1e300)
    assert best["scale"] == s["prior"]["scale"]
    assert main(["tip", str(real / "front" / "points.csv"), "--arm", str(tmp_path / "cal" / "panda-calibrated.toml"),
                 "-o", str(tmp_path / "tip.csv")]) == 0


def test_large_errors_converge_to_the_noise(model):
    """Errors of 0.3 mm and 3 mrad: the artefacts' unknowns started from the nominal arm settled in another
    basin (s0 49 on this campaign); started again from the fitted arm, the fit reaches the noise. Not on
    every campaign of this size: of seeds 0-11, the restart brought 4 from s0 50-125 to the noise and 3
    stayed in another basin (s0 40-114; measured)."""
    data, _ = _campaign(model, 0.3, 1)
    res = calibrate(model, data, FitOptions(weights=W))
    assert 0.8 < res.s0 < 1.2 and res.status.startswith("converged")
