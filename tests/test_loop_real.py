"""``aacmm close-loop`` on the real measured Panda seat data (examples/data/real-panda-seats): one placement
alone runs (the test set and the folds by pose), and misuse stops with one message."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from arm_model.cli import main
from calibration.loop import wilcoxon_units_needed
from calibration.placements import seat_figures

REAL = Path(__file__).resolve().parents[1] / "examples" / "data" / "real-panda-seats"
ARM = ["--arm", str(REAL / "panda-with-inertials.urdf"), "--tip-frame", "ball_link"]


def all_placements(tmp_path) -> Path:
    """The three placements in one points file."""
    out = tmp_path / "all.csv"
    parts = [(REAL / p / "points.csv").read_text().splitlines() for p in ("front", "right", "back-high")]
    out.write_text("\n".join(parts[0] + parts[1][1:] + parts[2][1:]) + "\n")
    return out


@pytest.mark.parametrize("alpha, tests", [(0.01, 1), (0.01, 3), (0.05, 1), (0.005, 4)])
def test_units_needed_is_where_the_exact_wilcoxon_first_reaches_the_level(alpha, tests):
    n = wilcoxon_units_needed(alpha, tests)
    p = [stats.wilcoxon(np.arange(1.0, k + 1), alternative="greater").pvalue for k in (n - 1, n)]
    assert p[0] >= alpha / tests > p[1]
    assert p[1] == pytest.approx(0.5 ** n)


def test_one_placement_runs_with_folds_by_pose(tmp_path, capsys):
    out = tmp_path / "loop"
    code = main(["close-loop", str(REAL / "front" / "points.csv"), str(REAL / "artefacts.toml"), *ARM,
                 "--max-effects", "1", "--no-plots", "-o", str(out)])
    assert code == 0, capsys.readouterr().err
    s = json.loads((out / "summary.json").read_text())
    assert s["measurements"]["test_by"] == "pose"
    power = s["decision_power"]
    assert power["fold_by"] == "pose" and power["can_reach"] and power["units"] >= power["needed"]
    assert "folds by pose" in capsys.readouterr().err


@pytest.mark.parametrize("holdout, message", [("front", "every measurement is held out"),
                                              ("nowhere", "not in the points file: nowhere"),
                                              (" , ", "names no measurement")])
def test_an_empty_or_impossible_test_set_stops_with_one_message(tmp_path, capsys, holdout, message):
    out = tmp_path / "loop"
    code = main(["close-loop", str(REAL / "front" / "points.csv"), str(REAL / "artefacts.toml"), *ARM,
                 "--holdout", holdout, "-o", str(out)])
    assert code == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not out.exists()


@pytest.mark.slow
def test_a_test_that_cannot_reach_its_level_is_reported_before_it_runs(tmp_path, capsys):
    out = tmp_path / "loop"
    code = main(["close-loop", str(all_placements(tmp_path)), str(REAL / "artefacts.toml"), *ARM,
                 "--holdout", "back-high", "--fold-by", "measurement", "--folds", "2", "--quiet", "-o", str(out)])
    assert code == 0
    err = capsys.readouterr().err
    assert "warning: the held-out test cannot reach its level" in err
    assert "smallest p = 1/2^2 = 0.25" in err and "at least 10 measurements" in err
    s = json.loads((out / "summary.json").read_text())
    assert s["measurements"]["test"] == ["back-high"] and s["decision_power"]["can_reach"] is False
    assert s["effects_added"] == []


def test_trained_on_one_placement_the_loop_is_no_worse_than_calibrate_on_the_others():
    """Train on 'front' with the default options of both commands, predict 'right' and 'back-high': the loop's
    model (calibrated on every point of the training placement) spreads the held-out seats no more than plain
    calibrate's (5 % tolerance), with the distance error no worse than 0.1 mm more."""
    from arm_model.io import read_artefacts, read_points
    from arm_model.model import ArmModel
    from arm_model.urdf_import import load_arm
    from calibration.calibrate import calibrate
    from calibration.data import make_data
    from calibration.loop import close_loop
    from conftest import loop_fit_options, seat_figures_of

    desc = load_arm(REAL / "panda-with-inertials.urdf", "ball_link")
    art = read_artefacts(REAL / "artefacts.toml")
    pts = {p: read_points(REAL / p / "points.csv", 7) for p in ("front", "right", "back-high")}
    plain = calibrate(ArmModel(desc), make_data(pts["front"], art, ArmModel(desc)), loop_fit_options())
    loop = close_loop(pts["front"], art, desc)
    assert loop.model_fit is not None and len(loop.model_fit.data) == len(pts["front"])

    for held in ("right", "back-high"):
        a, b = seat_figures_of(plain, desc, pts[held]), seat_figures_of(loop.model_fit, desc, pts[held])
        assert 0.2 < a["spread_mean_mm"] < 5.0                      # a real fit, not a degenerate one
        assert b["spread_mean_mm"] <= 1.05 * a["spread_mean_mm"], (held, a, b)
        assert abs(b["distance_error_mm"]) <= abs(a["distance_error_mm"]) + 0.1, (held, a, b)


def test_seat_figures_by_hand():
    x = np.array([[0, 0, 0], [2, 0, 0], [50, 0, 0], [50, 0, 4]], float) * 1e-3
    f = seat_figures(x, np.array(["a", "a", "b", "b"]), ("a", "b"), 0.05)
    # hole a: deviations +-1 mm, 2 sqrt((1 + 1) / 1) = 2.828 mm; hole b: +-2 mm -> 5.657 mm
    assert f["spread_a_mm"] == pytest.approx(2 * np.sqrt(2.0))
    assert f["spread_b_mm"] == pytest.approx(4 * np.sqrt(2.0))
    assert f["distance_error_mm"] == pytest.approx(np.hypot(49.0, 2.0) - 50.0)


def test_a_drift_along_the_capture_order_is_told_from_the_distance():
    """Two seats 50 mm apart, 30 centres each (0.1 mm scatter), hole-0 captured before hole-1. The plate drifting
    20 um a point along the seat line lengthens the mean centres' distance by 20 um x 30 points = 0.6 mm; removing
    the capture-order trend gives back the true distance (within 0.1 mm, the trend's own noise); without a
    drift, or with the drift's order shuffled, the two agree within that noise."""
    from calibration.placements import order_detrended_distance_error
    rng = np.random.default_rng(3)
    feature = np.array(["hole-0"] * 30 + ["hole-1"] * 30)
    centre = np.where((feature == "hole-1")[:, None], [0.05, 0.0, 0.0], [0.0, 0.0, 0.0])
    x = centre + rng.normal(0.0, 1e-4, (60, 3))
    drift = np.arange(60)[:, None] * np.array([20e-6, 0.0, 0.0])
    f = seat_figures(x + drift, feature, ("hole-0", "hole-1"), 0.05)
    assert f["distance_error_mm"] == pytest.approx(0.6, abs=0.1)
    assert abs(f["distance_error_detrended_mm"]) < 0.1
    still = seat_figures(x, feature, ("hole-0", "hole-1"), 0.05)
    assert abs(still["distance_error_detrended_mm"] - still["distance_error_mm"]) < 0.1
    shuffled = rng.permutation(60)
    assert abs(order_detrended_distance_error((x + drift)[shuffled], feature[shuffled], ("hole-0", "hole-1"), 0.05)
               - f["distance_error_mm"]) < 0.15


def test_the_study_trains_on_two_placements_together_and_predicts_the_third(tmp_path):
    from calibration.placements import placement_study
    rows = placement_study(REAL, REAL / "panda-with-inertials.urdf", "ball_link", tmp_path, train=["front+right"],
                           methods=("calibrate",))
    assert [(r.train, r.method, r.test) for r in rows] == [("front+right", "calibrate", "back-high")]
    trained = (tmp_path / "front+right" / "points.csv").read_text().splitlines()
    parts = [(REAL / p / "points.csv").read_text().splitlines() for p in ("front", "right")]
    assert len(trained) == len(parts[0]) + len(parts[1]) - 1 and trained[0] == parts[0][0]
    assert 0.2 < rows[0].figures["spread_mean_mm"] < 5.0
