"""scripts/mocap_study.py (the study behind docs/studies/calibration.md's "Where the remaining held-out error comes
from" and "A fresh round on what is missing"): its noise floor and its exact campaigns on a simulated
motion-capture campaign whose noise is known."""
from __future__ import annotations

import json
import math
import sys

import numpy as np
from test_sim_mocap import LIFT_ARM_URDF, TIP

from arm_model.cli import main
from conftest import ROOT


def _campaign(tmp_path):
    """The lift arm (its URDF ``liftarm.urdf`` in ``tmp_path``) seen by motion capture at 30 postures, the
    instrument's noise 0.2 mm per axis, geometric errors only: ``sim/points.csv`` in ``tmp_path``."""
    (tmp_path / "liftarm.urdf").write_text(LIFT_ARM_URDF)
    (tmp_path / "c.toml").write_text('name = "mocap"\nseed = 11\narm = "liftarm.urdf"\n'
                                     f'tip_frame = "{TIP}"\nsensor = "none"\n[truth]\nlength_error_mm = 1.0\n'
                                     'angle_error_deg = 0.3\n[[task]]\nkind = "mocap"\npostures = 30\n'
                                     'noise_mm = 0.2\n')
    assert main(["simulate", str(tmp_path / "c.toml"), "-o", str(tmp_path / "sim")]) == 0


def test_noise_floor_is_the_campaign_s_noise_and_leave_one_out_lies_above_it(tmp_path):
    """A lift arm seen by motion capture, 30 postures, the instrument's noise 0.2 mm per axis, no compliance in
    the truth: ``--floor`` fitted on every posture with the geometry alone gives a floor (its degrees of
    freedom counted) within 25 % of the campaign's 0.2 x sqrt(3) mm in 3D, a residual below it, and each
    posture predicted from the others (leave-one-out) at or above the floor, within 1.6x of it (30 postures
    for about 25 unknowns)."""
    sys.path.insert(0, str(ROOT / "scripts"))
    import mocap_study

    _campaign(tmp_path)
    out = tmp_path / "study.json"
    assert mocap_study.main([str(tmp_path / "sim" / "points.csv"), "--arm", str(tmp_path / "liftarm.urdf"),
                             "--tip-frame", TIP, "--halves", "0", "--sizes", "", "--effects", "none", "--floor",
                             "-o", str(out)]) == 0
    f = json.loads(out.read_text())["floor"]["none"]
    noise = 0.2 * math.sqrt(3)
    assert 0.75 * noise < f["floor_mm"] < 1.25 * noise, f
    assert f["fit_rms_mm"] < f["floor_mm"] and f["dof"] > 0
    assert len(f["loo_errors_mm"]) == 30
    assert f["floor_mm"] <= f["loo_rms_mm"] < 1.6 * f["floor_mm"], f


def test_exact_campaigns_carry_the_campaign_s_noise_about_the_model_s_fit(tmp_path):
    """``--exact``'s campaigns, on a simulated one the geometry describes exactly (the lift arm, 30 postures,
    0.2 mm per axis, no compliance in the truth): the noise they are drawn at is the campaign's (within 25 %),
    two draws differ by that noise (sqrt 2 times it, within 25 %), the rows, joints and ids are the campaign's,
    and the geometry fitted on a draw leaves the draw's noise (its floor within 25 % of 0.2 x sqrt 3 mm)."""
    sys.path.insert(0, str(ROOT / "scripts"))
    import mocap_study

    from arm_model.io import read_points
    from arm_model.model import ArmModel
    from arm_model.urdf_import import load_arm
    from calibration import make_data

    _campaign(tmp_path)
    model = ArmModel(load_arm(tmp_path / "liftarm.urdf", TIP))
    pts = read_points(tmp_path / "sim" / "points.csv", model.desc.n_joints)
    sigma, (a, b) = mocap_study.exact_campaigns(model, pts, make_data(pts, None, model), 2)
    assert 0.75 * 0.2e-3 < sigma < 1.25 * 0.2e-3, sigma
    assert a.ref.shape == pts.ref.shape and np.array_equal(a.q, pts.q)
    assert list(a.measurement) == list(pts.measurement)
    spread = float(np.std(a.ref - b.ref))
    assert 0.75 * np.sqrt(2) * sigma < spread < 1.25 * np.sqrt(2) * sigma, (spread, sigma)
    res = mocap_study.fitted(model, make_data(a, None, model))
    floor = float(np.sqrt(3 * np.mean(mocap_study.error_vectors(res, res.data) ** 2) * res.n_residuals / res.dof))
    assert 0.75 * 0.2 * math.sqrt(3) < floor < 1.25 * 0.2 * math.sqrt(3), floor


def test_complementary_halves_of_a_campaign_the_model_describes_agree_within_their_u(tmp_path):
    """The lift arm's 30 postures (geometry errors only, 0.2 mm of noise), one random half and its complement
    fitted with the geometry alone (the truth's structure): the parameters both estimate differ by their combined
    u or so (z RMS between 0.3 and 2: neither a copy of one fit nor two different geometries), and the study
    names the parameters only one half estimates."""
    sys.path.insert(0, str(ROOT / "scripts"))
    import mocap_study

    _campaign(tmp_path)
    out = tmp_path / "study.json"
    assert mocap_study.main([str(tmp_path / "sim" / "points.csv"), "--arm", str(tmp_path / "liftarm.urdf"),
                             "--tip-frame", TIP, "--halves", "1", "--sizes", "", "--effects", "none",
                             "--compare-halves", "-o", str(out)]) == 0
    c = json.loads(out.read_text())["half0"]["none"]["halves_compared"]
    assert c["common"] >= 5 and 0.3 < c["z_rms"] < 2.0, c
    assert len(c["parameters"]) == c["common"] and {"only_first", "only_second"} <= set(c)
    assert abs(c["parameters"][0]["z"]) >= abs(c["parameters"][-1]["z"])
