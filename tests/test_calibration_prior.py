"""The Gaussian prior on the free parameters (``prior_scale``, ``--prior-scale``, :mod:`calibration.prior`): its
limits (a wide prior is the plain fit, a narrow one the nominal), the MAP estimate as the minimum of data plus
prior cost, the evidence's choice of each group's scale against campaigns whose parameter errors are drawn at
known scales, no bias on well-determined parameters, the parameter groups, and the command line."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from arm_model.model import ArmModel
from arm_model.sim.quick import SynthSpec, make_campaign, random_truth
from calibration import FitOptions, Weights, calibrate, make_data
from calibration.calibrate import evidence_scale
from calibration.prior import (
    GROUP_ANGLES,
    GROUP_LENGTHS,
    GROUP_OFFSETS,
    GROUP_TIP,
    PRIOR_DOMINATED,
    parameter_groups,
    prior_spec,
)

SPEC = SynthSpec(ballbars=6, ballbar_points=5, seats=3, articulations=8, spheres=1, sphere_points=10, rings=0,
                 ring_points=0, planes=0, plane_points=0, reference_points=0, force=0.0, noise=5e-6,
                 reference_noise=5e-6)
W = Weights(probe=5e-6, reference=5e-6)


@pytest.fixture(scope="module")
def model(nominal):
    return ArmModel(nominal)


def _campaign(model, seed, length=1e-4, angle=1e-4, probe=1e-4):
    """A campaign whose length and probe errors are N(0, length), N(0, probe) [m] and angle errors N(0, angle)
    [rad]: ``length / 1 mm`` and ``angle / 1 mrad`` times the plausible sizes of calibration.prior."""
    rng = np.random.default_rng(seed)
    p = random_truth(model, rng, length=length, angle=angle, probe=probe)
    c = make_campaign(model, SPEC, seed=seed, p_true=p)
    return make_data(c.points, c.artefacts, model), p


def test_groups_of_a_dh_arm(model):
    """DH rows: theta_offset is a joint offset, alpha an axis angle, d and a lengths; probe.x/y/z the tip."""
    names = ["j2.theta_offset", "j2.d", "j2.a", "j2.alpha", "probe.x", "probe.compliance_z"]
    assert parameter_groups(model, names) == [GROUP_OFFSETS, GROUP_LENGTHS, GROUP_LENGTHS, GROUP_ANGLES, GROUP_TIP,
                                              "probe compliance"]


def test_groups_of_a_urdf_arm_follow_each_joint_axis():
    """URDF origins: an origin's angle errors turn it about its own axes, so of roll, pitch and yaw the one about
    the joint's own axis (whatever the origin's orientation) is the joint offset: on the Panda (every axis z,
    origins turned by roll +-90 deg) yaw, and a yaw error is the joint's own turn, the ball where that joint
    turned by as much puts it."""
    from arm_model import ball_centres
    from arm_model.params import param_spec
    from arm_model.urdf_import import load_arm
    from conftest import ROOT
    desc = load_arm(ROOT / "examples" / "data" / "real-panda-seats" / "panda.urdf", "ball_link")
    m = ArmModel(desc)
    q = np.random.default_rng(2).uniform(-1.0, 1.0, (4, desc.n_joints))
    spec = list(param_spec(desc).names)
    for k, j in enumerate(("panda_joint1", "panda_joint2", "panda_joint3")):
        names = [f"{j}.origin_{a}" for a in ("roll", "pitch", "yaw")]
        groups = parameter_groups(m, names)
        assert groups == [GROUP_OFFSETS if a == "yaw" else GROUP_ANGLES for a in ("roll", "pitch", "yaw")], j
        p = np.zeros(len(spec))
        p[spec.index(f"{j}.origin_yaw")] = 0.01
        turned = q.copy()
        turned[:, k] += 0.01
        assert np.abs(ball_centres(desc, q, None, p) - ball_centres(desc, turned)).max() < 1e-12


#: a lift and two revolute joints, written here: every origin turned about its own joint's axis
SLIDE_URDF = """<?xml version="1.0"?>
<robot name="slide">
  <link name="base"/><link name="carriage"/><link name="upper"/><link name="fore"/><link name="tool"/>
  <joint name="lift" type="prismatic"><parent link="base"/><child link="carriage"/>
    <origin xyz="0 0 0.5" rpy="0 0 0.3"/><axis xyz="0 0 1"/>
    <limit lower="0" upper="0.4" effort="1" velocity="1"/></joint>
  <joint name="shoulder" type="revolute"><parent link="carriage"/><child link="upper"/>
    <origin xyz="0.1 0 0" rpy="0 0 0.2"/><axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="reach" type="prismatic"><parent link="upper"/><child link="fore"/>
    <origin xyz="0.3 0 0" rpy="0.1 0 0"/><axis xyz="1 0 0"/>
    <limit lower="0" upper="0.2" effort="1" velocity="1"/></joint>
  <joint name="tool_joint" type="fixed"><parent link="fore"/><child link="tool"/><origin xyz="0.05 0 0"/></joint>
</robot>
"""


def test_a_prismatic_joint_has_no_angular_offset(tmp_path):
    """A slide's zero is a length (its origin's translation along the axis, a ``length``); the angle of its
    origin about its own axis orients the slide and what it carries (an ``axis angle``), unlike a revolute
    joint's, which is its encoder's zero (a ``joint offset``). The lift's axis is z (its yaw), the reach's x (its
    roll), the shoulder's z (its yaw)."""
    from arm_model.urdf_import import load_arm
    (tmp_path / "slide.urdf").write_text(SLIDE_URDF)
    m = ArmModel(load_arm(tmp_path / "slide.urdf", "tool"))
    for j in ("lift", "reach"):
        names = [f"{j}.origin_{a}" for a in ("x", "y", "z", "roll", "pitch", "yaw")]
        assert parameter_groups(m, names) == [GROUP_LENGTHS] * 3 + [GROUP_ANGLES] * 3, j
    names = [f"shoulder.origin_{a}" for a in ("roll", "pitch", "yaw")]
    assert parameter_groups(m, names) == [GROUP_ANGLES, GROUP_ANGLES, GROUP_OFFSETS]


def test_wide_prior_is_the_plain_fit_and_narrow_prior_the_nominal(model):
    data, _ = _campaign(model, 3)
    plain = calibrate(model, data, FitOptions(weights=W, prior_scale=None))
    wide = calibrate(model, data, FitOptions(free=list(plain.free), weights=W, prior_scale=1e4))
    idx = [model.spec.index(n) for n in plain.free]
    # a prior 1e4 times the plausible sizes moves the estimate by a negligible share of its uncertainty
    assert np.max(np.abs(wide.p[idx] - plain.p[idx]) / plain.u) < 1e-3
    assert np.allclose(wide.u, plain.u, rtol=1e-3)
    assert all(wide.state(n) == "free" for n in wide.free)
    narrow = calibrate(model, data, FitOptions(free=list(plain.free), weights=W, prior_scale=1e-9))
    size = prior_spec(model, data).size[idx]
    assert np.max(np.abs(narrow.p[idx]) / size) < 1e-8
    # the posterior uncertainty cannot exceed the prior's, and all of them are prior-dominated
    assert np.all(narrow.u <= 1e-9 * size * (1 + 1e-9))
    assert all(narrow.state(n) == "prior-dominated" for n in narrow.free)
    assert np.all(narrow.prior_ratio > PRIOR_DOMINATED)


def test_map_is_the_minimum_of_data_plus_prior_cost(model):
    """Each free parameter moved by +-0.3 of its posterior uncertainty (the others and the artefacts'
    unknowns refitted, the prior's scales held) raises data plus prior cost."""
    data, _ = _campaign(model, 5)
    res = calibrate(model, data, FitOptions(weights=W, covariance="stated"))
    idx = [model.spec.index(n) for n in res.free]
    total = res.cost + 0.5 * float(np.sum(((res.p - res.prior_centre)[idx] / res.prior_sd) ** 2))
    rng = np.random.default_rng(0)
    for name in rng.choice(list(res.free), 4, replace=False):
        k = list(res.free).index(name)
        for sign in (-1, 1):
            values = dict(zip(model.spec.names, res.p, strict=True))
            values[name] += sign * 0.3 * res.u[k]
            others = [n for n in res.free if n != name]
            r2 = calibrate(model, data, FitOptions(free=others, values=values, weights=W, prior_scale=res.prior_scales,
                                                   prior_centre=res.prior_centre))
            d = np.array([r2.p[model.spec.index(n)] - res.prior_centre[model.spec.index(n)] for n in res.free])
            assert r2.cost + 0.5 * float(np.sum((d / res.prior_sd) ** 2)) > total


@pytest.mark.parametrize("length,angle,seed", [(0.03e-3, 0.3e-3, 11), (0.3e-3, 0.03e-3, 12), (0.1e-3, 0.1e-3, 13)])
def test_evidence_finds_each_groups_scale(model, length, angle, seed):
    """Lengths and angles drawn at scales a decade apart (either way) or alike: the evidence puts each group's
    scale within a factor 2 of the RMS of its parameters' true errors over their plausible sizes, the truth
    expressed in the fitted (base) parameters (the held parameters' errors move along the combinations the
    data cannot see into the kept ones: a 0.3 mm length error held with ``probe.y`` shows in ``j7.alpha``)."""
    data, p = _campaign(model, seed, length=length, angle=angle)
    res = calibrate(model, data, FitOptions(weights=W))
    assert res.evidence[-1]["settled"]
    assert evidence_scale(model, data, FitOptions(weights=W))[0] == res.prior_scales
    eq = res.equivalent(p)
    for g in (GROUP_LENGTHS, GROUP_OFFSETS, GROUP_ANGLES):
        names = res.prior_groups[g]["parameters"]
        truth = np.sqrt(np.mean([(eq[model.spec.index(n)] / res.prior_groups[g]["size_at_scale_1"][n]) ** 2
                                 for n in names]))
        assert 0.5 < res.prior_scales[g] / truth < 2.0, (g, res.prior_scales, truth)


def _bias(model, seeds) -> tuple[list[float], dict[str, list[float]]]:
    """Over the campaigns of ``seeds``, for every parameter the data determine (posterior/prior variance below 0.1
    in each fit): z = (estimate - truth) / u, and the prior's own pull, (MAP - least squares) / u of the least-squares
    fit, by name."""
    z, pull = [], {}
    for seed in seeds:
        data, p = _campaign(model, seed, length=1e-4, angle=2e-4)
        res = calibrate(model, data, FitOptions(weights=W))
        ls = calibrate(model, data, FitOptions(weights=W, prior_scale=None, free=res.free))
        eq = res.equivalent(p)
        for k, n in enumerate(res.free):
            if res.prior_ratio[k] < 0.1:
                i = model.spec.index(n)
                z.append((res.p[i] - eq[i]) / res.u[k])
                pull.setdefault(n, []).append((res.p[i] - ls.p[i]) / ls.u[ls.free.index(n)])
    return z, pull


def test_the_prior_does_not_bias_well_determined_parameters_on_three_campaigns(model):
    """The study below on its first three campaigns (1.5 s of CPU): the same bounds, over 69 z values (measured: mean
    z -0.02, RMS 0.92, largest mean pull 0.06). A prior 4 times too narrow (the evidence's scales divided by 4 in
    the MAP fit) fails it: a mean pull of 0.84."""
    z, pull = _bias(model, range(100, 103))
    assert len(z) >= 60
    assert abs(np.mean(z)) < 0.3 and 0.7 < np.sqrt(np.mean(np.square(z))) < 1.4
    assert max(abs(np.mean(v)) for v in pull.values()) < 0.3


@pytest.mark.slow
def test_the_prior_does_not_bias_well_determined_parameters(model):
    """20 campaigns (slow: about 15 s): for every parameter the data determine (posterior/prior variance below
    0.1 in each fit), the mean over the campaigns of z = (estimate - truth) / u is within +-0.3 pooled over the
    parameters, and the prior's own pull, (MAP - least squares) / u of the least-squares fit, averages within
    +-0.3 for each parameter (measured: |pooled mean z| 0.02, pulls below 0.04)."""
    z, pull = _bias(model, range(100, 120))
    assert abs(np.mean(z)) < 0.3 and 0.7 < np.sqrt(np.mean(np.square(z))) < 1.4
    assert max(abs(np.mean(v)) for v in pull.values()) < 0.3


def test_large_errors_converge_to_the_noise(model):
    """Errors of 0.3 mm and 3 mrad: the artefacts' unknowns started from the nominal arm settled in another
    basin; started again from the fitted arm, the fit reaches the noise."""
    data, _ = _campaign(model, 1, length=0.3e-3, angle=3e-3, probe=0.3e-3)
    res = calibrate(model, data, FitOptions(weights=W))
    assert 0.8 < res.s0 < 1.2 and res.status.startswith("converged")


def test_an_off_axis_compliance_prior_comes_from_the_gravity_moment_about_its_axis():
    """Lateral compliance of the Panda (URDF masses): each parameter's prior size is 10 mrad over the RMS, over
    the data's poses, of the moment of gravity on the links its joint moves about that joint frame's x or y
    axis; the moments agree with Pinocchio's RNEA (the model's own evaluator of them) to 1e-9 N m. (Before,
    the axial torque was used: joint 1, whose axial gravity torque is nil, got the largest size, 0.1.)"""
    from arm_model.chain import NUMPY_OPS
    from arm_model.effects import Geometry, LateralCompliance, joint_frame
    from arm_model.io import read_artefacts, read_points
    from arm_model.params import split_params
    from arm_model.urdf_import import load_arm
    from calibration.prior import DEFLECTION
    from conftest import ROOT
    panda = ROOT / "examples" / "data" / "real-panda-seats"
    desc = load_arm(panda / "panda-with-inertials.urdf", "ball_link")
    model = ArmModel(desc, (LateralCompliance(),))
    data = make_data(read_points(panda / "front" / "points.csv", 7), read_artefacts(panda / "artefacts.toml"), model)
    spec = prior_spec(model, data)
    loads = LateralCompliance().gravity_loads(desc, data.points.q)
    rows, p_last, comp = split_params(desc, None)
    geom = Geometry([list(r) for r in rows], list(p_last), list(comp))
    for n, name in enumerate(model.spec.names[model.base_size:]):
        rms = np.sqrt(np.mean(loads[n] ** 2))
        assert spec.size[model.base_size + n] == pytest.approx(DEFLECTION / rms, rel=1e-12), name
    for k in (0, 17, 40):
        q = data.points.q[k]
        for i in range(7):
            o, (ux, uy, _) = joint_frame(desc, geom, list(q), i, NUMPY_OPS)
            mg, _ = model._pinocchio_moments(geom, list(q), i, o, [0.0] * 6)
            assert float(np.dot(mg, ux)) == pytest.approx(loads[2 * i][k], abs=1e-9)
            assert float(np.dot(mg, uy)) == pytest.approx(loads[2 * i + 1][k], abs=1e-9)


def test_a_physical_group_keeps_its_scale_while_the_evidence_moves_the_others():
    """MacKay's fixed point on two groups of two parameters each, both fully determined (rho = 0) and 3 prior
    sizes from the centre: the ordinary group's scale goes to sqrt((9 + 9) / 2) = 3 (hand-derived), the
    physical one (an angular compliance's, :attr:`PriorSpec.physical`) stays at its given scale."""
    from calibration.prior import PriorSpec, update_scales
    spec = PriorSpec(("lengths", "lengths", "effect c", "effect c"), np.array([1e-3, 1e-3, 2e-4, 2e-4]),
                     np.array([-np.inf, -np.inf, 0.0, 0.0]), ("a",) * 4, frozenset({"effect c"}))
    delta = np.array([3e-3, -3e-3, 6e-4, 6e-4])
    new, gamma = update_scales({"lengths": 1.0, "effect c": 1.0}, spec, [0, 1, 2, 3], delta, np.zeros(4))
    assert new["lengths"] == pytest.approx(3.0, rel=1e-12)
    assert new["effect c"] == 1.0 and gamma == {"lengths": 2.0, "effect c": 2.0}


def test_pooled_groups_share_one_fixed_point_and_the_others_keep_their_own():
    """``prior_groups="pooled"``: lengths (two parameters 3 sizes off, both determined), joint offsets (one, 1 size
    off, rho 0.5) and a physical compliance group. Pooled over the geometric groups the scale of both is
    sqrt((9 + 9 + 1) / (2 + 0.5)) = 2.757 (hand-derived), separate 3 and sqrt(1 / 0.5) = 1.414; the physical group
    stays at 1 either way, and so does the pool when its groups determine fewer than 0.5 parameters in all."""
    from calibration.prior import GEOMETRY_GROUPS, PriorSpec, update_scales
    spec = PriorSpec(("lengths", "lengths", "joint offsets", "effect c"), np.array([1e-3, 1e-3, 1e-3, 2e-4]),
                     np.array([-np.inf, -np.inf, -np.inf, 0.0]), ("a",) * 4, frozenset({"effect c"}))
    delta, rho = np.array([3e-3, -3e-3, 1e-3, 6e-4]), np.array([0.0, 0.0, 0.5, 0.0])
    start = {"lengths": 1.0, "joint offsets": 1.0, "effect c": 1.0}
    apart, gamma = update_scales(start, spec, [0, 1, 2, 3], delta, rho)
    pooled, gamma_pooled = update_scales(start, spec, [0, 1, 2, 3], delta, rho, GEOMETRY_GROUPS)
    assert apart["lengths"] == pytest.approx(3.0, rel=1e-12)
    assert apart["joint offsets"] == pytest.approx(np.sqrt(2.0), rel=1e-12)
    assert pooled["lengths"] == pooled["joint offsets"] == pytest.approx(np.sqrt(19 / 2.5), rel=1e-12)
    assert pooled["effect c"] == apart["effect c"] == 1.0 and gamma_pooled == gamma
    unseen, _ = update_scales(start, spec, [0, 1, 2, 3], delta, np.array([0.95, 0.95, 0.95, 0.0]), GEOMETRY_GROUPS)
    assert unseen["lengths"] == unseen["joint offsets"] == 1.0


def test_a_pooled_fit_gives_the_geometry_one_scale_and_says_so(model):
    """``prior_groups="pooled"`` on a simulated campaign whose lengths and tip are off by 0.1 mm and angles by 1 mrad
    (ten times as many plausible sizes): separate, the evidence gives both angles' groups a scale over twice the
    lengths' and the tip's; pooled, the four geometric groups one scale (each under its ceiling) between the separate
    ones, which the result, the console and summary.json name; an unknown choice is refused."""
    from calibration.cli import prior_lines
    data, _ = _campaign(model, 3, length=1e-4, angle=1e-3, probe=1e-4)
    apart = calibrate(model, data, FitOptions(weights=W))
    pooled = calibrate(model, data, FitOptions(weights=W, prior_groups="pooled"))
    geometry = [g for g in (GROUP_LENGTHS, GROUP_OFFSETS, GROUP_ANGLES, GROUP_TIP) if g in pooled.prior_scales]
    assert len(geometry) == 4 and apart.pooled_groups() == []
    sep = apart.prior_scales
    assert min(sep[GROUP_ANGLES], sep[GROUP_OFFSETS]) > 2 * max(sep[GROUP_LENGTHS], sep[GROUP_TIP]), sep
    tau = [pooled.prior_scales[g] for g in geometry]
    assert max(tau) == pytest.approx(min(tau), rel=1e-9), pooled.prior_scales
    assert min(sep[g] for g in geometry) < tau[0] < max(sep[g] for g in geometry)
    assert pooled.to_dict()["prior"]["pooled"] == geometry == pooled.pooled_groups()
    assert any("one scale for lengths" in line for line in prior_lines(pooled))
    with pytest.raises(ValueError, match="prior_groups"):
        FitOptions(prior_groups="together")


def test_joint_compliance_groups_are_physical_and_given_sizes_are_not():
    """prior_spec marks the joint compliance effect's group physical (every parameter sized by the data's
    torque); a size given for one of its parameters makes the group an ordinary one (the user's size)."""
    from arm_model.effects import JointCompliance
    from arm_model.io import read_artefacts, read_points
    from arm_model.urdf_import import load_arm
    from conftest import ROOT
    panda = ROOT / "examples" / "data" / "real-panda-seats"
    model = ArmModel(load_arm(panda / "panda-with-inertials.urdf", "ball_link"), (JointCompliance(),))
    data = make_data(read_points(panda / "front" / "points.csv", 7), read_artefacts(panda / "artefacts.toml"), model)
    assert prior_spec(model, data).physical == frozenset({"effect joint_compliance"})
    assert prior_spec(model, data, {"panda_joint2.compliance": 1e-3}).physical == frozenset()


def test_a_parameter_the_data_barely_see_has_no_say_in_its_groups_scale():
    """MacKay's fixed point on a group of three: two parameters fully determined (rho = 0) at 0.1 prior sizes from
    the centre, the third barely seen (rho = 0.97, the data's own uncertainty 5.7 prior sizes) and pulled 9 sizes
    off (a systematic pull on a direction the data barely see: the bundled ring's probe z). The scale is the
    determined ones' own, sqrt((0.01 + 0.01) / 2) = 0.1 (hand-derived); with the third counted, as before, it was
    sqrt(81.02 / 2.03) = 6.3 and grew round after round. At rho = 0.6 (prior-dominated, but seen) it still counts:
    sqrt(81.02 / 2.4) = 5.81."""
    from calibration.prior import PriorSpec, update_scales
    spec = PriorSpec(("tip offset",) * 3, np.full(3, 1e-3), np.full(3, -np.inf), ("a",) * 3)
    new, gamma = update_scales({"tip offset": 1.0}, spec, [0, 1, 2], np.array([1e-4, -1e-4, -9e-3]),
                               np.array([0.0, 0.0, 0.97]))
    assert new["tip offset"] == pytest.approx(0.1, rel=1e-12)
    assert gamma["tip offset"] == pytest.approx(2.03, rel=1e-12)
    seen, _ = update_scales({"tip offset": 1.0}, spec, [0, 1, 2], np.array([1e-4, -1e-4, -9e-3]),
                            np.array([0.0, 0.0, 0.6]))
    assert seen["tip offset"] == pytest.approx(np.sqrt(81.02 / 2.4), rel=1e-12)


def test_each_groups_scale_stops_at_the_ceiling_the_arms_dimensions_give(model):
    """The shipped AACMM (DH rows, an 85 mm stylus): the ceilings are 5 % of the tip's distance from the last joint
    (4.25 mm: scale 4.25), 0.5 % of the chain's length (the sum of its rows' hypot(d, a) and the stylus, summed by
    hand from its description) and 50 mrad; determined parameters 300 sizes off stop there, not at the old cap of
    100. A group whose sizes were given beyond the ceiling keeps at least scale 1."""
    import math

    from calibration.prior import PriorSpec, limits, update_scales
    desc = model.desc
    by_hand = sum(math.hypot(j.d, j.a) for j in desc.joints) + 0.085
    assert desc.chain_length == pytest.approx(by_hand, rel=1e-12)
    lim = limits(model)
    spec = model.spec
    assert lim[spec.index("probe.z")] == pytest.approx(0.05 * 0.085, rel=1e-12)
    assert lim[spec.index("j2.a")] == pytest.approx(0.005 * by_hand, rel=1e-12)
    assert lim[spec.index("j3.alpha")] == 0.05
    assert math.isinf(lim[spec.index("probe.compliance_x")])
    pspec = prior_spec(model, None)              # no effect: no data needed
    for g, top in ((GROUP_TIP, 4.25), (GROUP_LENGTHS, 5.0 * by_hand), (GROUP_ANGLES, 50.0), (GROUP_OFFSETS, 50.0)):
        kept = [i for i, n in enumerate(pspec.group) if n == g]
        new, _ = update_scales({g: 1.0}, pspec, kept, 0.3 * np.ones(len(kept)), np.zeros(len(kept)))
        assert new[g] == pytest.approx(top, rel=1e-9), g
    wide = PriorSpec(("lengths",), np.array([0.05]), np.array([-np.inf]), ("given",), limit=np.array([5e-3]))
    assert wide.ceiling("lengths") == 1.0


def _ring(model, measurements: int, copies: int):
    """The bundled ring campaign's first ``measurements`` measurements, every row given ``copies`` times, copy k's
    joint readings k 1e-10 rad apart (a reading repeated exactly counts once, :class:`calibration.problem.Problem`;
    these are poses measured again, their ball centres 1e-10 m apart at a metre, 3e-5 of the noise)."""
    import dataclasses

    from arm_model.io import read_artefacts, read_points
    from conftest import ROOT
    ring = ROOT / "examples" / "data" / "paper-ring-xyz"
    data = make_data(read_points(ring / "points.csv", 7), read_artefacts(ring / "artefacts.toml"), model)
    rows = np.flatnonzero(np.isin(data.points.measurement, sorted(set(data.points.measurement))[:measurements]))
    out = data.select(np.tile(rows, copies))
    q = out.points.q + np.repeat(np.arange(copies), len(rows))[:, None] * 1e-10
    return dataclasses.replace(out, points=dataclasses.replace(out.points, q=q))


RING_OPTIONS = FitOptions(weights=Weights(probe=2.94e-6), gross_threshold=None, discrepancy=False)


@pytest.fixture(scope="module")
def ring_x4(model):
    """The bundled ring's first four measurements, every row given four times (1152 rows), and their default fit
    with the weights held (about 0.9 s of CPU)."""
    data = _ring(model, 4, 4)
    return data, calibrate(model, data, RING_OPTIONS)


def test_the_tip_offset_a_ring_barely_sees_does_not_run_away_on_repeated_rows(model, ring_x4):
    """The bundled ring (stylus parallel to the ring's axis: probe z seen only through the stylus' tilt), its first
    four measurements given four times (1152 rows; about 1.5 s of CPU with the rows given once), the default fit:
    before, probe z's pull (the scatter of the joint readings, which tilt the stylus) raised the tip offset's scale
    to its cap of 100 and probe z ran from 85 mm to -89 mm (-173.6 mm off), behind the wrist. Now the scale is probe
    x and y's (0.01) and every parameter is where the rows given once put it, within their uncertainty, probe z
    within a micrometre."""
    once = calibrate(model, _ring(model, 4, 1), RING_OPTIONS)
    res = ring_x4[1]
    assert res.evidence[-1]["settled"] and res.prior_scales[GROUP_TIP] <= 0.02
    assert abs(res.value("probe.z")) < 1e-6
    assert res.free == once.free
    for k, n in enumerate(once.free):
        assert abs(res.value(n) - once.value(n)) < 2 * once.u[k], n


def test_the_nominal_baseline_fits_its_tip_offset_under_the_prior(model):
    """The like-for-like nominal of the bundled ring's first three measurements: before, its tip offset was fitted by
    least squares and probe z moved by -252 +- 30 mm (the ball 167 mm behind the wrist); under the calibration's prior
    (the evidence's scale, probe z barely seen) it stays within a micrometre, probe x and y still fitted (the fit
    without a prior, ``--prior-scale off``, is least squares as before)."""
    from calibration.calibrate import nominal_baseline
    data = _ring(model, 3, 1)
    opts = FitOptions(weights=Weights(probe=2.94e-6))
    base = nominal_baseline(model, data, opts)
    assert base.free == ("probe.x", "probe.y", "probe.z") and base.prior_scales is not None
    assert abs(base.value("probe.z")) < 1e-6
    plain = nominal_baseline(model, data, replace(opts, prior_scale=None))
    assert plain.prior_scales is None and plain.value("probe.z") < -0.1
    for n in ("probe.x", "probe.y"):
        assert abs(base.value(n) - plain.value(n)) < 2 * plain.uncertainty(n), n


def test_a_scale_the_data_shrink_reaches_the_floor_in_few_rounds(ring_x4):
    """The ring x4 fit: every group's true errors are about nil (a simulated arm with micrometre errors), and the
    joint offsets' fixed point shrinks their scale by about a tenth a round from 0.038 on (measured: the plain
    MacKay iteration 11 rounds, each a full refit, stopped at 0.0104 by its damping from the tenth round). The
    secant (:func:`calibration.prior.secant_gains`) lengthens those ever equal steps: at the floor of 0.01 in 6."""
    from calibration.prior import SCALE_RANGE
    res = ring_x4[1]
    assert res.evidence[-1]["settled"] and len(res.evidence) <= 6, [h["scales"] for h in res.evidence]
    assert res.prior_scales[GROUP_OFFSETS] == pytest.approx(SCALE_RANGE[0], rel=1e-9)


def test_the_accelerated_evidence_reaches_the_plain_fixed_points_optimum(model, ring_x4, monkeypatch):
    """The same fit with the plain fixed point (every gain 1: MacKay's iteration, 12 rounds here): the scales agree
    within the stopping tolerance (2 %) and every parameter within 0.01 of its standard uncertainty (measured:
    4e-8 u at most; the plain iteration with the tolerance 1e-4 agrees with both to 1e-7 u)."""
    import sys
    data, fast = ring_x4
    plain = lambda steps, last, tol: dict.fromkeys(steps, 1.0)      # noqa: E731
    monkeypatch.setattr(sys.modules["calibration.calibrate"], "secant_gains", plain)
    slow = calibrate(model, data, RING_OPTIONS)
    assert len(slow.evidence) >= 2 * len(fast.evidence) - 1
    assert slow.free == fast.free
    for g, tau in fast.prior_scales.items():
        assert tau == pytest.approx(slow.prior_scales[g], rel=0.05), g
    z = [(fast.value(n) - slow.value(n)) / fast.u[k] for k, n in enumerate(fast.free)]
    assert max(np.abs(z)) < 0.01, dict(zip(fast.free, z, strict=True))


def test_secant_gains_by_hand():
    """Hand-derived gains: a log step that stays equal (a scale shrinking to its floor) gets the largest gain; a map
    x <- x + r with r = -0.5 x (slope -0.5) gets 2, Newton's, which lands on its root; a 2-cycle (r = +-a, moves
    +-a: slope -2) gets 0.5, its middle; a key without history, whose last move or whose step is within the
    tolerance, 1; a step that grew as the scale moved its way (the other groups' moves: a KUKA iiwa's joint offsets,
    r = -0.5 then -1.42 over a move of -0.5, slope +1.84) 1, and one that grew by a tenth of the move at most (slope
    +0.1, a creep) the largest."""
    from calibration.prior import MAX_GAIN, secant_gains
    x0, x1 = 4.0, 2.0                      # r(x) = -0.5 x: from 4 a plain step to 2, then the secant step
    g = secant_gains({"a": -0.5 * x1, "b": -0.1, "c": 0.3, "d": 0.2, "e": 0.1, "f": 0.01},
                     {"a": (-0.5 * x0, x1 - x0), "b": (-0.1, -0.1), "c": (-0.3, -0.3), "d": (0.1, 0.015),
                      "f": (0.1, 0.1)}, 0.02)
    assert g["a"] == pytest.approx(2.0, rel=1e-12) and x1 + g["a"] * (-0.5 * x1) == pytest.approx(0.0, abs=1e-12)
    assert g["b"] == MAX_GAIN and g["c"] == pytest.approx(0.5, rel=1e-12)
    assert g["d"] == g["e"] == g["f"] == 1.0
    g = secant_gains({"grew": -1.42, "creep": -0.11}, {"grew": (-0.5, -0.5), "creep": (-0.1, -0.1)}, 0.02)
    assert g["grew"] == 1.0 and g["creep"] == MAX_GAIN
