"""What the second red team (scripts/hidden_effects_study.py ``base-tilt`` and ``bent-stylus``,
scripts/robot_hidden_study.py on simulated robots; docs/studies/close-loop.md "Hidden effects on robots")
found and fixed, each checked on its own:

* the mount's tilt under the arm's moment (the first joint's lateral compliance) is a library candidate on request
  (family ``base_tilt``; not a default one: it made the real Panda's other placements worse), not only an effect
  built from a ``j1 lateral load`` family the Bonferroni over every
  structure family rarely lets through;
* a ``contact force`` family builds the probe compliance's tilted axes (the xz and yz terms: a bent stylus) beside
  the full matrix, whose six terms the folds of a small campaign cannot afford;
* the simulator places a motion-capture marker where a lateral compliance puts it (it moved the tip frame's origin
  and added the unturned offset: its own truth check stopped the campaign);
* the loop takes a joint compliance's torques at the base fit's static equilibrium, as the model file does.
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from arm_model import PinocchioArm
from arm_model.effects import JointGain, LateralCompliance, ProbeCompliance, ProbeComplianceMatrix
from arm_model.io import PointSet
from arm_model.model import ArmModel, AuxData
from arm_model.sim import campaign_from_dict, simulate
from arm_model.tracker import offset_matrix
from calibration.calibrate import default_effects
from calibration.candidates import (
    DEFAULT_FAMILIES,
    FAMILIES,
    OPT_IN_FAMILIES,
    Candidate,
    Skipped,
    library_candidates,
)
from calibration.data import Weights, make_data
from calibration.loop import close_loop, heldout_figures
from calibration.model_output import with_fitted_torques
from calibration.synthesis import synthesise
from conftest import assert_close

ROOT = Path(__file__).resolve().parents[1]
PANDA = ROOT / "examples/data/real-panda-seats/panda-with-inertials.urdf"


def _points(desc, n: int, force: bool, seed: int = 0) -> PointSet:
    rng = np.random.default_rng(seed)
    f = rng.normal(0.0, 2.0, (n, 3)) if force else None
    return PointSet("mem.csv", np.array([f"m{i % 3}" for i in range(n)]), np.array([""] * n),
                    rng.uniform(-2.0, 2.0, (n, desc.n_joints)), force=f, force_kind="xyz" if force else None,
                    ref=rng.normal(0.0, 1.0, (n, 1, 3)), lines=np.arange(2, n + 2))


def _library(desc, pts):
    return library_candidates(desc, make_data(pts, None, ArmModel(desc, (LateralCompliance(joints=(0,)),))),
                              families=FAMILIES)


def test_the_base_tilt_is_a_library_candidate_where_a_torque_loads_the_arm(nominal):
    """On request (``--candidates ...,base_tilt``: not a default family, it made real placements worse), offered
    as ``lateral compliance j1`` (the name the structure family's effect gets, so it is built once) on an
    arm with masses; left out, with the reason, on an arm without masses measured without force; with force data
    it is offered again (the contact's moment tilts the mount)."""
    cands, _ = _library(nominal, _points(nominal, 12, force=False))
    tilt = [c for c in cands if c.family == "lateral_compliance"]
    assert [c.name for c in tilt] == ["lateral compliance j1"]
    assert tilt[0].effect == LateralCompliance(joints=(0,)) and tilt[0].size(nominal) == 2
    massless = replace(nominal, joints=tuple(replace(j, mass=0.0) for j in nominal.joints))
    cands, skipped = _library(massless, _points(massless, 12, force=False))
    assert not [c for c in cands if c.family == "lateral_compliance"]
    assert any(isinstance(s, Skipped) and "base tilt" in s.name and "no masses" in s.reason for s in skipped)
    cands, _ = _library(massless, _points(massless, 12, force=True))
    assert [c.name for c in cands if c.family == "lateral_compliance"] == ["lateral compliance j1"]
    cands, _ = library_candidates(nominal, make_data(_points(nominal, 12, False), None,
                                                     ArmModel(nominal, (LateralCompliance(joints=(0,)),))),
                                  families=("eccentricity",))
    assert all(isinstance(c, Candidate) and c.family == "eccentricity" for c in cands)
    cands, _ = library_candidates(nominal, make_data(_points(nominal, 12, False), None,
                                                     ArmModel(nominal, (LateralCompliance(joints=(0,)),))))
    assert "base_tilt" not in DEFAULT_FAMILIES and not [c for c in cands if c.family == "lateral_compliance"]


def test_the_reading_couplings_are_an_opt_in_family_named_as_synthesis_builds_them(nominal):
    """On request or by the escalation (not a default family: one candidate a pair of joints), ``coupling jN by qK``
    for every ordered pair of revolute joints whose source angle varies, each ``JointGain(source=K)`` under the name
    :mod:`calibration.synthesis` gives the effect built from a ``qK harmonics on jN`` family (so it is built once);
    a source joint at one angle throughout the data gives none (its coupling is an offset of jN)."""
    assert "joint_coupling" in OPT_IN_FAMILIES and "joint_coupling" not in DEFAULT_FAMILIES
    pts = _points(nominal, 12, force=False)
    cands, _ = library_candidates(nominal, make_data(pts, None, ArmModel(nominal)), families=("joint_coupling",))
    J = nominal.n_joints
    assert len(cands) == J * (J - 1) and {c.family for c in cands} == {"joint_coupling"}
    c = next(c for c in cands if c.name == "coupling j6 by q5")
    assert c.effect == JointGain(joints=(5,), source=4) and c.joint == "j6"
    built = synthesise(["q5 harmonics on j6"], ArmModel(nominal))
    assert any(b.name == c.name and b.effect == c.effect for b in built)
    fixed = replace(pts, q=np.where(np.arange(J) == 2, 0.3, pts.q))
    cands, _ = library_candidates(nominal, make_data(fixed, None, ArmModel(nominal)), families=("joint_coupling",))
    assert not [c for c in cands if c.name.endswith(" by q3")] and len(cands) == J * (J - 1) - (J - 1)


def test_the_contact_force_family_builds_the_tilted_axes_beside_the_matrix(nominal):
    """``contact force``: ``probe compliance axes tilted`` (xz, yz) and the full matrix (the terms a probe compliance
    in the model leaves); with both off-diagonal axial terms already the only ones left, the tilt is not built
    twice; nothing once a matrix is in the model."""
    built = {c.name: c.effect for c in synthesise(["contact force"], ArmModel(nominal))}
    assert built == {"probe compliance axes tilted": ProbeComplianceMatrix(terms=("xz", "yz")),
                     "probe compliance matrix": ProbeComplianceMatrix()}
    full = ArmModel(nominal, (ProbeCompliance(anisotropic=True, axial=True),))
    assert {c.name: c.effect.terms for c in synthesise(["contact force"], full)} == {
        "probe compliance axes tilted": ("xz", "yz"), "probe compliance matrix": ("xy", "xz", "yz")}
    assert synthesise(["contact force"], ArmModel(nominal, (ProbeComplianceMatrix(terms=("xz", "yz")),))) == []


def test_a_turned_compliance_is_the_xz_and_yz_terms_to_first_order():
    """The physics the tilted-axes candidate stands for, by hand: ``R diag(c) R^T`` for R small turns tx, ty about the
    probe's x and y axes differs from ``diag(c)`` by ``dC_xz = -ty (c_x - c_z)``, ``dC_yz = tx (c_y - c_z)`` and by
    terms of the second order only (the 85 mm probe's compliances; 5 deg of bend)."""
    c = np.diag([0.0142e-3, 0.0142e-3, 0.0000876e-3])
    for tx, ty in ((0.0, np.radians(5.0)), (np.radians(3.0), np.radians(-2.0))):
        rx = np.array([[1, 0, 0], [0, np.cos(tx), -np.sin(tx)], [0, np.sin(tx), np.cos(tx)]])
        ry = np.array([[np.cos(ty), 0, np.sin(ty)], [0, 1, 0], [-np.sin(ty), 0, np.cos(ty)]])
        r = ry @ rx
        d = r @ c @ r.T - c
        first = np.zeros((3, 3))
        first[0, 2] = first[2, 0] = -ty * (c[0, 0] - c[2, 2])
        first[1, 2] = first[2, 1] = tx * (c[1, 1] - c[2, 2])
        assert np.max(np.abs(d - first)) < 2.0 * (tx ** 2 + ty ** 2) * c[0, 0]      # the rest: second order
        assert abs(d[0, 2]) > 0.5 * abs(ty) * c[0, 0] or ty == 0.0


def test_the_new_candidates_agree_across_the_three_evaluators(nominal):
    """The base tilt and the tilted axes as the loop adds them: batch, CasADi and Pinocchio to 1e-12 m."""
    model = ArmModel(nominal, (LateralCompliance(joints=(0,)), ProbeComplianceMatrix(terms=("xz", "yz"))))
    rng = np.random.default_rng(4)
    q = rng.uniform(-2.5, 2.5, (5, nominal.n_joints))
    w = np.zeros((5, 6))
    w[:, :3] = rng.normal(0, 3, (5, 3))
    tg, tc = PinocchioArm(nominal).torques(q, w)
    aux = AuxData(np.full(5, 20.0), tg, tc)
    p = np.zeros(model.spec.size)
    p[: model.base_size] = rng.normal(0, 1e-6, model.base_size)
    p[model.base_size:] = [3e-6, -2e-6, 1.2e-6, -0.8e-6]
    batch = model.ball_centres(q, w, p, aux)
    assert np.min(np.linalg.norm(batch - model.ball_centres(q, w, np.r_[p[: model.base_size], 0, 0, 0, 0], aux),
                                 axis=1)) > 1e-7
    f = model.casadi_function()
    a = ArmModel.aux_matrix(aux, len(q), nominal.n_joints)
    for i in range(len(q)):
        assert_close(np.array(f(q[i], w[i], a[i], p)).ravel(), batch[i], atol=1e-12)
        assert_close(model.pinocchio_ball_centre(q[i], w[i], p, dict(temperature=20.0)), batch[i], atol=1e-12)


def _panda_mocap(truth: dict, postures: int = 16, sessions: int = 2) -> dict:
    return {"seed": 2, "arm": str(PANDA), "tip_frame": "panda_link8", "sensor": "none",
            "truth": {"length_error_mm": 0.3, "angle_error_deg": 0.03, **truth},
            "task": [{"kind": "mocap", "postures": postures, "markers": 1, "sessions": sessions, "noise_mm": 0.0}]}


def test_a_marker_moves_with_the_links_a_lateral_compliance_turns():
    """A motion-capture campaign on a robot whose shoulder tilts under gravity simulates (before: "truth check
    failed: a marker of task 'pose' is 2.67e+05 nm off where the core model puts it"), and without noise each
    marker is where Pinocchio's evaluation of the truth (its lateral moments from RNEA) puts the marker point, in the
    instrument's frame, to 1 nm."""
    lateral = {"lateral_compliance": {"joints": ["panda_joint2"], "stiffness_x_Nm_per_rad": 5000.0,
                                      "stiffness_y_Nm_per_rad": 5000.0, "gravity": True, "contact": False}}
    sim = simulate(campaign_from_dict(_panda_mocap(lateral, postures=6, sessions=1)))
    model, p = sim.truth["model"], np.asarray(sim.truth["p_vector"])
    t = np.asarray(sim.truth["T_ref_base"]["pose"])
    pk = p + offset_matrix(model) @ np.asarray(sim.truth["marker_offsets"]["pose"][0])
    tilt = 0.0
    for q, ref in zip(sim.points.q, sim.points.ref[:, 0], strict=True):
        x = model.pinocchio_ball_centre(q, np.zeros(6), pk, {"temperature": 20.0})
        assert_close(t[:3, :3] @ x + t[:3, 3], ref, atol=1e-9)
        rigid = ArmModel(model.desc).ball_centres(q[None], None, pk[: model.base_size])[0]
        tilt = max(tilt, float(np.linalg.norm(x - rigid)))
    assert tilt > 1e-4                                  # the tilt moves the marker by tenths of a millimetre


def test_the_loop_takes_a_compliance_s_torques_at_its_equilibrium():
    """A robot whose shoulder sags 20 mrad under its RMS gravity torque: the loop's held-out figure of its base model
    is the one the model file gives (torques at the fit's static equilibrium, :func:`with_fitted_torques`), within 1 %
    (before: the torques at the readings, 169 against 141 um on scripts/robot_hidden_study.py's ``stiff2x``)."""
    d = _panda_mocap({"joint_compliance": {"stiffness_Nm_per_rad": [20000, 1200, 20000, 20000, 20000, 20000, 20000],
                                           "gravity": True, "contact": False}}, postures=16, sessions=2)
    d["task"][0]["noise_mm"] = 0.05
    camp = campaign_from_dict(d)
    sim = simulate(camp)
    effects = default_effects(ArmModel(camp.arm, ()))
    pts = sim.points
    held = tuple(sorted(set(pts.measurement[pts.session == sorted(set(pts.session))[-1]])))
    loop = close_loop(pts, sim.artefacts, camp.arm, weights=Weights(probe=5e-5, reference=5e-5), effects=effects,
                      families_=("eccentricity",), holdout=held, max_effects=0, progress=lambda s: None,
                      synthesise=False)
    st = loop.stages[0]
    test = loop.data.select(np.isin(loop.data.points.measurement, list(loop.test)))
    # predicted as the loop predicts: the held-out session's frame solved on it, the marker offset the design fit's
    tracker = st.result.tracker
    tip = heldout_figures(st.model, st.result.p, with_fitted_torques(test, st.result), Weights(5e-5, 5e-5),
                          tracker=tracker)["rms_um"]
    assert st.heldout["rms_um"] == pytest.approx(tip, rel=0.01)
    readings = make_data(test.points, test.artefacts, st.model, marker_offsets=test.marker_offsets)
    assert heldout_figures(st.model, st.result.p, readings, Weights(5e-5, 5e-5), tracker=tracker)["rms_um"] > 1.1 * tip


@pytest.mark.parametrize("synthesise, per_pose", [(True, True), (False, False)])
def test_the_decision_power_counts_the_built_candidates_a_stage_may_test(nominal, synthesise, per_pose):
    """9 design measurements reach ``alpha / cv_top`` (1/2^9 = 0.00195 < 0.0033) but not the level the built
    candidates of a stage are held to, ``alpha / (2 cv_top)`` = 0.00167: with effects built from the residual the
    units become the held-out measurements' poses; with the library alone they stay the measurements."""
    from arm_model.sim.quick import SynthSpec, make_campaign
    from calibration.loop import LoopSettings
    from calibration.loop.folds import choose_folds
    model = ArmModel(nominal)
    c = make_campaign(model, SynthSpec(ballbars=0, seats=9, articulations=4, spheres=0), seed=1,
                      p_true=np.zeros(model.spec.size))
    design = make_data(c.points, c.artefacts, model)
    folds, power = choose_folds(design, LoopSettings(synthesise=synthesise))
    assert folds.by == "measurement" and folds.per_pose is per_pose
    assert power["level"] == pytest.approx(0.01 / (6 if synthesise else 3)) and power["can_reach"]
    assert power["units"] == (36 if per_pose else 9)
