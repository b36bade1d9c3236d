"""The simulator hides the synthesised effects that depend on the pose and the wrench: lateral compliance of
a joint, the probe compliance's coupling terms and an approach (lobing) offset (``[truth.lateral_compliance]``,
``[truth.probe_compliance] coupling_*``, ``[truth.approach_offset]``). The true ball is moved by them at the
true pose: checked by hand formulas (``B u``, ``C_off f``) and by the Pinocchio evaluator (RNEA moments)."""
from __future__ import annotations

import numpy as np
import pytest

from arm_model import InputError
from arm_model.model import ArmModel, AuxData
from arm_model.sim import campaign_from_dict, load_campaign, simulate

TASKS = [{"kind": "sphere", "points": 8, "measurements": 2}, {"kind": "seat", "articulations": 6, "measurements": 2}]


def _campaign(truth, seed=5):
    return {"seed": seed, "sensor": "xyz", "signals": {"enabled": False}, "task": TASKS, "truth": truth}


def _without(sim, keys):
    """The truth's core model and parameters without the effects of ``keys`` (effect keys)."""
    model, p = sim.truth["model"], sim.truth["p_vector"]
    keep = [np.arange(model.base_size)]
    effects = []
    for e, sl in model.effect_slices():
        if e.key not in keys:
            effects.append(e)
            keep.append(np.arange(sl.start, sl.stop))
    return ArmModel(model.desc, tuple(effects)), p[np.concatenate(keep)]


def test_approach_offset_and_coupling_move_the_true_ball_by_B_u_and_C_f():
    b = {"dx_uy_um": 6.0, "dy_ux_um": -4.0, "dz_ux_um": 5.0, "dz_uz_um": 3.0}
    truth = {"approach_offset": b, "probe_compliance": {"bending_x_um_per_N": 16.0, "bending_y_um_per_N": 12.0,
                                                          "coupling_xy_um_per_N": -5.0}}
    sim = simulate(campaign_from_dict(_campaign(truth)))
    p = sim.truth["p"]
    assert (p["approach.dx_uy"], p["approach.dz_uz"], p["approach.dx_ux"]) == pytest.approx((6e-6, 3e-6, 0.0))
    assert p["probe.dcompliance_xy"] == pytest.approx(-5e-6)
    assert sim.stats["truth_residual_max_m"] < 1e-9
    n = len(sim.points)
    q_enc = sim.truth["q_enc"][:n]
    w = sim.true_wrench
    rot = sim.truth["truth"].rotation(sim.true_q, sim.truth["temperature"][:n])     # R_base_probe
    u = rot[:, :, 2]                                                                   # stylus, base frame
    bmat = np.zeros((3, 3))
    for k, v in b.items():
        bmat["xyz".index(k[1]), "xyz".index(k[4])] = v * 1e-6
    c_off = np.array([[0.0, -5e-6, 0.0], [-5e-6, 0.0, 0.0], [0.0, 0.0, 0.0]])
    shift = u @ bmat.T + np.einsum("nij,nj->ni", rot, w[:, :3] @ c_off.T)
    assert np.max(np.linalg.norm(shift, axis=1)) > 5e-6                               # the check has teeth
    plain, pp = _without(sim, ("approach_offset", "probe_compliance_matrix"))
    x = plain.ball_centres(q_enc, w, pp, AuxData(sim.truth["temperature"][:n]))
    np.testing.assert_allclose(x, sim.true_centres - shift, atol=1e-10)


def test_lateral_compliance_in_the_truth_agrees_with_pinocchio_moments():
    truth = {"lateral_compliance": {"joints": ["j4"], "stiffness_x_Nm_per_rad": 1e5, "stiffness_y_Nm_per_rad": 2e5}}
    sim = simulate(campaign_from_dict(_campaign(truth)))
    p = sim.truth["p"]
    assert (p["j4.lateral_compliance_x"], p["j4.lateral_compliance_y"]) == pytest.approx((1e-5, 5e-6))
    assert sim.truth["effects"]["lateral_compliance"]["stiffness_x"] == [1e5]
    n = len(sim.points)
    q_enc, w = sim.truth["q_enc"][:n], sim.true_wrench
    model, pv = sim.truth["model"], sim.truth["p_vector"]
    plain, pp = _without(sim, ("lateral_compliance",))
    x0 = plain.ball_centres(q_enc, w, pp, AuxData(sim.truth["temperature"][:n]))
    moved = np.linalg.norm(sim.true_centres - x0, axis=1)
    assert moved.max() > 2e-6                                           # the tilt moves the ball (gravity)
    for i in range(0, n, 7):            # a second implementation of the moments: Pinocchio's RNEA
        xi = model.pinocchio_ball_centre(q_enc[i], w[i], pv, {"temperature": sim.truth["temperature"][i]})
        np.testing.assert_allclose(xi, sim.true_centres[i], atol=1e-9)


@pytest.mark.parametrize("truth, message", [
    ({"lateral_compliance": {"joints": ["j4"]}}, "stiffness_x"),
    ({"lateral_compliance": {"joints": ["j4"], "stiffness_x_Nm_per_rad": 0.0}}, "> 0"),
    ({"lateral_compliance": {"joints": ["j9"], "stiffness_x_Nm_per_rad": 1e5}}, "j9"),
    ({"lateral_compliance": {"joints": ["j4"], "stiffness_x_Nm_per_rad": [1e5, 2e5]}}, "2 values for 1 joints"),
    ({"lateral_compliance": {"joints": ["j4"], "stiffness_x_Nm_per_rad": 1e5, "gravity": False, "contact": False}},
     "no load"),
    ({"lateral_compliance": {"joints": ["j4"], "stiffness_x": 1e5}}, "unit suffix"),
    ({"lateral_compliance": {"joints": ["j4"], "stifness_x_Nm_per_rad": 1e5}}, "unknown key"),
    ({"approach_offset": {"dx_uy_mm": 2.0}}, "within"),
    ({"approach_offset": {"dx_uw_um": 2.0}}, "unknown key"),
    ({"probe_compliance": {"bending_um_per_N": 1.0, "coupling_xy_um_per_N": 5.0}}, "positive semi-definite"),
    ({"probe_compliance": {"coupling_xz_deg": 1.0}}, "compliance"),
    ({"lobing": {"dx_uy_um": 2.0}}, "unknown key"),
])
def test_bad_pose_effect_tables_are_refused(truth, message):
    with pytest.raises(InputError, match=message):
        campaign_from_dict(_campaign(truth))


def test_bad_key_in_a_campaign_file_names_its_line(tmp_path):
    f = tmp_path / "c.toml"
    f.write_text('seed = 1\n[[task]]\nkind = "sphere"\n\n[truth.approach_offset]\ndx_uy_um = 6.0\n'
                 'dy_ux_um = 4000.0\n')
    with pytest.raises(InputError) as exc:
        load_campaign(f)
    assert exc.value.line == 7 and "dy_ux" in str(exc.value)


LOBING = """\
seed = 3
sensor = "xyz"

[signals]
enabled = false

[noise]
probing_repeatability_um = 2.0

[truth.approach_offset]
dx_uy_um = 8.0
dy_ux_um = -6.0
dz_ux_um = 6.0

[[task]]
kind = "ballbar"
positions = 10
length_mm = 600.0
points_per_sphere = 4

[[task]]
kind = "seat"
articulations = 8
measurements = 8

[[task]]
kind = "sphere"
points = 8
measurements = 8
"""


# in make test-slow: the loop finding lobing is held in make test by test_loop_synthesis[lobing]
@pytest.mark.slow
def test_lobing_hidden_by_aacmm_simulate_is_found_by_aacmm_close_loop(tmp_path):
    """From the command line only: a campaign file hides a lobing offset, ``aacmm close-loop`` builds the
    approach offset from the residual, adds it and recovers each term within 3 sigma.

    The held-out test's units are whole measurements, and the offset shows mostly on the seats and spheres (a
    ball bar's few points per sphere leave little of it once its centres are fitted): with 4 seat and 5 sphere
    measurements the design set held 7 informative units and the Wilcoxon p of the offset spread over
    0.00006-0.03 across simulation seeds (3 of 7 seeds under the level). With 8 of each it is below 0.002 at
    seeds 1-7 and the offset alone is added at every one."""
    from conftest import simulate_and_close_loop

    sim, _, s = simulate_and_close_loop(tmp_path, LOBING, "--cv-top", "2")
    assert '"approach.dx_uy_m" = 8e-06' in (sim / "truth.toml").read_text()
    (eff,) = s["effects_added"]
    assert eff["name"] == "approach offset" and eff["origin"] == "residual", s["verdict"]
    true = {"approach.dx_uy": 8e-6, "approach.dy_ux": -6e-6, "approach.dz_ux": 6e-6}
    checked = 0
    for prm in eff["parameters"]:
        if prm["state"] == "free":
            assert abs(prm["value"] - true.get(prm["name"], 0.0)) <= 3 * prm["u"], prm
            checked += 1
    assert checked >= 8 and s["structure_remains"] is False
