"""One placement of one plane, validated on a stated held-out file (``--holdout-points``): a humanoid standing on
its foot touching a table with its hand (the chain runs back up the leg, ``--base-frame``), simulated here with a
known truth on the self-written robot of ``test_urdf_base_below_root``. Also the noise rule for a group with
few redundant rows whose residuals refute the stated uncertainty."""
import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from test_urdf_base_below_root import PELVIS_ROOTED  # noqa: E402

from arm_model.cli import main  # noqa: E402
from arm_model.model_file import load_model  # noqa: E402
from calibration.calibrate import MIN_REDUNDANCY, _refutes  # noqa: E402

TRUTH = {"l_knee.origin_roll": 16e-3, "l_hip.origin_pitch": 16e-3, "shoulder.origin_roll": -12e-3,
         "wrist.origin_pitch": 12e-3, "l_ankle.origin_yaw": 10e-3, "l_knee.origin_x": 6e-3}
HEIGHT = 0.9          # the table's height above the sole [m]


def _touches(arm, p, n, rng, noise_rad):
    """(q readings, n touches): random leg and arm angles, the waist lift solved so that the true tool point is on
    the table; the readings carry ``noise_rad`` of encoder noise (the contact's scatter)."""
    out = []
    while len(out) < n:
        q = np.r_[rng.uniform(-0.4, 0.4, 3), 0.0, rng.uniform(-1.0, 1.0, 2)]
        for _ in range(20):                      # Newton on the lift: the tool's height is nearly linear in it
            z = arm.model.ball_centres(q[None], None, p)[0, 2]
            dz = (arm.model.ball_centres((q + [0, 0, 0, 1e-6, 0, 0])[None], None, p)[0, 2] - z) / 1e-6
            q[3] -= (z - HEIGHT) / dz
        if abs(arm.model.ball_centres(q[None], None, p)[0, 2] - HEIGHT) < 1e-12 and abs(q[3]) < 1.0:
            out.append(q + np.r_[rng.normal(0, noise_rad, 3), 0.0, rng.normal(0, noise_rad, 2)])
    return np.array(out)


def _write(path, q, measurement="session-1"):
    cols = ["q1_deg", "q2_deg", "q3_deg", "q4_mm", "q5_deg", "q6_deg"]
    conv = np.array([180 / math.pi] * 3 + [1000.0] + [180 / math.pi] * 2)
    with open(path, "w") as f:
        f.write("measurement,feature," + ",".join(cols) + "\n")
        for row in q * conv:
            f.write(f"{measurement},table," + ",".join(f"{v:.12g}" for v in row) + "\n")


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    d = tmp_path_factory.mktemp("plane")
    urdf = d / "walker.urdf"
    urdf.write_text(PELVIS_ROOTED)
    arm = load_model(urdf, "tool", base_frame="l_sole")
    p = arm.p.copy()
    for name, v in TRUTH.items():
        p[arm.model.spec.names.index(name)] = v
    rng = np.random.default_rng(7)
    _write(d / "train.csv", _touches(arm, p, 40, rng, 2e-4))
    _write(d / "validation.csv", _touches(arm, p, 12, rng, 2e-4))
    (d / "table.toml").write_text('[[feature]]\nid = "table"\nkind = "plane"\n')
    return d


def _calibrate(d, *extra):
    return main(["calibrate", str(d / "train.csv"), str(d / "table.toml"), "--arm", str(d / "walker.urdf"),
                 "--tip-frame", "tool", "--base-frame", "l_sole", "--effect", "none", "--no-plots", *extra])


def test_a_stated_validation_file_is_predicted_against_the_plane_fitted_on_training(campaign, capsys):
    """Every held-out touch is predicted against the table as fitted on the training touches: the calibrated model
    predicts them at least twice better than the nominal given the same unknowns (plane, tool offset); the
    held-out poses are the file's rows, the training model is fitted without them, and the noise of the contact
    (encoder noise of 0.2 mrad on levers of about 1 m: a few tenths of a millimetre), stated at 10 um, is
    estimated."""
    out = campaign / "cal"
    assert _calibrate(campaign, "--holdout-points", str(campaign / "validation.csv"), "-o", str(out)) == 0
    text = capsys.readouterr().out
    assert "12 held-out poses (the --holdout-points file's)" in text
    s = json.loads((out / "summary.json").read_text())
    assert s["holdout_by"] == "pose" and s["n_points"] == 40 and len(s["holdout_poses"]) == 12
    assert s["inputs"]["holdout_points"].endswith("validation.csv")
    rms = [r for r in s["validation_holdout"] if r["key"] == "pose_rms"][0]
    assert rms["after"] < 0.5 * rms["before"], rms
    plane = [v for v in s["variance_components"] if v["group"] == "plane"][0]
    assert plane["estimated"] and 50 < plane["estimate_um"] < 2000, plane
    assert 0.5 < s["s0"] < 2.0
    # the parameters held for rank are counted beyond a dozen lines, all of them in summary.json
    lines = [ln for ln in text.splitlines() if ln.startswith("  fixed ")]
    assert len(s["fixed"]) > 12 and len(lines) == 12
    assert f"... and {len(s['fixed']) - 12} more fixed parameters" in text


@pytest.mark.parametrize("case, words", [
    ("with --holdout", "give one of them"),
    ("with --holdout-by measurement", "leave --holdout-by out"),
    ("the points file", "the points file itself"),
    ("another plane", "which the training points fit on 0 point(s)"),
])
def test_holdout_points_refused(campaign, capsys, case, words):
    """A held-out file beside --holdout or --holdout-by measurement (ignored without a word before), the points
    file given again, or touches of a plane the training file
    never touched (another measurement): one message (the last naming the held-out file and line), exit 2,
    nothing written."""
    other = campaign / "other.csv"
    _write(other, np.zeros((2, 6)) + [0, 0, 0, 0.1, 0, 0], measurement="session-2")
    extra = {"with --holdout": ["--holdout", "0.2", "--holdout-points", str(campaign / "validation.csv")],
             "with --holdout-by measurement": ["--holdout-by", "measurement", "--holdout-points",
                                               str(campaign / "validation.csv")],
             "the points file": ["--holdout-points", str(campaign / "train.csv")],
             "another plane": ["--holdout-points", str(other)]}[case]
    out = campaign / "refused"
    assert _calibrate(campaign, *extra, "-o", str(out)) == 2
    err = capsys.readouterr().err
    assert words in err and not out.exists()
    if case == "another plane":
        assert "other.csv" in err and "line 2" in err


def test_refuted_stated_uncertainty_hand_derived():
    """Chi-square with 2 degrees of freedom has the tail exp(-x/2): the stated uncertainty is refuted beyond
    x = 2 ln(1e6) = 27.63 (and below x = -2 ln(1 - 1e-6) = 2e-6); with 3 redundant rows, residuals of 1 mm
    against a stated 10 um (x = 3e4) refute it."""
    edge = 2 * math.log(1e6)
    assert not _refutes(edge - 0.05, 2.0) and _refutes(edge + 0.05, 2.0)
    assert _refutes(1.5e-6, 2.0) and not _refutes(2.5e-6, 2.0)
    assert _refutes(3.0 * (1e-3 / 10e-6) ** 2, 3.0) and not _refutes(3.0, 3.0)
    assert MIN_REDUNDANCY == 5.0


def test_too_few_touches_hold_only_what_the_chain_cannot_separate(campaign, capsys):
    """14 touches give 11 data dimensions (rows less the plane's 3 unknowns), fewer than the 23 parameters the
    chain and a plane can separate at all: the rank test is the structural one (the same parameters held as with
    40 touches), the others stay free under the prior, more of them than the data have dimensions, and the
    held-out touches are predicted better than by the nominal given the same unknowns, and better than with the
    data's own rank test (which held all but 11)."""
    rows = (campaign / "train.csv").read_text().splitlines()
    few = campaign / "few"
    few.mkdir(exist_ok=True)
    (few / "train.csv").write_text("\n".join(rows[:15]) + "\n")
    for name in ("walker.urdf", "table.toml", "validation.csv"):
        (few / name).write_text((campaign / name).read_text())
    assert _calibrate(few, "--holdout-points", str(few / "validation.csv"), "-o", str(few / "cal")) == 0
    assert "the fit passes through its training points" in capsys.readouterr().err
    assert _calibrate(campaign, "-o", str(campaign / "all")) == 0
    assert "passes through its training points" not in capsys.readouterr().err
    s = json.loads((few / "cal" / "summary.json").read_text())
    full = json.loads((campaign / "all" / "summary.json").read_text())
    assert s["n_points"] == 14 and len(s["free"]) > 14 - 3
    assert {f["name"] for f in s["fixed"]} == {f["name"] for f in full["fixed"]}
    # held by the data's own rank (11 free) the held-out RMS was 0.76 of the nominal's; structurally 0.37
    rms = [r for r in s["validation_holdout"] if r["key"] == "pose_rms"][0]
    assert rms["after"] < 0.5 * rms["before"], rms


def test_repeated_readings_count_once_in_n_points_and_each_in_n_rows(campaign, capsys):
    """Two rows of the file written twice more (a logger's copies): the fit counts each reading once, and so does
    summary.json's n_points (it counted the copies: 43); n_rows counts the file's rows."""
    rows = (campaign / "train.csv").read_text().splitlines()
    twice = campaign / "twice"
    twice.mkdir(exist_ok=True)
    (twice / "train.csv").write_text("\n".join(rows + [rows[3], rows[3], rows[7]]) + "\n")
    for name in ("walker.urdf", "table.toml"):
        (twice / name).write_text((campaign / name).read_text())
    assert _calibrate(twice, "-o", str(twice / "cal")) == 0
    assert "3 row(s) repeat an earlier reading exactly" in capsys.readouterr().err
    s = json.loads((twice / "cal" / "summary.json").read_text())
    assert (s["n_points"], s["n_rows"]) == (40, 43)
