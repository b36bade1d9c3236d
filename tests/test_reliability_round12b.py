"""Reliability, round 12 (b): the leftovers of the round 12 hostile-input audit. A session that took no point wrote a
header-only points.csv (no points file: `tip` refused it, so session.json's `reproduce` failed); a model file reached
through a symbolic link looked for the files it names beside the link; `view --residual-scale` without anything it
draws was accepted and did nothing. Each test is named after its finding and is quick (no fit, a few points)."""
from __future__ import annotations

import json

from test_reliability_round12 import RING, SAMPLES, _run

from conftest import ROOT, exit_status


def test_a_session_without_a_point_writes_no_points_file_and_no_reproduce_line(tmp_path, capsys):
    """99 samples, no contact: points.csv and tips.csv were a header alone, which `tip` refuses ("no points after the
    header line"), so the `reproduce` command of session.json failed, and the folder held a file its reader refuses.
    Now both files come with the first point, `reproduce` is null until then, and the command says why."""
    stream = tmp_path / "stream.csv"
    stream.write_text("".join(SAMPLES.read_text().splitlines(keepends=True)[:100]))
    sess = tmp_path / "s"
    rc = exit_status(["live", str(stream), "--arm", "aacmm7", "--speed", "0", "-o", str(sess)])
    out = capsys.readouterr()
    assert rc == 0, out.err
    assert "no point was taken: the folder has no points.csv and no tips.csv" in out.out + out.err
    assert sorted(p.name for p in sess.iterdir() if not p.name.startswith(".")) == \
        ["contacts.csv", "events.csv", "features.csv", "samples.csv", "session.json"]
    status = json.loads((sess / "session.json").read_text())
    assert status["counts"]["points"] == 0 and status["reproduce"] is None


def test_a_residual_scale_without_anything_it_draws_is_refused(tmp_path, capsys):
    """`view --residual-scale 100` without --residuals, and with no tracker's markers seen in the points, drew nothing
    with it and said nothing (the other options that did nothing were refused in round 12). Now exit 2 naming it and
    what it belongs to, nothing written; with --residuals it draws (tests/test_viz_cli.py)."""
    out = tmp_path / "v.html"
    rc, err = _run(["view", RING / "points.csv", "--arm", "aacmm7", "--residual-scale", "100", "--html", out], capsys)
    assert rc == 2 and "--residual-scale: option(s) of the drawing of residuals, which is not asked for (add " \
        "--residuals FILE; or, for a tracker's markers, a model file with [[reference_frame]] and points with its " \
        "reference columns)" in err, err
    assert list(tmp_path.iterdir()) == []


def test_a_model_file_through_a_link_names_the_files_beside_itself(tmp_path):
    """A model file reached through a symbolic link (`ln -s ../cal/m.toml current.toml`) looked for its covariance
    file and training poses beside the link, where there are none (or another fit's: read as this one's). The
    files a model file names were written beside it; a link is not a copy of its folder. Now both are looked for
    beside the file the link points to (docs/formats.md), as the model file named directly."""
    from arm_model.model_file import parse_model
    real, other = tmp_path / "cal", tmp_path / "elsewhere"
    real.mkdir()
    other.mkdir()
    text = (ROOT / "urdf" / "aacmm7.dh.toml").read_text() + \
        '\n[calibration]\ncovariance = "m-covariance.csv"\ntraining_poses = "m-training.csv"\n'
    (real / "m.toml").write_text(text)
    (other / "current.toml").symlink_to(real / "m.toml")
    (tmp_path / "up.toml").symlink_to(other / "current.toml")         # a link to a link: followed to its end
    for name in (tmp_path / "up.toml", real / "m.toml"):               # through the links, and named directly
        arm = parse_model(text, str(name))
        assert (arm.covariance, arm.training_poses) == (real / "m-covariance.csv", real / "m-training.csv")
