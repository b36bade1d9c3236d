"""Residual diagnostics against independent references: the score statistic against an actual refit,
the joint-angle columns against finite differences, folds, Holm's adjustment by hand, candidates."""
from __future__ import annotations

from functools import cache

import numpy as np
import pytest

from arm_model.effects import EncoderEccentricity, JointCompliance
from arm_model.model import ArmModel
from arm_model.sim.quick import SynthSpec, make_campaign, random_truth
from calibration.calibrate import FitOptions, calibrate
from calibration.candidates import library_candidates, needs_model
from calibration.data import Weights, make_data
from calibration.diagnostics import (
    JointAngleOffset,
    f_upper_tail,
    holm,
    measurement_folds,
    residual_space,
    screen_candidates,
)


@cache
def fitted(desc):
    """A synthetic campaign with a hidden j2 eccentricity, fitted without it."""
    truth = ArmModel(desc, (EncoderEccentricity(joints=(1,), harmonics=(1,)),))
    p = random_truth(truth, np.random.default_rng(5), length=30e-6, angle=5e-5, probe=30e-6)
    p[truth.spec.index("j2.ecc1_cos")] = 2e-5
    p[truth.spec.index("j2.ecc1_sin")] = -3e-5
    camp = make_campaign(truth, SynthSpec(ballbars=8, ballbar_points=4, seats=3, articulations=8, spheres=4,
                                          sphere_points=8, noise=2e-6), seed=5, p_true=p)
    data = make_data(camp.points, camp.artefacts, needs_model(desc, [JointCompliance()]))
    # least squares (no prior): the score tests are of a least-squares fit
    res = calibrate(ArmModel(desc), data, FitOptions(weights=Weights(probe=2e-6), prior_scale=None))
    return camp, data, res


def test_score_statistic_matches_the_refit(nominal):
    """delta chi2 of the score test = the drop of sum(r_w^2) when the effect is fitted (to first order), and
    the one-step estimate = the refitted parameters."""
    camp, data, res = fitted(nominal)
    eff = EncoderEccentricity(joints=(1,), harmonics=(1,))
    cand = [c for c in library_candidates(nominal, data)[0] if c.name == "eccentricity j2"][0]
    cand = type(cand)(cand.name, eff, cand.family, cand.joint)
    (test,), _ = screen_candidates(res, [cand], measurement_folds(data, 3))
    refit = calibrate(ArmModel(nominal, (eff,)), data, FitOptions(weights=Weights(probe=2e-6), prior_scale=None))
    drop = 2 * res.cost - 2 * refit.cost
    assert test.rank == 2
    assert test.delta_chi2 == pytest.approx(drop, rel=0.02)
    for name, b in zip(test.names, test.estimate, strict=True):
        assert b == pytest.approx(refit.value(name), abs=0.05 * abs(refit.value(name)) + 1e-7)
    assert test.p_value < 1e-10 and test.explained_cv > 0.5


def test_joint_angle_columns_are_the_ball_sensitivity(nominal):
    """The diagnostic JointAngleOffset effect's Jacobian equals d(ball)/d(q_j) by central differences."""
    model = ArmModel(nominal, (JointAngleOffset(),))
    q = np.random.default_rng(0).uniform(-1, 1, (5, nominal.n_joints))
    f = model.casadi_function()
    import casadi as ca
    p = ca.SX.sym("p", model.spec.size)
    aux = np.zeros(ArmModel.aux_width(nominal.n_joints))
    jac = ca.Function("j", [p], [ca.jacobian(f(q[0], np.zeros(6), aux, p), p)])
    j = np.asarray(jac(np.zeros(model.spec.size)))[:, model.base_size:]
    h = 1e-6
    for k in range(nominal.n_joints):
        dq = np.zeros(nominal.n_joints)
        dq[k] = h
        fd = (ArmModel(nominal).ball_centres(q[:1] + dq) - ArmModel(nominal).ball_centres(q[:1] - dq))[0] / (2 * h)
        np.testing.assert_allclose(j[:, k], fd, atol=1e-7)


def test_residual_space_is_orthogonal_to_the_fit(nominal):
    _, _, res = fitted(nominal)
    space = residual_space(res)
    free = [space.model.spec.index(n) for n in res.free]
    assert np.max(np.abs(space.project(space.jp[:, free]))) < 1e-6 * np.max(np.abs(space.jp[:, free]))
    assert np.max(np.abs(space.basis.T @ space.r)) < 1e-4 * np.linalg.norm(space.r)


def test_folds_hold_whole_measurements(nominal):
    _, data, _ = fitted(nominal)
    a = measurement_folds(data, 3)
    assert set(a) == set(data.measurements()) and set(a.values()) == {0, 1, 2}
    counts = np.bincount(list(a.values()))
    assert counts.max() - counts.min() <= 3      # one stratum may leave one extra in a fold
    with pytest.raises(ValueError):
        measurement_folds(data, 1)


def _shuffled(data, seed):
    """The same data with its rows in another order."""
    return data.select(np.random.default_rng(seed).permutation(len(data)))


def test_splits_are_functions_of_the_data_not_of_the_row_order(nominal):
    """The loop's test set and folds (no seed): the rows shuffled give the same measurements in each fold and
    the same poses held out (compared by their joint angles)."""
    from calibration.data import split_poses
    from calibration.diagnostics import pose_folds
    from calibration.loop.folds import spread_measurements
    _, data, _ = fitted(nominal)

    def poses(d, mask):
        return sorted(map(tuple, np.round(d.points.q[mask], 12)))
    for seed in (1, 2):
        other = _shuffled(data, seed)
        assert measurement_folds(other, 3) == measurement_folds(data, 3)
        assert spread_measurements(other, 0.25) == spread_measurements(data, 0.25)
        assert poses(other, split_poses(other, 0.25)) == poses(data, split_poses(data, 0.25))
        for blocked in (False, True):
            fa, fb = pose_folds(data, 4, blocked), pose_folds(other, 4, blocked)
            for f in range(4):
                assert poses(other, fb == f) == poses(data, fa == f), (blocked, f)


def test_blocked_folds_by_hand():
    """Poses t v / 12 on a line in joint space (t = 0..11 given shuffled): 4 blocked folds are the four runs of 3
    consecutive t (the line bisected at its middle, each half at its own), 3 folds runs of 4 (the first cut at
    1/3: floor(3/2) = 1 fold's share on one side); the same on the poses -t v / 12."""
    from calibration.data import blocked_folds
    t = np.random.default_rng(0).permutation(12).astype(float)
    v = np.array([0.2, -0.9, 0.1])
    for q in (np.outer(t, v) / 12, np.outer(-t, v) / 12):
        for k in (4, 3):
            f = blocked_folds(q, k)
            runs = [set(t[f == g]) for g in range(k)]
            assert sorted(map(sorted, runs)) == [list(np.arange(i, i + 12 // k, dtype=float))
                                                 for i in range(0, 12, 12 // k)], (k, f)


def test_blocked_folds_lie_apart_from_their_training_poses():
    """A sweep-like pose set (48 poses spread over a plane of a 7-joint space, with scatter): each held-out
    pose's nearest training pose is on average more than 1.5 times as far with blocked folds as with the dealt
    ones, the folds are equal in size, and the construction depends on the poses alone (rows shuffled: the
    same poses in each fold)."""
    from calibration.data import blocked_folds, pose_order
    rng = np.random.default_rng(3)
    plane = rng.normal(size=(2, 7))
    q = rng.uniform(-1, 1, (48, 2)) @ plane + 0.02 * rng.normal(size=(48, 7))

    def nearest(f):
        return np.mean(np.concatenate([np.min(np.linalg.norm(q[f == g][:, None] - q[f != g][None], axis=2), axis=1)
                                       for g in range(4)]))
    blocked = blocked_folds(q, 4)
    dealt = np.empty(48, dtype=int)
    dealt[pose_order(q)] = np.arange(48) % 4
    assert np.bincount(blocked).tolist() == [12] * 4
    assert nearest(blocked) > 1.5 * nearest(dealt), (nearest(blocked), nearest(dealt))
    perm = rng.permutation(48)
    again = blocked_folds(q[perm], 4)
    for g in range(4):
        assert sorted(perm[again == g]) == sorted(np.flatnonzero(blocked == g))


def test_blocked_pose_folds_keep_each_feature_fittable(nominal):
    """Blocked folds by pose on a campaign: every fold holds poses out, and every instance keeps at least the
    points its fit needs outside each fold; LoopSettings refuses an unknown way of folding."""
    from calibration.data import pose_groups
    from calibration.diagnostics import pose_folds
    from calibration.kinds import MIN_POINTS
    from calibration.loop import LoopSettings
    _, data, _ = fitted(nominal)
    f = pose_folds(data, 4, blocked=True)
    assert all(np.sum(f == g) > 0 for g in range(4))
    for kind, rows in pose_groups(data):
        for g in range(4):
            assert np.sum(f[rows] != g) >= MIN_POINTS[kind][0], (kind, g)
    with pytest.raises(ValueError, match="pose_folds"):
        LoopSettings(pose_folds="random")


def test_pose_order_and_spread_by_hand():
    """Poses t v on a line in joint space, v = (0.2, -0.9, 0.1), given out of order: ordered along the axis
    whose largest component (q2) is positive, -v, so by decreasing t (whatever the sign the SVD gives);
    the poses -t v in the reverse order. spread(8, 2) takes ranks 2 and 6, spread(10, 3) ranks 1, 5, 8."""
    from calibration.data import pose_order, spread
    t = np.array([3.0, -1.0, 0.0, 2.0, 1.0])
    q = np.outer(t, [0.2, -0.9, 0.1])
    assert list(pose_order(q)) == [0, 3, 4, 2, 1]
    assert list(pose_order(-q)) == [1, 2, 4, 3, 0]
    assert list(spread(8, 2)) == [2, 6] and list(spread(10, 3)) == [1, 5, 8]


def test_holm_by_hand():
    # p sorted 0.01, 0.02, 0.04 (m = 3): 3*0.01, max(0.03, 2*0.02), max(0.04, 1*0.04)
    np.testing.assert_allclose(holm([0.04, 0.01, 0.02, np.nan])[:3], [0.04, 0.03, 0.04])
    assert np.isnan(holm([0.04, 0.01, 0.02, np.nan])[3])


def test_f_upper_tail_is_scipy_s_f_survival_function():
    """The one F-test p-value of the package (the structure tests' and the held-out verdict's) equals
    scipy.stats.f.sf over small and large degrees of freedom and F from 0 to far in the tail; F = 0 gives 1,
    a negative F (not reachable from sums of squares) 1 as stats.f.sf does, NaN stays NaN; and one hand value:
    F(2, 2) has P(F > f) = 1 / (1 + f)."""
    from scipy import stats
    for dfn in (1, 2, 3.5, 12, 200):
        for dfd in (1, 4, 10.5, 87, 5000):
            for f in (0.0, 1e-6, 0.3, 1.0, 2.7, 15.0, 1e3):
                want = float(stats.f.sf(f, dfn, dfd))
                assert abs(f_upper_tail(f, dfn, dfd) - want) <= 1e-12 * want + 1e-300, (f, dfn, dfd)
    assert f_upper_tail(0.0, 3, 7) == 1.0 and f_upper_tail(-1.0, 3, 7) == 1.0
    assert np.isnan(f_upper_tail(float("nan"), 3, 7))
    assert abs(f_upper_tail(3.0, 2, 2) - 0.25) < 1e-15


def test_candidates_follow_the_data(nominal):
    _, data, _ = fitted(nominal)
    cands, skipped = library_candidates(nominal, data)
    names = [c.name for c in cands]
    assert "eccentricity j7" in names and "joint compliance j2" in names
    assert not any(n.startswith("gain ") for n in names)          # offered on request only
    gains = [c.name for c in library_candidates(nominal, data, families=["joint_gain"])[0]]
    assert gains == [f"gain j{i}" for i in range(1, 8)]
    assert not any(n.startswith(("force sensor", "probe compliance", "thermal")) for n in names)
    why = {s.name: s.reason for s in skipped}
    assert "no force data" in why["force sensor"] and "temperature" in why["thermal growth"]
    with pytest.raises(ValueError, match="unknown candidate"):
        library_candidates(nominal, data, families=["gravity"])


def test_a_seat_pair_length_offset_is_the_arm_shrunk_to_a_point(nominal):
    """On seat pairs a certified length's offset lies almost whole in the arm's scale; what the projection off the
    geometry leaves of it is the scale's move of each seat's articulations about their centre, i.e. the residual
    itself (independent check: its cosine with the residual), and its score step is the bar's whole length. The
    structure tests count it as absorbed (a step beyond a plausible length error): before, the
    ``artefact`` family "explained" nearly all of the residual of every seat campaign, and the decisions' forward
    selection, given it, found nothing else (docs/studies/close-loop.md, Hidden effects on robots)."""
    from calibration.diagnostics import families, structure_tests, test_family, test_group
    model = ArmModel(nominal)
    p = random_truth(model, np.random.default_rng(2), length=30e-6, angle=5e-5, probe=30e-6)
    # a robot's scatter on a short bar, its certificate as loose as the scatter (as scripts/robot_hidden_study.py's):
    # with a measuring arm's 2 um and a 0.8 um certificate what is left of the offset is under the rank tolerance
    spec = SynthSpec(ballbars=8, ballbar_kind="seat", ballbar_points=5, ballbar_length=0.1, seats=0, spheres=0,
                     noise=1e-4, u_length=1.3e-4)
    camp = make_campaign(model, spec, seed=2, p_true=p)
    data = make_data(camp.points, camp.artefacts, model)
    res = calibrate(model, data, FitOptions(weights=Weights(probe=1e-4), prior_scale=None))
    space = residual_space(res)
    fam = next(f for f in families(space) if f.name == "artefact")
    cols, names = fam.columns(space)
    k = next(i for i, n in enumerate(names) if n.startswith("length"))
    c = space.project(cols[:, [k]])[:, 0]
    assert abs(c @ space.r) > 0.9 * np.linalg.norm(c) * np.linalg.norm(space.r)
    raw = test_group(space, cols[:, [k]], [names[k]], "length", None)
    assert abs(raw.estimate[0]) == pytest.approx(0.1, rel=0.1) and raw.explained > 0.8
    guarded = test_family(space, fam, cols, names, None)
    assert names[k] in guarded.absorbed
    assert dict((f.name, t.p_value) for f, t in structure_tests(space, None))["artefact"] > 0.01


@pytest.mark.parametrize("name, bad", [("max_effects", 1001), ("cv_top", 10 ** 300), ("pairs", 1001)],
                         ids=["max_effects", "cv_top", "pairs"])
def test_loop_counts_are_bounded(name, bad):
    """The loop's counts stop at MAX_COUNT (more than any library offers), the CLI's bound and the API's the same:
    ``cv_top`` 10^300 was taken and written to summary.json as a 301-digit integer."""
    from calibration.loop import LoopSettings
    from calibration.loop.settings import MAX_COUNT
    assert MAX_COUNT == 1000
    LoopSettings(**{name: MAX_COUNT})
    with pytest.raises(ValueError, match=f"{name} must be at most 1000"):
        LoopSettings(**{name: bad})
