"""Identifiability: the fit finds and names the combinations the data cannot separate, by itself."""
from __future__ import annotations

import numpy as np
import pytest

from arm_model import NumericalError
from arm_model.model import ArmModel
from arm_model.sim.quick import SynthSpec, make_campaign
from calibration import FitOptions, Weights, analyse, calibrate, make_data
from conftest import assert_close


def test_analyse_on_a_hand_built_matrix():
    """Columns a, b = 2 a (units differ), c independent: rank 2, one of a/b dependent with the exact
    combination, the SVD null vector (1, -1/2, 0) up to scale, condition by hand."""
    rng = np.random.default_rng(0)
    a = rng.normal(size=50)
    c = rng.normal(size=50)
    c -= (c @ a) / (a @ a) * a                  # orthogonal to a
    c *= np.linalg.norm(a) / np.linalg.norm(c)
    j = np.column_stack([a, 2 * a, c])
    idf = analyse(j, j, ["a", "b", "c"])
    assert idf.rank == 2
    assert len(idf.dependent) == 1 and idf.dependent[0] in ("a", "b")
    comb = idf.combinations[idf.dependent[0]]
    terms = dict(comb.terms)
    if idf.dependent[0] == "b":
        assert_close(terms["a"], -2.0, atol=1e-12)
    else:
        assert_close(terms["b"], -0.5, atol=1e-12)
    assert "c" not in terms
    null = dict(idf.null[0].terms)
    assert_close(null[idf.null[0].terms[0][0]], 1.0, atol=0)
    assert_close(null.get("b", 0) / null.get("a", 1), -0.5, atol=1e-12)
    # scaled columns: a/|a|, b/|b| equal, c/|c| orthogonal: singular values sqrt(2), 1
    assert_close(idf.singular_values[:2], [np.sqrt(2), 1.0], atol=1e-12)
    assert_close(idf.condition, np.sqrt(2), atol=1e-12)


@pytest.fixture(scope="module")
def artefact_data(nominal):
    model = ArmModel(nominal)
    c = make_campaign(model, SynthSpec(ballbars=8, ballbar_points=5, seats=3, articulations=8, spheres=1,
                                       sphere_points=10, noise=1e-6), seed=4)
    return model, c, make_data(c.points, c.artefacts, model)


def test_base_pose_not_observable_from_artefacts(artefact_data):
    """Without reference coordinates the base pose is invisible: the fit finds j1.theta_offset (rotation
    about the base z) and j1.d (translation along it) and names the exact equivalences of the chain's end
    (probe offset vs j7), without being told."""
    model, c, data = artefact_data
    res = calibrate(model, data, FitOptions(weights=Weights(probe=1e-6)))
    fixed = {f.name: f for f in res.fixed}
    assert {"j1.theta_offset", "j1.d"} <= set(fixed)
    for name in ("j1.theta_offset", "j1.d"):
        assert "rigid motion of the base" in fixed[name].reason
        assert name in res.identifiability.gauge
    # the ball is on the j7 axis: probe.x ~ j7.a and probe.z ~ j7.d exactly
    for pair in (("probe.x", "j7.a"), ("probe.z", "j7.d")):
        named = [f for f in res.fixed if f.name in pair]
        assert len(named) == 1
        terms = dict(named[0].combination.terms)
        other = pair[1] if named[0].name == pair[0] else pair[0]
        assert_close(terms[other], -1.0, atol=1e-6)
    assert not set(fixed) & set(res.free)
    assert res.identifiability_final.rank == len(res.free)


def test_reference_in_base_frame_makes_the_base_pose_identifiable(nominal):
    """Tracker points given in the base frame (reference='identity'): j1.theta_offset and j1.d become
    identifiable, and they are recovered."""
    model = ArmModel(nominal)
    c = make_campaign(model, SynthSpec(ballbars=4, seats=2, spheres=0, reference_points=60, noise=1e-6,
                                       reference_noise=1e-6), seed=6, T_ref_base=np.eye(4))
    data = make_data(c.points, c.artefacts, model, reference=c.reference_points)
    res = calibrate(model, data, FitOptions(weights=Weights(probe=1e-6, reference=1e-6), reference="identity"))
    assert "j1.theta_offset" in res.free and "j1.d" in res.free
    for n in ("j1.theta_offset", "j1.d"):
        assert abs(res.value(n) - c.truth[n]) < 4 * res.uncertainty(n)
    res2 = calibrate(model, data, FitOptions(weights=Weights(probe=1e-6, reference=1e-6), reference="fit"))
    assert {"j1.theta_offset", "j1.d"} <= {f.name for f in res2.fixed}


def test_stop_policy_lists_the_combinations(artefact_data):
    model, _, data = artefact_data
    with pytest.raises(NumericalError) as exc:
        calibrate(model, data, FitOptions(on_unidentifiable="stop"))
    msg = str(exc.value)
    assert "j1.theta_offset" in msg and "probe.z" in msg or "j7.d" in msg


def test_compliance_without_force_has_no_effect(artefact_data):
    model, _, data = artefact_data
    res = calibrate(model, data, FitOptions(free=["j2.*", "probe.compliance_*"], weights=Weights(probe=1e-6)))
    fixed = {f.name: f.reason for f in res.fixed}
    for n in ("probe.compliance_x", "probe.compliance_y", "probe.compliance_z"):
        assert "no effect" in fixed[n]
    assert set(res.free) == {"j2.theta_offset", "j2.d", "j2.a", "j2.alpha"}


def _urdf_arm(nominal, tmp_path):
    """The nominal arm written as a URDF (its stylus replaced by a fixed tip 85 mm out) and read back: six
    errors a joint origin."""
    from arm_model.urdf import urdf_text
    from arm_model.urdf_import import description_from_urdf
    text = urdf_text(nominal)
    text = text[: text.index('  <joint name="stylus_root_joint"')]
    text += ('  <joint name="tip_joint" type="fixed"><parent link="flange"/><child link="tip"/>'
             '<origin xyz="0.002 -0.001 0.085" rpy="0 0 0"/></joint>\n  <link name="tip"/>\n</robot>\n')
    path = tmp_path / "arm.urdf"
    path.write_text(text)
    return description_from_urdf(path, "tip")


def test_urdf_arm_origin_errors(nominal, tmp_path):
    """An arm given as a URDF (per-joint origin xyz/rpy errors, 6 a joint): the same code finds the
    redundant origin parameters (the first joint's 6 are rigid motions of the base) and recovers the
    rest in the identifiable parameterization."""
    model = ArmModel(_urdf_arm(nominal, tmp_path))
    assert model.spec.names[:6] == ("j1.origin_x", "j1.origin_y", "j1.origin_z", "j1.origin_roll",
                                    "j1.origin_pitch", "j1.origin_yaw")
    c = make_campaign(model, SynthSpec(ballbars=8, ballbar_points=5, seats=3, articulations=10, spheres=1,
                                       noise=1e-6), seed=8)
    res = calibrate(model, make_data(c.points, c.artefacts, model), FitOptions(weights=Weights(probe=1e-6)))
    j1 = {f"j1.origin_{k}" for k in ("x", "y", "z", "roll", "pitch", "yaw")}
    assert j1 <= set(res.identifiability.gauge)          # all six rigid motions found
    rigid = {f.name for f in res.fixed if "rigid motion" in f.reason}
    assert len(rigid) >= 6 and rigid <= set(res.identifiability.gauge)
    # j2's origin z acts along the j1 axis, and of its angles (turns about its own axes) the one about the
    # origin's own axis along j1's: rigid motions too (or exact equivalents)
    from arm_model.urdf import origin_matrix
    j1_axis, j2 = np.array(model.desc.joints[0].axis), model.desc.joints[1]
    about_j1 = ("roll", "pitch", "yaw")[int(np.argmax(np.abs(origin_matrix(j2.origin)[:3, :3].T @ j1_axis)))]
    assert {"j2.origin_z", f"j2.origin_{about_j1}"} <= set(res.identifiability.gauge)
    assert len(res.fixed) > 6 and res.identifiability_final.rank == len(res.free)
    peq = res.equivalent(c.p_true)
    z = [(res.value(n) - peq[model.spec.index(n)]) / res.uncertainty(n) for n in res.free]
    assert np.max(np.abs(z)) < 4.0


def test_modified_dh_arm(nominal):
    """Modified DH (Craig): the first row Rx(alpha) Tx(a) Rz(theta) Tz(d) holds four rigid motions of the
    base frame, all found; the rest is recovered within 3 sigma."""
    from dataclasses import replace
    model = ArmModel(replace(nominal, convention="mdh"))
    c = make_campaign(model, SynthSpec(ballbars=8, ballbar_points=5, seats=3, articulations=8, spheres=1,
                                       noise=1e-6), seed=9)
    res = calibrate(model, make_data(c.points, c.artefacts, model), FitOptions(weights=Weights(probe=1e-6)))
    assert {"j1.theta_offset", "j1.d", "j1.a", "j1.alpha"} <= set(res.identifiability.gauge)
    assert {"j1.theta_offset", "j1.d", "j1.a", "j1.alpha"} <= {f.name for f in res.fixed}
    peq = res.equivalent(c.p_true)
    z = [(res.value(n) - peq[model.spec.index(n)]) / res.uncertainty(n) for n in res.free]
    assert np.max(np.abs(z)) < 3.5 and len(res.free) >= 18


def test_base_set_of_the_full_origin_errors_is_the_literature_count(nominal, tmp_path):
    """The same 7-joint arm as a URDF (six errors a joint origin, three of the tip: 45) reduces, by the rank of
    the identification Jacobian and pivoted QR, to the base set the literature counts for revolute joints
    measured by a point: 4R + 2P + 6 (Everett, Driels and Mooring 1987) less the tool's orientation (3), so
    31 with the base pose known (reference points in the base frame) and 25 with it unknown (its 6 rigid
    motions a gauge). As DH rows (four errors a row) the base frame lacks two errors: 25 and 23."""
    spec = SynthSpec(ballbars=8, ballbar_points=5, seats=3, articulations=10, spheres=1, noise=1e-6,
                     reference_points=12)
    counts = {}
    for label, desc in (("urdf", _urdf_arm(nominal, tmp_path)), ("dh", nominal)):
        model = ArmModel(desc)
        c = make_campaign(model, spec, seed=8, T_ref_base=np.eye(4))
        data = make_data(c.points, c.artefacts, model, reference=c.reference_points)
        for ref in ("fit", "identity"):
            res = calibrate(model, data, FitOptions(weights=Weights(1e-6, 1e-6), reference=ref, prior_scale=None))
            assert res.identifiability_final.rank == len(res.free)
            counts[label, ref] = len(res.free)
    assert counts == {("urdf", "fit"): 25, ("urdf", "identity"): 31, ("dh", "fit"): 23, ("dh", "identity"): 25}


def test_nuisance_projection_dense_and_sparse_agree(monkeypatch):
    """The nuisance's elimination held dense (up to DENSE_UNKNOWNS nuisance unknowns) and sparse (the limit set
    to 0) give the same columns to 1e-12 of their size, orthogonal to every nuisance column, and a column made
    of nuisance columns alone projects to zero; one factorization serves several calls."""
    import scipy.sparse as sp

    import calibration.solver as solver
    from calibration.identifiability import NuisanceProjection, reduced_jacobian
    rng = np.random.default_rng(3)
    blocks = [rng.normal(size=(12, 3)) for _ in range(20)]         # 20 instances, 3 nuisance unknowns each
    jt = sp.block_diag(blocks, format="csr")
    jp = np.column_stack([rng.normal(size=(240, 5)), jt @ rng.normal(size=60)])
    dense = NuisanceProjection(jt)
    assert isinstance(dense.jt, np.ndarray)
    got = dense(jp)
    monkeypatch.setattr(solver, "DENSE_UNKNOWNS", 0)
    sparse = NuisanceProjection(jt)
    assert sp.issparse(sparse.jt)
    assert_close(got, sparse(jp), atol=1e-12 * np.abs(jp).max())
    assert_close(got, reduced_jacobian(jp, jt), atol=1e-12 * np.abs(jp).max())
    assert_close(jt.T @ got, np.zeros((60, 6)), atol=1e-11 * np.abs(jp).max())
    assert np.abs(got[:, 5]).max() < 1e-12 * np.abs(jp[:, 5]).max()
    assert_close(dense(jp[:, :2]), got[:, :2], atol=1e-13 * np.abs(jp).max())


def _twin_yaw_chain(q: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Tip points (N, 3) [m] of a small simulated chain at joint angles ``q`` (N, 3) [rad] and parameters ``p`` =
    (o1, l1, y2, o2, l2, o3, l3): Rz(q1 + o1) Tx(l1) Rz(y2) Rz(q2 + o2) Tx(l2) Ry(q3 + o3) Tx(l3), joints 1 and 2
    about parallel axes. The origin's yaw y2 and joint 2's offset o2 turn about the same axis: an exact two-fold
    ambiguity (either one explains the data as well as the other)."""
    def rz(t):
        c, s = np.cos(t), np.sin(t)
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])

    def ry(t):
        c, s = np.cos(t), np.sin(t)
        return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])

    o1, l1, y2, o2, l2, o3, l3 = p
    out = []
    for q1, q2, q3 in q:
        r1 = rz(q1 + o1)
        r2 = r1 @ rz(y2) @ rz(q2 + o2)
        r3 = r2 @ ry(q3 + o3)
        out.append(r1 @ [l1, 0, 0] + r2 @ [l2, 0, 0] + r3 @ [l3, 0, 0])
    return np.array(out)


def _twin_yaw_jacobian(seed: int) -> np.ndarray:
    """The chain's Jacobian [m/SI] by central differences at 12 random poses (numpy seed ``seed``)."""
    q = np.random.default_rng(seed).uniform(-1.5, 1.5, (12, 3))
    p0 = np.array([0.0, 0.4, 0.0, 0.0, 0.3, 0.0, 0.1])
    cols = []
    for k in range(len(p0)):
        d = np.zeros_like(p0)
        d[k] = 1e-6
        cols.append(((_twin_yaw_chain(q, p0 + d) - _twin_yaw_chain(q, p0 - d)) / 2e-6).ravel())
    return np.column_stack(cols)


def test_the_held_branch_of_an_exact_ambiguity_does_not_flip():
    """Of two parameters that explain the data equally (a simulated chain's origin yaw y2 and joint offset o2,
    equal plausible sizes), which one is held is decided by the tie keys (the chain's order: the later kept), not
    by the poses, the parameters' order, or unknowns added that the data do not need (nil columns, as an
    artefact's drift where every measurement is one point): the same branch every time. (LAPACK's pivoted QR with
    a tie weight of 1e-6 of a parameter's place over the parameter count, which this replaced, held o2 in some of
    these orders.)"""
    from calibration.identifiability import PRIOR_SCALES
    names = ["o1", "l1", "y2", "o2", "l2", "o3", "l3"]
    sizes = np.array([PRIOR_SCALES["rad" if n[0] in "oy" else "m"] for n in names])
    keys = [(0, k, "") for k in range(len(names))]
    nil = [f"drift{k:03d}" for k in range(60)]
    for seed in range(4):
        j = _twin_yaw_jacobian(seed)
        idf = analyse(j, j, names, pivot_scale=sizes, tie_key=keys)
        assert idf.rank == 6 and idf.dependent == ("y2",), idf
        assert dict(idf.combinations["y2"].terms) == pytest.approx({"y2": 1.0, "o2": -1.0}, abs=1e-6)
        # nil unknowns appended, with their own names
        big = np.column_stack([j, np.zeros((len(j), len(nil)))])
        more = analyse(big, big, names + nil, pivot_scale=np.r_[sizes, np.full(len(nil), 1e-3)],
                       tie_key=keys + [(1, 0, n) for n in nil])
        assert set(more.dependent) == {"y2", *nil}, more.dependent
        # the same parameters in other orders
        for perm in np.random.default_rng(seed).permuted(np.tile(np.arange(len(names)), (3, 1)), axis=1):
            shuffled = analyse(j[:, perm], j[:, perm], [names[k] for k in perm], pivot_scale=sizes[perm],
                               tie_key=[keys[k] for k in perm])
            assert shuffled.dependent == ("y2",), (perm, shuffled.dependent)
    # a larger plausible size of y2 keeps it (its plausible error moves the data more): o2 held
    wide = sizes.copy()
    wide[2] *= 3
    assert analyse(j, j, names, pivot_scale=wide, tie_key=keys).dependent == ("o2",)
