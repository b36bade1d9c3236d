"""The loop on the real Panda seat data (examples/data/real-panda-seats), trained on one placement: joint
compliance under gravity, which held-out poses of one placement cannot show, is included as physics and
carries over to the other placements; a compliance and a joint gain injected into the real joint angles (known
effects in real data, with the real scatter) are found and recovered; a joint gain the data cannot resolve
is held.

The injection is independent of the project's own effect code: gravity torques from Pinocchio's RNEA on
the URDF, and the encoder angles moved so that a joint of compliance c at the injected angles reaches the
recorded angles (``q_inj - c tau_g(q_inj) = q_recorded``, the sign convention of
:class:`arm_model.effects.JointCompliance`)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from conftest import loop_fit_options, seat_figures_of

REAL = Path(__file__).resolve().parents[1] / "examples" / "data" / "real-panda-seats"
PLACES = ("front", "right", "back-high")
COMPLIANCE = 1e-4          # rad/(N m) on every joint: about 4 mrad on the shoulder


@pytest.fixture(scope="module")
def setup():
    from arm_model.io import read_artefacts, read_points
    from arm_model.urdf_import import load_arm
    desc = load_arm(REAL / "panda-with-inertials.urdf", "ball_link")
    return desc, read_artefacts(REAL / "artefacts.toml"), {p: read_points(REAL / p / "points.csv", 7) for p in PLACES}


def _inject(pts, c):
    """The points with their encoder angles moved by a compliance ``c`` [rad/(N m)] of every joint."""
    import dataclasses

    import pinocchio as pin
    m = pin.buildModelFromUrdf(str(REAL / "panda-with-inertials.urdf"))
    d = m.createData()
    q0 = np.asarray(pts.q, float)
    q = q0.copy()
    for _ in range(8):                    # fixed point: the deflection changes the torques by ~1e-4 of themselves
        tau = np.array([pin.computeGeneralizedGravity(m, d, np.r_[qi, np.zeros(m.nq - 7)])[:7] for qi in q])
        q = q0 + c * tau
    return dataclasses.replace(pts, q=q)


def _compare(desc, art, pts, train: str, loop, held) -> tuple[list, list, list]:
    """Plain calibrate trained on ``pts[train]`` against the loop's model, on the placements ``held``:
    (plain's seat figures, the loop's, the two mean spreads [mm])."""
    from arm_model.model import ArmModel
    from calibration.calibrate import calibrate
    from calibration.data import make_data
    plain = calibrate(ArmModel(desc), make_data(pts[train], art, ArmModel(desc)), loop_fit_options())
    a = [seat_figures_of(plain, desc, pts[p]) for p in held]
    b = [seat_figures_of(loop.model_fit, desc, pts[p]) for p in held]
    return a, b, [np.mean([f["spread_mean_mm"] for f in x]) for x in (a, b)]


@pytest.mark.slow
def test_trained_on_back_high_joint_compliance_is_included_and_the_other_placements_spread_less(setup):
    from calibration.loop import PHYSICS, close_loop
    desc, art, pts = setup
    loop = close_loop(pts["back-high"], art, desc)
    assert [c.name for c in loop.added] == ["joint compliance (every loaded joint)"], loop.verdict
    assert "(included as physics, not for a held-out gain)" in loop.verdict
    cv = [v for v in loop.stages[1].cv if v.candidate == loop.added[0].name][0]
    assert cv.reason.startswith(PHYSICS)
    a, b, spread = _compare(desc, art, pts, "back-high", loop, ("front", "right"))
    # measured: 2.84 -> 2.07 mm (front 3.27 -> 1.80, right 2.42 -> 2.34)
    assert spread[1] <= 0.8 * spread[0], (a, b)
    # the distance error is worse (0.56 -> 0.80 mm mean |error|), and bounded here
    dist = [np.mean([abs(f["distance_error_mm"]) for f in x]) for x in (a, b)]
    assert dist[1] <= dist[0] + 0.35, (a, b)


def test_a_compliance_injected_into_the_real_angles_is_found_recovered_and_carries_over(setup):
    from arm_model.effects import JointCompliance
    from arm_model.model import ArmModel
    from calibration.calibrate import calibrate
    from calibration.data import make_data
    from calibration.loop import close_loop
    desc, art, pts = setup
    inj = {p: _inject(pts[p], COMPLIANCE) for p in PLACES}
    loop = close_loop(inj["front"], art, desc)
    # the compliance first; since the loop drops calibrate's gross points (the point test: one design pose and
    # two test poses of this misfit base model), the eccentricity of joints 4 and 6 passes the held-out folds
    # and the outer test after it
    assert [c.name for c in loop.added][:1] == ["joint compliance (every loaded joint)"], loop.verdict
    a, b, spread = _compare(desc, art, inj, "front", loop, ("right", "back-high"))
    # measured: 3.38 -> 1.27 mm (with the compliance alone, before the point test: 3.21 -> 1.76 mm)
    assert spread[1] <= 0.8 * spread[0], (a, b)
    # recovered: the injected compliance is the difference to the same fit on the recorded angles (the real
    # arm's own apparent compliance), within 3 sigma on every joint both fits resolve
    model = ArmModel(desc, (loop.added[0].effect,))
    assert isinstance(loop.added[0].effect, JointCompliance)
    ref = calibrate(model, make_data(pts["front"], art, model), loop_fit_options())
    fit = loop.model_fit
    both = [n for n in fit.free if n.endswith(".compliance") and n in ref.free]
    assert len(both) >= 3
    for n in both:
        diff, u = fit.value(n) - ref.value(n), np.hypot(fit.uncertainty(n), ref.uncertainty(n))
        assert abs(diff - COMPLIANCE) <= 3 * u, (n, diff, u)


GAIN = 5e-3                # encoder scale error injected on the shoulder (panda_joint2): 0.5 %


@pytest.mark.slow        # make test holds its property with the compliance injected the same way (the test above)
def test_a_joint_gain_injected_into_the_real_angles_is_found_recovered_and_carries_over(setup):
    """Encoder readings of joint 2 divided by 1 + g (so the true angle is (1 + g) times the reading, the
    convention of :class:`arm_model.effects.JointGain`), independent of the effect code: the loop trained
    on ``front`` with every candidate family (gains are offered on request) adds ``gain panda_joint2``, recovers g
    against the same fit on the recorded angles, and
    the other placements spread less."""
    import dataclasses

    from arm_model.model import ArmModel
    from calibration.calibrate import calibrate
    from calibration.candidates import FAMILIES
    from calibration.data import make_data
    from calibration.loop import close_loop
    desc, art, pts = setup

    def inject(p):
        q = np.array(p.q, float)
        q[:, 1] /= 1 + GAIN
        return dataclasses.replace(p, q=q)
    inj = {p: inject(pts[p]) for p in PLACES}
    loop = close_loop(inj["front"], art, desc, families_=FAMILIES)
    assert [c.name for c in loop.added] == ["gain panda_joint2"], loop.verdict
    a, b, spread = _compare(desc, art, inj, "front", loop, ("right", "back-high"))
    # measured: 5.57 -> 1.14 mm (distance error 1.65 -> 0.71 mm)
    assert spread[1] <= 0.5 * spread[0], (a, b)
    model = ArmModel(desc, (loop.added[0].effect,))
    ref = calibrate(model, make_data(pts["front"], art, model), loop_fit_options())
    n = "panda_joint2.gain"
    diff, u = loop.model_fit.value(n) - ref.value(n), np.hypot(loop.model_fit.uncertainty(n), ref.uncertainty(n))
    # measured: 0.501 % +- 0.047 %
    assert abs(diff - GAIN) <= 3 * u and u < 0.2 * GAIN, (diff, u)


def test_a_joint_gain_the_data_cannot_resolve_is_prior_dominated(setup):
    """On the recorded angles the evidence finds the encoders' gains small (their group's scale is a few
    hundredths of the plausible 1 %); the last joint's gain, which the data would resolve only to about 10 % (the
    ball is near its axis), is prior-dominated: it stays at the nominal with the prior's uncertainty, never held
    and never a free value out of proportion. With the practical-resolution rule of earlier versions (no prior,
    ``min_resolution`` 0.1) it is held instead."""
    from arm_model.effects import JointGain
    from arm_model.model import ArmModel
    from calibration.calibrate import FitOptions, calibrate
    from calibration.data import make_data
    desc, art, pts = setup
    model = ArmModel(desc, (JointGain(),))
    data = make_data(pts["front"], art, model)
    res = calibrate(model, data, FitOptions(weights_from_data=True))
    assert res.prior_scales["effect joint_gain"] < 0.1
    k = res.free.index("panda_joint7.gain")
    assert res.state("panda_joint7.gain") == "prior-dominated" and res.prior_ratio[k] > 0.99
    assert abs(res.value("panda_joint7.gain")) < 0.01 * res.u[k]
    assert res.u[k] == pytest.approx(res.prior_sd[k], rel=0.01)
    assert res.prior_ratio[res.free.index("panda_joint2.gain")] < res.prior_ratio[k]
    legacy = calibrate(model, data, loop_fit_options())
    held = {f.name: f.reason for f in legacy.fixed}
    assert "weakly determined" in held["panda_joint7.gain"] and legacy.value("panda_joint7.gain") == 0.0


def test_an_eccentricity_the_data_cannot_resolve_is_shrunk_and_the_fit_converges(setup):
    """Trained on ``front`` alone, every joint's eccentricity (harmonics 1 and 2): the last joint's is
    resolved only to degrees (the ball is near its axis). Left free without a prior, such a harmonic wandered
    at each fit, a new one fell below the rank test each time and calibrate stopped with "the identifiable set
    kept changing between fits" (below); with the prior the fit converges, the last joint's second harmonics
    are prior-dominated and stay at the nominal within their prior's uncertainty, and no harmonic is held for
    being weak (only the rank test's exact dependences are)."""
    from arm_model.effects import EncoderEccentricity
    from arm_model.model import ArmModel
    from calibration.calibrate import FitOptions, calibrate
    from calibration.data import make_data
    desc, art, pts = setup
    model = ArmModel(desc, (EncoderEccentricity(),))
    res = calibrate(model, make_data(pts["front"], art, model), FitOptions(weights_from_data=True))
    assert res.status.startswith("converged")
    assert not [f.name for f in res.fixed if "weakly" in f.reason]
    for n in ("panda_joint7.ecc2_cos", "panda_joint7.ecc2_sin"):
        k = res.free.index(n)
        assert res.state(n) == "prior-dominated" and abs(res.value(n)) < 0.1 * res.prior_sd[k], n
    ecc = [n for n in res.free if ".ecc" in n]
    assert all(abs(res.value(n)) < 3 * res.uncertainty(n) + 1e-9 for n in ecc)


def test_an_identifiable_set_that_never_settles_is_reported_with_the_parameters(setup, monkeypatch):
    """The failure the prior (or the hold rule of earlier versions) removes is still reported when it
    happens: with the eccentricity's weak harmonics left free (no prior, the rule switched off for them), calibrate
    stops with a NumericalError naming the parameters the rank test held one fit after another (the last
    joint's harmonics)."""
    from arm_model.effects import EncoderEccentricity
    from arm_model.errors import NumericalError
    from arm_model.model import ArmModel
    from calibration.calibrate import calibrate
    from calibration.data import make_data
    desc, art, pts = setup
    monkeypatch.setattr(EncoderEccentricity, "held_when_weak", False)
    model = ArmModel(desc, (EncoderEccentricity(),))
    with pytest.raises(NumericalError, match=r"kept changing between fits \(held in turn: .*panda_joint7\.ecc"):
        calibrate(model, make_data(pts["front"], art, model), loop_fit_options())


def test_with_the_prior_a_cascade_of_exact_dependences_settles(setup):
    """Trained on ``back-high`` with joint compliance and every joint's eccentricity under the default prior:
    each fit's solution put one more of the last joint's harmonics and origin terms below the rank test (the
    ball is near that axis), and calibrate used to stop after four such fits with "the identifiable set kept
    changing between fits". With a prior every fit is well posed, so the holds go on until the set settles:
    the fit converges, every parameter held for rank is said with its combination, and the compliances are
    >= 0."""
    from arm_model.effects import EncoderEccentricity, JointCompliance
    from arm_model.model import ArmModel
    from calibration.calibrate import FitOptions, calibrate
    from calibration.data import make_data
    desc, art, pts = setup
    model = ArmModel(desc, (JointCompliance(), EncoderEccentricity()))
    res = calibrate(model, make_data(pts["back-high"], art, model), FitOptions(weights_from_data=True))
    assert res.status.startswith("converged")
    rank = [f for f in res.fixed if "not separable" in f.reason]
    assert len(rank) >= 5 and all(f.name.split(".")[0] in f.reason for f in rank)
    assert any(f.name.startswith("panda_joint7.ecc") for f in rank)
    assert all(res.value(n) >= 0 for n in res.free if n.endswith(".compliance"))
    assert not [f.name for f in res.fixed if "weakly" in f.reason]


def test_with_the_prior_joint_compliance_follows_the_evidence_and_is_never_negative(setup):
    """``--prior-scale evidence``: every fit chooses its own prior scales; trained on ``front``, joint compliance
    as physics is decided by the evidence alone (included exactly when the design set's log evidence with it is
    above the log evidence without: with the compliances' physical prior, 10 mrad under the data's RMS torque,
    it was not on this placement at the last measurement), every compliance of the model written is >= 0, and
    no parameter is held for being weak (the prior shrinks it instead)."""
    import re

    from calibration.loop import PHYSICS, close_loop
    desc, art, pts = setup
    lines: list[str] = []
    loop = close_loop(pts["front"], art, desc, prior_scale="evidence", progress=lines.append)
    checks = [m for line in lines for m in [re.search(r"physics check of joint compliance \(every loaded joint\): "
                                                      r"the evidence (does not favour|favours) it \(log evidence "
                                                      r"(-?[\d.]+) vs (-?[\d.]+) without\)", line)] if m]
    assert checks, "\n".join(lines)
    verdict, with_it, without = checks[0].group(1), float(checks[0].group(2)), float(checks[0].group(3))
    if with_it != without:                          # printed to 0.1: equal figures can go either way
        assert (verdict == "favours") == (with_it > without)
    added = [c.name for c in loop.added]
    assert ("joint compliance (every loaded joint)" in added) == (verdict == "favours"), loop.verdict
    if added:
        cv = [v for v in loop.stages[1].cv if v.candidate == loop.added[0].name][0]
        assert cv.reason.startswith(f"{PHYSICS}: the evidence favours it"), cv.reason
    fit = loop.model_fit or loop.final.result
    assert fit.prior_scales is not None
    comp = [n for n in fit.model.spec.names if n.endswith(".compliance") and not n.startswith("probe.")]
    assert all(fit.value(n) >= 0.0 for n in comp)
    assert not [f.name for f in fit.fixed if "weakly" in f.reason]
