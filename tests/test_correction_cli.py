"""``aacmm ring`` and ``aacmm paper``: the files they write, their content, and refusals."""
from __future__ import annotations

import json
import tomllib

import pytest

from arm_model import load_description, read_artefacts, read_points
from arm_model.cli import build_parser, main
from arm_model.output import MARKER
from conftest import NOMINAL, ROOT, assert_close
from correction.models import analyse_ring_campaign

RING_FILES = {"report.html", "summary.json", "table2.csv", "correlations.csv", "budgets.csv", "roundness.csv",
              "figures/point_errors.png", "figures/diameters.png", "figures/form_errors.png", "figures/forces.png",
              "figures/correlation_diameter.png", "figures/correlation_form.png", "figures/budgets.png",
              "figures/roundness.png"}


@pytest.fixture(scope="module")
def small_campaign(tmp_path_factory):
    """A small simulated paper-like campaign (3 x 24 points, three-axis forces, signals) on disk."""
    from arm_model.sim import campaign_from_dict, simulate
    data = tomllib.loads((ROOT / "examples/campaigns/paper-ring-xyz.toml").read_text())
    data.pop("arm")
    data["task"][0].update(measurements=4, points_per_row=8)
    out = tmp_path_factory.mktemp("sim")
    simulate(campaign_from_dict(data, arm=NOMINAL)).write(out)
    return out


def files_under(d):
    return {str(p.relative_to(d)) for p in d.rglob("*") if p.is_file() and p.name != MARKER}


def test_ring_report_with_signals(small_campaign, tmp_path):
    out = tmp_path / "report"
    rc = main(["ring", str(small_campaign / "points.csv"), str(small_campaign / "artefacts.toml"), "--arm",
               str(NOMINAL), "--signals", str(small_campaign / "signals"), "-o", str(out)])
    assert rc == 0
    assert files_under(out) == RING_FILES
    for png in out.glob("figures/*.png"):
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    html = (out / "report.html").read_text()
    for f in RING_FILES:
        if f.startswith("figures/"):
            assert f"src='{f}'" in html
    s = json.loads((out / "summary.json").read_text())
    assert len(s["measurements"]) == 4 and all(m["n_points"] == 24 for m in s["measurements"])
    # the summary holds what the Python API computes (forces from the same signals)
    desc = load_description(NOMINAL)
    camp = analyse_ring_campaign(desc, read_points(small_campaign / "points.csv", 7),
                                 read_artefacts(small_campaign / "artefacts.toml"),
                                 signals=small_campaign / "signals")
    for m, r in zip(s["measurements"], camp.measurements, strict=True):
        for model, fit in r.fits.items():
            assert_close(m["models"][model]["diameter_error_mm"], fit.diameter_error * 1e3, atol=1e-12)
            assert_close(m["models"][model]["form_error_mm"], fit.form_error * 1e3, atol=1e-12)
        assert_close(m["forces_N"]["max"], r.summary.max, atol=1e-12)
    assert s["summary"]["wrench"]["diameter_error_reduction_pct"] > 80
    assert {b["name"] for b in s["budgets"]} >= {"diameter, initial", "diameter, full wrench"}
    # the CSV table carries the same numbers
    lines = (out / "table2.csv").read_text().splitlines()
    header = lines[0].split(",")
    assert header[0] == "measurement" and "diameter_error_wrench_mm" in header and "force_max_N" in header
    col = header.index("diameter_error_initial_mm")
    assert_close([float(line.split(",")[col]) for line in lines[1:]],
                 [m["models"]["initial"]["diameter_error_mm"] for m in s["measurements"]], atol=1e-6)


def test_ring_report_from_point_columns_on_the_bundled_campaign(tmp_path):
    data = ROOT / "examples/data/paper-ring-xyz"
    out = tmp_path / "r"
    assert main(["ring", str(data / "points.csv"), str(data / "artefacts.toml"), "--arm", str(NOMINAL),
                 "-o", str(out), "--u-force-N", "0.01", "--no-plots"]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert len(s["measurements"]) == 17 and s["force_kind"] == "xyz"
    ucor = [t for b in s["budgets"] if b["name"] == "diameter, full wrench" for t in b["terms"] if t["name"] == "u_cor"]
    assert_close(ucor[0]["u"], 2 * 0.0142 * 0.01, atol=1e-12)
    du = s["diameter_uncertainty_from_points"]["measurements"]
    assert len(du) == 17
    for d in du:   # no parameter covariance: nothing from the parameters; the parts add in quadrature
        assert d["parameters_mm"] == 0 and d["u_mm"] > 0
        assert_close(d["u_mm"] ** 2, d["independent_mm"] ** 2 + d["compliance_mm"] ** 2, atol=1e-15)
    # the form error of each measurement with its sampled uncertainty: the same form as table2's
    fu = s["form_uncertainty_from_points"]
    assert fu["model"] == "wrench" and len(fu["measurements"]) == 17
    table = (out / "table2.csv").read_text().splitlines()
    col = table[0].split(",").index("form_error_wrench_mm")
    for f, row in zip(fu["measurements"], table[1:], strict=True):
        assert_close(f["form_mm"], float(row.split(",")[col]), atol=5e-7)   # table2: 6 decimals
        assert 0 < f["u_form_mm"] < f["form_mm"] and f["samples"] == 2000


def test_ring_refusals_write_nothing(small_campaign, tmp_path, capsys):
    pts, art = str(small_campaign / "points.csv"), str(small_campaign / "artefacts.toml")
    out = tmp_path / "never"
    # a signal folder without the measurement's file
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["ring", pts, art, "--arm", str(NOMINAL), "--signals", str(empty), "-o", str(out)]) == 2
    assert "no force signal for measurement 'ring-01'" in capsys.readouterr().err
    # a signal with one peak too few: both counts named
    sig = tmp_path / "sig"
    sig.mkdir()
    for f in (small_campaign / "signals").glob("*.csv"):
        (sig / f.name).write_text(f.read_text())
    text = (sig / "ring-02.csv").read_text().splitlines()
    (sig / "ring-02.csv").write_text("\n".join(text[: int(len(text) * 0.9)]) + "\n")
    assert main(["ring", pts, art, "--arm", str(NOMINAL), "--signals", str(sig), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "ring-02.csv" in err and "24 points" in err and "peaks" in err
    # the output over an input: the points file, or the signals folder given
    assert main(["ring", pts, art, "--arm", str(NOMINAL), "-o", pts]) == 2
    assert main(["ring", pts, art, "--arm", str(NOMINAL), "--signals", str(sig), "-o", str(sig)]) == 2
    assert "refusing to write" in capsys.readouterr().err
    # an artefacts file without a ring
    noring = tmp_path / "a.toml"
    noring.write_text('[[feature]]\nid = "ring"\nkind = "sphere"\ndiameter_mm = 25.0\n')
    assert main(["ring", pts, str(noring), "--arm", str(NOMINAL), "-o", str(out)]) == 2
    assert "0 ring features" in capsys.readouterr().err
    assert not out.exists()


def test_paper_report(tmp_path):
    out = tmp_path / "paper"
    assert main(["paper", "-o", str(out)]) == 0
    assert files_under(out) == {"report.html", "summary.json", "table2_implied.csv", "findings.csv",
                                "figures/paper_table2.png", "figures/paper_implied_forces.png",
                                "figures/paper_correlation.png", "figures/paper_loop.png"}
    s = json.loads((out / "summary.json").read_text())
    r = {c["force"]: c["r"] for c in s["pearson"] if c["with_reference"]}
    assert abs(r["mean_force_N"] - 0.89) < 0.005 and abs(r["max_force_N"] - 0.90) < 0.005
    assert s["loop"]["loo_rms_after_mm"] < 0.4 * s["loop"]["rms_before_mm"]
    assert len(s["per_measurement"]) == 17
    assert any(not f["consistent"] and "misprint" in f["note"] for f in s["findings"])
    assert "0.0723" in (out / "report.html").read_text()


def test_help_texts():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    for name in ("ring", "paper"):
        p = sub.choices[name]
        assert len(p.description) > 200
        for action in p._actions:
            if action.dest != "help":
                assert action.help and len(action.help) > 20, (name, action.dest)


def test_ring_input_uncertainties_are_overridable(small_campaign, tmp_path):
    """The points' input uncertainties of ``ring`` are the tip's options: the compliance part of the
    diameter's uncertainty is linear in the compliance's (0.2 -> 0.4 doubles it), and a probing scatter
    sigma independent at every point adds (2 sigma)^2 / N to the diameter's variance (the radius is the
    mean radial distance to first order, for points spread around the ring)."""
    def run(name, *opts):
        out = tmp_path / name
        assert main(["ring", str(small_campaign / "points.csv"), str(small_campaign / "artefacts.toml"),
                     "--arm", str(NOMINAL), "-o", str(out), "-q", "--no-plots", *opts]) == 0
        s = json.loads((out / "summary.json").read_text())
        n = {m["measurement"]: m["n_points"] for m in s["measurements"]}
        return s["diameter_uncertainty_from_points"]["measurements"], n

    base, n = run("base")
    more, _ = run("more", "--u-compliance-rel", "0.4", "--u-probing-um", "3")
    # --no-plots: every file but the figures, and a report that shows none
    assert files_under(tmp_path / "base") == {f for f in RING_FILES if not f.startswith("figures/")}
    assert "<img" not in (tmp_path / "base" / "report.html").read_text()
    for a, b in zip(base, more, strict=True):
        assert a["compliance_mm"] > 0
        assert_close(b["compliance_mm"], 2 * a["compliance_mm"], atol=1e-9 * a["compliance_mm"])
        added = b["independent_mm"] ** 2 - a["independent_mm"] ** 2
        assert_close(added, (2 * 3e-3) ** 2 / n[a["measurement"]], atol=0.1 * added)
