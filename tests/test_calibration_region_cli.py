"""``aacmm calibrate --region-effect`` (calibration/region.py from the command line), and what the console and
report.html say of repeated readings and of the file an outlier's point is in."""
from __future__ import annotations

import json

import numpy as np
import pytest

from arm_model.cli import main
from arm_model.model import ArmModel
from arm_model.sim.quick import SynthSpec, make_campaign
from conftest import NOMINAL

COV = "aacmm7-calibrated-covariance.csv"


@pytest.fixture(scope="module")
def files(tmp_path_factory, nominal):
    """A small campaign whose model holds (the region test does not keep an effect on it: likelihood ratio 0.2
    against a largest null draw of 15.6)."""
    c = make_campaign(ArmModel(nominal), SynthSpec(ballbars=4, ballbar_points=5, seats=3, articulations=10, spheres=1,
                                                   sphere_points=10, noise=2e-6), seed=4)
    return c.write(tmp_path_factory.mktemp("campaign"))


def _calibrate(f, out, *extra, points=None) -> dict:
    code = main(["calibrate", str(points or f["points"]), str(f["artefacts"]), "--arm", str(NOMINAL), "--effect",
                 "none", "--no-plots", "-o", str(out), *extra])
    assert code == 0
    return json.loads((out / "summary.json").read_text())


@pytest.fixture(scope="module")
def without(files, tmp_path_factory):
    """The output folder and summary of the fit without ``--region-effect``."""
    out = tmp_path_factory.mktemp("without") / "out"
    return out, _calibrate(files, out)


def test_region_effect_option_reaches_the_fit_and_a_rejected_effect_leaves_the_covariance_file(files, without,
                                                                                                 tmp_path, capsys):
    off_dir, off = without
    capsys.readouterr()
    on = _calibrate(files, tmp_path / "on", "--region-effect")
    assert "region effect: not kept (nothing added to the covariance): likelihood ratio" in capsys.readouterr().out
    assert off["region_effect"] is None
    reg = on["region_effect"]
    assert reg is not None and reg["folds"] > 0 and reg["likelihood_ratio"] < reg["likelihood_ratio_critical"]
    assert reg["sd_per_prior_sd"] == {} and reg["p_value"] > 0.05 and reg["null_draws"] < 199     # stopped early
    assert (tmp_path / "on" / COV).read_bytes() == (off_dir / COV).read_bytes()


def test_a_kept_region_effect_widens_the_covariance_file(files, without, tmp_path, monkeypatch, capsys):
    """With the Monte Carlo test switched off (no null draws: the maximum-likelihood variances are taken as they
    are) the effect is kept, and the covariance file written holds more than the posterior."""
    from arm_model.model_file import read_covariance
    from calibration import region
    monkeypatch.setattr(region, "NULL_DRAWS", 0)
    off_dir, off = without
    capsys.readouterr()
    on = _calibrate(files, tmp_path / "on", "--region-effect")
    assert on["region_effect"]["sd_per_prior_sd"]
    largest = next(iter(on["region_effect"]["sd_per_prior_sd"]))
    err = capsys.readouterr().out
    assert "region effect: kept: likelihood ratio" in err and "no Monte Carlo test" in err
    assert f"largest: {largest}" in err
    a, b = read_covariance(off_dir / COV), read_covariance(tmp_path / "on" / COV)
    assert a.names == b.names
    grown = np.diag(b.matrix) - np.diag(a.matrix)
    assert np.all(grown >= -1e-12 * np.diag(a.matrix)) and np.max(grown / np.diag(a.matrix)) > 1e-3
    assert [r["u"] for r in on["parameters"]] == [r["u"] for r in off["parameters"]]    # the posterior's u


def test_repeated_readings_are_counted_once_and_outliers_name_their_file(files, tmp_path, capsys):
    """A row repeated exactly counts once ("N points (N + 1 rows)"), and the tables of report.html give the file of
    an outlier's point beside its line."""
    lines = files["points"].read_text().splitlines()
    cells = lines[6].split(",")
    cells[3] = f"{float(cells[3]) + 0.5:.12g}"           # half a degree off on joint 2: a gross error
    lines[6] = ",".join(cells)
    pts = tmp_path / "repeated.csv"
    pts.write_text("\n".join([*lines, lines[3]]) + "\n")
    n = len(lines) - 1
    summary = _calibrate(files, tmp_path / "out", points=pts)
    printed = capsys.readouterr()
    assert f"fitting the model to {n} points ({n + 1} rows)" in printed.err
    assert f"{n} training points ({n + 1} rows) in " in printed.out + printed.err     # the console's count too
    html = (tmp_path / "out" / "report.html").read_text()
    assert [(g["file"], g["line"]) for g in summary["gross_errors_removed"]] == [(str(pts), 7)]
    assert "<th>file</th><th>line</th>" in html and f"<td>{pts}</td><td>7</td>" in html
