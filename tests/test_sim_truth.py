"""The simulator's truth is consistent: every true deflected ball centre lies on its artefact within
1 nm, recomputed independently (Pinocchio on the true description, the effects by hand) from what
the files hold; the core model with the true parameters reproduces it from the written readings."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from arm_model import PinocchioArm
from arm_model.model import AuxData
from arm_model.sim import campaign_from_dict, simulate
from arm_model.sim.artefacts import ring_surface
from conftest import assert_close

ALL_EFFECTS = {
    "eccentricity": [{"joint": "j2", "amplitude_deg": 0.003, "phase_deg": 40.0, "amplitude2_deg": 0.001,
                      "phase2_deg": -30.0},
                     {"joint": "j5", "amplitude_arcsec": 8.0, "phase_deg": 100.0}],
    "joint_compliance": {"joints": ["j2", "j4"], "stiffness_Nm_per_rad": [4e4, 2.5e4]},
    "thermal": {"alpha_per_K": 2.3e-5},
    "probe_compliance": {"bending_x_mm_per_N": 0.016, "bending_y_mm_per_N": 0.013, "axial_mm_per_N": 0.0002},
    "force_sensor": {"gain": [0.03, -0.02, 0.01], "offset_N": [0.04, -0.03, 0.02]},
}


def campaign(effects=ALL_EFFECTS, sensor="xyz", seed=5, **extra):
    data = {"seed": seed, "sensor": sensor, "truth": dict(effects),
            "environment": {"temperature_C": 24.0, "drift_C_per_h": 30.0},
            "operator": {"point_period_s": 0.5}, "signals": {"enabled": False},
            "task": [{"kind": "ring", "measurements": 1, "points_per_row": 8, "true_form_error_mm": 0.005},
                     {"kind": "sphere", "points": 6},
                     {"kind": "plane", "points": 5},
                     {"kind": "seat", "articulations": 5}]}
    data.update(extra)
    return campaign_from_dict(data)


@pytest.fixture(scope="module")
def full():
    return simulate(campaign())


def _by_hand_true_angles(result):
    """q_true from the written readings with the effects written out by hand (not the core)."""
    t = result.truth
    q = result.points.q.copy()
    q_enc = q.copy()
    names = [j.name for j in result.campaign.arm.joints]
    for e in t["effects"]["eccentricity"]:
        i = names.index(e["joint"])
        q[:, i] += (e["amplitude"] * np.sin(q_enc[:, i] + e["phase"])
                    + e["amplitude2"] * np.sin(2 * q_enc[:, i] + e["phase2"]))
    jc = t["effects"]["joint_compliance"]
    arm = PinocchioArm(t["description"])
    for row in range(len(q)):
        tau_g = arm.gravity_torques(result.true_q[row])
        tau_c = arm.contact_torques(result.true_q[row], result.true_wrench[row])
        for name, k in zip(jc["joints"], jc["stiffness"], strict=True):
            i = names.index(name)
            q[row, i] += (tau_c[i] - tau_g[i]) / k
    return q


def _distance_to_surface(result, centres):
    """Distance [m] of each ball centre from the surface its feature puts it on."""
    pl = result.truth["placements"]
    ball = result.campaign.arm.probe.ball_diameter
    out = np.empty(len(centres))
    for i, (fid, p) in enumerate(zip(result.points.feature, centres, strict=True)):
        a = pl[fid]
        if a["kind"] == "ring":   # distance to the (lobed) bore, in the plane across the axis
            v = p - np.array(a["centre_m"])
            x, y = v @ np.array(a["e1"]), v @ np.array(a["e2"])

            def d2(phi, a=a, x=x, y=y):
                r, _ = ring_surface(a, phi)
                return (x - r * np.cos(phi)) ** 2 + (y - r * np.sin(phi)) ** 2
            phi0 = np.arctan2(y, x)
            best = minimize_scalar(d2, bracket=(phi0 - 1e-3, phi0, phi0 + 1e-3), tol=1e-12)
            out[i] = np.sqrt(best.fun) - ball / 2
        elif a["kind"] == "sphere":
            out[i] = np.linalg.norm(p - np.array(a["centre_m"])) - (a["diameter_m"] + ball) / 2
        elif a["kind"] == "plane":
            out[i] = (p - np.array(a["point_m"])) @ np.array(a["normal"]) - ball / 2
        elif a["kind"] == "seat":
            out[i] = np.linalg.norm(p - np.array(a["position_m"]))
    return out


def test_true_centres_lie_on_the_artefacts(full):
    d = _distance_to_surface(full, full.true_centres)
    assert np.all(np.abs(d) < 1e-9), f"max {np.abs(d).max():.3g} m"
    # the ring's true bore is lobed (5 um peak to valley): the ball centres show it
    ring = full.points.feature == "ring"
    pl = full.truth["placements"]["ring"]
    v = full.true_centres[ring] - np.array(pl["centre_m"])
    radial = np.hypot(v @ np.array(pl["e1"]), v @ np.array(pl["e2"]))
    assert 3e-6 < np.ptp(radial) <= 5e-6 + 1e-9


def test_truth_recomputed_independently_from_the_written_data(full):
    """Readings (file) -> effects by hand -> true angles; true description + thermal growth by hand +
    true probe compliance -> Pinocchio -> the ball centre is on the surface within 1 nm."""
    t = full.truth
    q_true = _by_hand_true_angles(full)
    assert_close(q_true, full.true_q, atol=1e-12, msg="true angles from the written readings")
    fs = t["effects"]["force_sensor"]
    f_true = (full.points.force - np.array(fs["offset"])) / (1 + np.array(fs["gain"]))
    assert_close(f_true, full.true_wrench[:, :3], atol=2e-6, msg="true force from the written readings")
    base = t["description"]
    pc = t["effects"]["probe_compliance"]
    alpha = t["effects"]["thermal"]["alpha"][0]
    centres = np.empty((len(q_true), 3))
    for i, (q, f, temp) in enumerate(zip(q_true, f_true, full.points.temperature, strict=True)):
        s = 1 + alpha * (temp - 20.0)
        table = base.row_table().copy()
        table[:, 1:3] *= s                       # d and a grow; angles do not
        desc = base.with_row_table(table).with_probe(bending_compliance_x=pc["bending_x"],
                                                     bending_compliance_y=pc["bending_y"],
                                                     axial_compliance=pc["axial"])
        centres[i] = PinocchioArm(desc).ball_centre(q, f)
    d = _distance_to_surface(full, centres)
    assert np.all(np.abs(d) < 1e-9), f"max {np.abs(d).max():.3g} m"


def test_core_model_with_true_parameters_reproduces_the_truth(full):
    """The analysis side's model (core ArmModel with the same effects) and the true p, fed the written
    readings, forces, temperatures and the true torques, gives the true centres (no noise here)."""
    t = full.truth
    model, p = t["model"], t["p_vector"]
    aux = AuxData(full.points.temperature, t["tau_gravity"], t["tau_contact"])
    got = model.ball_centres(full.points.q, full.points.force, p, aux)
    assert_close(got, full.true_centres, atol=1e-9)
    # and the effects matter: the nominal-model answer is far off
    assert np.abs(model.ball_centres(full.points.q, full.points.force, None, aux) - full.true_centres).max() > 1e-5


def test_encoder_inversion_is_exact(full):
    truth = full.truth["truth"]
    aux = truth.aux(full.truth["temperature"], full.truth["tau_gravity"], full.truth["tau_contact"])
    q_enc = full.truth["q_enc"]
    assert_close(truth.true_angles(q_enc, aux), np.vstack([full.true_q]), atol=1e-13)


def test_true_parameters_have_the_requested_sizes():
    """Random base errors: lengths ~ length_error, angles ~ angle_error, probe ~ probe_error (1 sigma);
    explicit errors override them exactly."""
    sizes = {"length_error_um": 40.0, "angle_error_deg": 0.005, "probe_error_um": 25.0}
    lengths, angles, probe = [], [], []
    for seed in range(40):
        c = campaign_from_dict({"seed": seed, "truth": dict(sizes, errors={"j3.d_um": 12.5}),
                                "task": [{"kind": "seat", "articulations": 1}]})
        from arm_model.sim.truth import build_truth
        truth = build_truth(c.arm, c.truth, np.random.default_rng(seed))
        v = truth.values
        assert v["j3.d"] == pytest.approx(12.5e-6, abs=1e-18)
        lengths += [v[f"j{i}.{k}"] for i in range(1, 8) for k in ("a", "d") if (i, k) != (3, "d")]
        angles += [v[f"j{i}.{k}"] for i in range(1, 8) for k in ("theta_offset", "alpha")]
        probe += [v[f"probe.{k}"] for k in "xyz"]
    assert np.std(lengths) == pytest.approx(40e-6, rel=0.1)
    assert np.std(angles) == pytest.approx(math.radians(0.005), rel=0.1)
    assert np.std(probe) == pytest.approx(25e-6, rel=0.2)


def test_truth_file_is_marked_and_holds_every_parameter(full):
    import tomllib
    text = full.texts["truth.toml"]
    assert text.splitlines()[0].startswith("# TRUTH") and "No analysis reads this file" in text.splitlines()[0]
    data = tomllib.loads(text)
    spec = full.truth["spec"]
    assert len(data["parameters"]) == spec.size
    assert data["parameters"]["j2.ecc1_cos_rad"] == full.truth["p"]["j2.ecc1_cos"]
    assert data["parameters"]["j4.compliance_rad_per_Nm"] == pytest.approx(1 / 2.5e4, rel=1e-15)
