"""Reliability, inputs: values that cannot be right are refused at the boundary (options and files,
exit 2, one message, nothing written); unknown keys are errors with the nearest known key suggested;
degenerate data give clear errors instead of tracebacks; over-range forces and joint angles beyond
their limits are flagged everywhere (console, summary.json, report), never dropped."""
from __future__ import annotations

import json
import time
from pathlib import Path

import pytest

from arm_model import InputError
from arm_model.cli import main
from arm_model.io import parse_artefacts
from arm_model.sim import campaign_from_dict, simulate
from conftest import NOMINAL, ROOT

RING = ROOT / "examples" / "data" / "paper-ring-xyz"
TABLE2 = ROOT / "correction" / "data" / "paper_table2.csv"
SMALL = {"seed": 5, "sensor": "xyz", "signals": {"enabled": False},
         "noise": {"probing_repeatability_um": 2.0},
         "task": [{"kind": "ballbar", "positions": 6, "length_mm": 600.0, "points_per_sphere": 4},
                  {"kind": "seat", "articulations": 6, "measurements": 3},
                  {"kind": "sphere", "points": 8, "measurements": 3}]}


def tree(d: Path) -> set[str]:
    return {str(p.relative_to(d)) for p in d.rglob("*")}


def run(args, capsys):
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    assert "Traceback" not in err
    return code, out, err


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    """A small calibration campaign with one 40 N point (the probe's range is 13 N)."""
    out = tmp_path_factory.mktemp("small")
    simulate(campaign_from_dict(SMALL, arm=NOMINAL)).write(out)
    lines = (out / "points.csv").read_text().splitlines()
    head = lines[0].split(",")
    k = head.index("fx_N")
    cells = lines[5].split(",")
    cells[k] = "40.0"
    lines[5] = ",".join(cells)
    (out / "points.csv").write_text("\n".join(lines) + "\n")
    return out


@pytest.fixture(scope="module")
def ring_files(tmp_path_factory):
    """The bundled ring campaign cut to 3 measurements; one point of ring-02 pushed at 40 N."""
    out = tmp_path_factory.mktemp("ring")
    lines = (RING / "points.csv").read_text().splitlines()
    keep = [lines[0]] + [ln for ln in lines[1:] if ln.split(",", 1)[0] in ("ring-01", "ring-02", "ring-03")]
    k = lines[0].split(",").index("fx_N")
    for i, ln in enumerate(keep):
        if ln.startswith("ring-02"):
            cells = ln.split(",")
            cells[k] = "40"
            keep[i] = ",".join(cells)
            break
    (out / "points.csv").write_text("\n".join(keep) + "\n")
    return out


# ---------------------------------------------------------------------------------------------
# options

BAD_OPTIONS = [
    (["ring", "{p}", "{a}", "--probability-pct", "150"], "--probability-pct"),
    (["ring", "{p}", "{a}", "--probability-pct", "0"], "--probability-pct"),
    (["ring", "{p}", "{a}", "--delta-T-C", "inf"], "--delta-T-C"),
    (["ring", "{p}", "{a}", "--delta-T-C", "nan"], "--delta-T-C"),
    (["ring", "{p}", "{a}", "--u-force-N", "4_5"], "--u-force-N"),
    (["calibrate", "{p}", "{a}", "--sigma-probe-um", "inf"], "--sigma-probe-um"),
    (["calibrate", "{p}", "{a}", "--sigma-ref-um", "-1"], "--sigma-ref-um"),
    (["calibrate", "{p}", "{a}", "--seed", "-1"], "--seed"),
    (["calibrate", "{p}", "{a}", "--min-resolution", "nan"], "--min-resolution"),
    (["calibrate", "{p}", "{a}", "--rank-tol", "2"], "--rank-tol"),
    (["close-loop", "{p}", "{a}", "--min-improvement", "nan"], "--min-improvement"),
    (["close-loop", "{p}", "{a}", "--min-improvement", "1"], "--min-improvement"),
    (["close-loop", "{p}", "{a}", "--seed", "1.5"], "--seed"),
    (["study", "poses", "{p}", "{a}", "--count", "-3"], "--count"),
    (["study", "poses", "{p}", "{a}", "--count", "0"], "--count"),
    (["study", "montecarlo", "{c}", "--holdout", "1.5"], "--holdout"),
    (["study", "montecarlo", "{c}", "--workers", "0"], "--workers"),
    (["study", "montecarlo", "{c}", "--runs", "0"], "--runs"),
    (["view", "{p}", "--port", "70000", "--html", "{o}.html"], "--port"),
    (["simulate", "{c}", "--seed", "-1"], "--seed"),
    # values that overflowed, underflowed to zero or ran (nearly) forever before they were bounded
    (["tip", "{p}", "--mc", "99999999999999999999"], "--mc"),
    (["tip", "{p}", "--seed", "1_0"], "--seed"),
    (["tip", "{p}", "--u-probing-um", "1e308"], "--u-probing-um"),
    (["tip", "{p}", "--encoder-resolution-deg", "1e99"], "--encoder-resolution-deg"),
    (["ring", "{p}", "{a}", "--u-force-N", "1e308"], "--u-force-N"),
    (["ring", "{p}", "{a}", "--delta-T-C", "1e308"], "--delta-T-C"),
    (["calibrate", "{p}", "{a}", "--sigma-probe-um", "1e-320"], "--sigma-probe-um"),
    (["calibrate", "{p}", "{a}", "--sigma-length-um", "1e308"], "--sigma-length-um"),
    (["calibrate", "{p}", "{a}", "--plausible-length-mm", "1e308"], "--plausible-length-mm"),
    (["calibrate", "{p}", "{a}", "--prior-scale", "1_0"], "--prior-scale"),
    (["close-loop", "{p}", "{a}", "--alpha", "1e-320"], "--alpha"),
    (["close-loop", "{p}", "{a}", "--max-effects", "99999999999999999999"], "--max-effects"),
    (["close-loop", "{p}", "{a}", "--cv-top", "1001"], "--cv-top"),
    (["close-loop", "{p}", "{a}", "--pairs", "1" + "0" * 300], "--pairs"),
    (["study", "montecarlo", "{c}", "--runs", "99999999999999999999"], "--runs"),
    (["view", "{p}", "--scale", "1e308", "--html", "{o}.html"], "--scale"),
]


@pytest.mark.parametrize("args, option", BAD_OPTIONS)
def test_bad_option_values_are_refused(tmp_path, capsys, args, option):
    fill = {"p": RING / "points.csv", "a": RING / "artefacts.toml", "c": ROOT / "examples" / "campaigns" /
            "paper-ring.toml", "o": tmp_path / "out"}
    argv = [a.format(**{k: str(v) for k, v in fill.items()}) for a in args]
    if args[0] in ("tip", "ring", "calibrate", "close-loop", "view") or args[:2] == ["study", "poses"]:
        argv += ["--arm", str(NOMINAL)]
    if "--html" not in args:
        argv += ["-o", str(tmp_path / ("out.csv" if args[0] == "tip" else "out"))]
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert option in err and "Traceback" not in err
    assert tree(tmp_path) == set()


def test_poses_count_beyond_the_measurements(small, tmp_path, capsys):
    code, _, err = run(["study", "poses", small / "points.csv", small / "artefacts.toml", "--arm", NOMINAL,
                        "--count", "1000", "-q", "-o", tmp_path / "o"], capsys)
    assert code == 2 and "--count 1000: the points file has 12 measurement(s)" in err
    assert tree(tmp_path) == set()


def test_unreachable_scheduler_fails_fast_naming_it(tmp_path, capsys):
    camp = tmp_path / "c.toml"
    camp.write_text(f'arm = "{NOMINAL}"\nsensor = "none"\n[[task]]\nkind = "seat"\nmeasurements = 2\n'
                    'articulations = 4\n')
    t0 = time.perf_counter()
    code, _, err = run(["study", "montecarlo", camp, "--scheduler", "tcp://127.0.0.1:9", "--runs", "2", "-q",
                        "-o", tmp_path / "o"], capsys)
    assert code == 2 and "cannot reach the Dask scheduler at 'tcp://127.0.0.1:9'" in err
    # fails fast: within the toolkit's connect timeout (3 s) plus start-up, far below Dask's own 30 s wait
    # (a generous margin: a loaded CI machine stretches the wall time)
    assert time.perf_counter() - t0 < 15.0
    assert tree(tmp_path) == {"c.toml"}


# ---------------------------------------------------------------------------------------------
# files: unknown keys, values that cannot be right

ART = '[[feature]]\nid = "ring"\nkind = "ring"\ndiameter_mm = 175.0\n'
TWO = '[[feature]]\nid = "a"\nkind = "sphere"\ndiameter_mm = 25\n[[feature]]\nid = "b"\nkind = "sphere"\n' \
      'diameter_mm = 25\n[[distance]]\nbetween = ["a", "b"]\nlength_mm = 600\n'


@pytest.mark.parametrize("text, line, message", [
    (ART + "u_diamter_mm = 0.001\n", 5, "unknown key 'u_diamter_mm'; did you mean 'u_diameter_mm'?"),
    (ART + "certificate = 'X'\n", 5, "unknown key 'certificate'"),
    (ART + "u_diameter_mm = -0.001\n", 5, "must not be negative"),
    (ART + "form_error_mm = -1\n", 5, "must not be negative"),
    (ART + "u_diameter_deg = 1\n", 5, "must be a length"),
    (ART + "diameter_m = 0.175\n", 5, "given twice"),
    (TWO + "u_length_mm = 0\n", 12, "must be > 0"),
    (TWO + "u_length_mm = -0.001\n", 12, "must be > 0"),
    (TWO + "u_lenght_mm = 0.001\n", 12, "did you mean 'u_length_mm'?"),
    (TWO.replace('["a", "b"]', '["a", "a"]'), 10, "names 'a' twice"),
    ("featur = 1\n" + ART, 1, "did you mean 'feature'?"),
])
def test_artefact_values_that_cannot_be_right(text, line, message):
    with pytest.raises(InputError, match=message.replace("?", r"\?").replace("(", r"\(")) as e:
        parse_artefacts(text, "a.toml")
    assert e.value.line == line and e.value.path == "a.toml"


def test_campaign_unknown_key_suggests_and_huge_campaign_is_refused(tmp_path, capsys):
    text = (ROOT / "examples" / "campaigns" / "paper-ring.toml").read_text().replace(
        'arm = "../../urdf/aacmm7.dh.toml"', f'arm = "{NOMINAL}"')
    bad = tmp_path / "typo.toml"
    bad.write_text(text.replace("force_mean_N", "forse_mean_N"))
    code, _, err = run(["simulate", bad, "-o", tmp_path / "o"], capsys)
    assert code == 2 and "line 29, key 'operator.forse_mean_N'" in err and "did you mean 'force_mean_N'?" in err
    huge = tmp_path / "huge.toml"
    huge.write_text(text.replace("measurements = 17", "measurements = 1388889"))
    t0 = time.perf_counter()
    code, _, err = run(["simulate", huge, "-o", tmp_path / "o"], capsys)
    assert code == 2 and "asks for 1e+08 points (about 55.6 h" in err and "at most 1,000,000" in err
    # fails fast: within the toolkit's connect timeout (3 s) plus start-up, far below Dask's own 30 s wait
    # (a generous margin: a loaded CI machine stretches the wall time)
    assert time.perf_counter() - t0 < 15.0
    assert tree(tmp_path) == {"typo.toml", "huge.toml"}


def test_description_unknown_key_suggests(tmp_path, capsys):
    arm = tmp_path / "arm.toml"
    arm.write_text(NOMINAL.read_text().replace("max_force_N", "max_forse_N"))
    code, _, err = run(["tip", RING / "points.csv", "--arm", arm, "-o", tmp_path / "t.csv"], capsys)
    assert code == 2 and "max_forse_N" in err and "did you mean 'max_force" in err
    assert tree(tmp_path) == {"arm.toml"}


# ---------------------------------------------------------------------------------------------
# degenerate but valid data

def _ring_variant(tmp_path, keep=None, zero=False):
    lines = (RING / "points.csv").read_text().splitlines()
    head = lines[0].split(",")
    rows = [ln for ln in lines[1:] if keep is None or ln.split(",", 1)[0] in keep]
    if zero:
        idx = [head.index(c) for c in ("fx_N", "fy_N", "fz_N")]
        rows = [",".join("0" if k in idx else c for k, c in enumerate(r.split(","))) for r in rows]
    p = tmp_path / "in" / "points.csv"
    p.parent.mkdir(exist_ok=True)
    p.write_text("\n".join([lines[0]] + rows) + "\n")
    return p


@pytest.mark.parametrize("keep, zero, message", [
    (("ring-01",), False, "1 measurement(s) of the ring; the analysis"),
    (None, True, "the mean force is zero in every measurement"),
])
def test_degenerate_ring_campaigns(tmp_path, capsys, keep, zero, message):
    pts = _ring_variant(tmp_path, keep, zero)
    code, _, err = run(["ring", pts, RING / "artefacts.toml", "--arm", NOMINAL, "-o", tmp_path / "o"], capsys)
    assert code == 2 and message in err
    assert not (tmp_path / "o").exists()


def _table(tmp_path, name, text=None, data=None):
    p = tmp_path / "in" / name
    p.parent.mkdir(exist_ok=True)
    if data is not None:
        p.write_bytes(data)
    else:
        p.write_text(text, encoding="utf-8")
    return p


def test_degenerate_paper_tables(tmp_path, capsys):
    src = TABLE2.read_text()
    rows = [ln for ln in src.splitlines() if ln.strip() and not ln.startswith("#")]
    zero = rows[0] + "\n" + "\n".join(ln.split(",")[0] + ",0,0,0,0,0" for ln in rows[1:]) + "\n"
    cases = [(_table(tmp_path, "two.csv", "\n".join(rows[:3]) + "\n"), "2 measurement row(s)"),
             (_table(tmp_path, "zero.csv", zero), "line 2, column 'initial_mm': an initial diameter error of 0"),
             (_table(tmp_path, "latin1.csv", data=src.encode().replace(b"measurement", b"m\xe9asurement", 1)),
              "not UTF-8 text"),
             (_table(tmp_path, "extra.csv", src.replace("max10_force_mm", "max10_force_mm,note", 1)),
              "unknown column 'note'")]
    for table, message in cases:
        code, _, err = run(["paper", "--table2", table, "-o", tmp_path / "o"], capsys)
        assert code == 2 and message in err, err
        assert not (tmp_path / "o").exists()


def test_paper_accepts_a_bom(tmp_path, capsys):
    table = _table(tmp_path, "bom.csv", "\ufeff" + TABLE2.read_text())
    code, out, _ = run(["paper", "--table2", table, "-o", tmp_path / "o"], capsys)
    assert code == 0 and "Table 2 (" in out and (tmp_path / "o" / "summary.json").is_file()


def test_calibrate_with_one_pose_repeated_says_unidentifiable(small, tmp_path, capsys):
    lines = (small / "points.csv").read_text().splitlines()
    head = lines[0].split(",")
    f = head.index("feature")
    sphere = next(ln for ln in lines[1:] if ln.split(",")[f] == "sphere")
    pts = tmp_path / "in" / "p.csv"
    pts.parent.mkdir()
    pts.write_text("\n".join([lines[0]] + [sphere] * 12) + "\n")
    code, _, err = run(["calibrate", pts, small / "artefacts.toml", "--arm", NOMINAL, "-o", tmp_path / "o"], capsys)
    assert code == 2 and "unidentifiable" in err and "did not converge" not in err
    assert "warning: 11 row(s) repeat an earlier reading exactly" in err       # said before the fit fails
    assert not (tmp_path / "o").exists()


def test_close_loop_with_one_sphere_measurement(small, tmp_path, capsys):
    lines = (small / "points.csv").read_text().splitlines()
    m = lines[0].split(",").index("measurement")
    first = next(ln.split(",")[m] for ln in lines[1:] if "sphere" in ln)
    pts = tmp_path / "in" / "p.csv"
    pts.parent.mkdir()
    pts.write_text("\n".join([lines[0]] + [ln for ln in lines[1:] if ln.split(",")[m] == first]) + "\n")
    code, _, err = run(["close-loop", pts, small / "artefacts.toml", "--arm", NOMINAL, "--quiet",
                        "-o", tmp_path / "o"], capsys)
    # one measurement: the test set falls back to poses of the feature, and the fit says what is missing
    # an empty held-out set is bad input (exit 2); a fit left without redundancy a numerical failure (exit 4)
    assert (code, "held-out set is empty" in err or "not enough data" in err) in ((2, True), (4, True)), err
    assert ("not enough data" in err) == (code == 4) and "Traceback" not in err
    assert not (tmp_path / "o").exists()


# ---------------------------------------------------------------------------------------------
# flagged, never dropped

def test_ring_flags_over_range_forces(ring_files, tmp_path, capsys):
    out = tmp_path / "o"
    code, _, text = run(["ring", ring_files / "points.csv", RING / "artefacts.toml", "--arm", NOMINAL,
                         "--no-plots", "-o", out], capsys)
    assert code == 0
    assert "warning: 1 point(s) with a force over the probe's calibrated range (13 N; largest 40" in text
    s = json.loads((out / "summary.json").read_text())
    (w,) = s["warnings"]
    assert w["kind"] == "over_force" and w["lines"] == [74] and w["count"] == 1
    assert "<h2>Warnings</h2>" in (out / "report.html").read_text()
    assert sum(m["n_points"] for m in s["measurements"]) == 216          # used, not dropped


def test_calibrate_and_close_loop_flag_over_range_forces(small, tmp_path, capsys):
    base = [small / "points.csv", small / "artefacts.toml", "--arm", NOMINAL]
    code, _, text = run(["calibrate", *base, "--no-plots", "-o", tmp_path / "cal"], capsys)
    assert code == 0 and "warning: 1 point(s) with a force over the probe's calibrated range" in text
    s = json.loads((tmp_path / "cal" / "summary.json").read_text())
    assert [w["lines"] for w in s["warnings"]] == [[6]]
    assert "<h2>Warnings</h2>" in (tmp_path / "cal" / "report.html").read_text()
    code, _, text = run(["close-loop", *base, "--max-effects", "0", "--folds", "2", "--quiet", "--no-plots",
                         "-o", tmp_path / "loop"], capsys)
    assert code == 0 and "warning: 1 point(s) with a force over the probe's calibrated range" in text
    s = json.loads((tmp_path / "loop" / "summary.json").read_text())
    assert [w["lines"] for w in s["warnings"]] == [[6]]
    assert "<h2>Warnings</h2>" in (tmp_path / "loop" / "report.html").read_text()


def test_rows_repeated_exactly_are_warned_with_the_copies_lines(tmp_path):
    """A points file with rows given twice (the copies at lines 5-7; a row differing in one reading's last digit is no
    copy): one ``duplicate_rows`` warning with the copies' lines and count, as summary.json lists it."""
    from arm_model import load_description
    from arm_model.checks import point_warnings
    from arm_model.io import read_points
    lines = (RING / "points.csv").read_text().splitlines()[:4]
    head = lines[0].split(",")
    k = head.index("q3_deg")
    near = lines[3].split(",")
    near[k] = near[k][:-1] + ("1" if near[k][-1] != "1" else "2")
    pts = tmp_path / "p.csv"
    pts.write_text("\n".join(lines + [lines[1], lines[2], lines[2], ",".join(near)]) + "\n")
    desc = load_description(NOMINAL)
    (w,) = [w for w in point_warnings(desc, read_points(pts, desc.n_joints)) if w.kind == "duplicate_rows"]
    assert w.as_dict()["count"] == 3 and w.as_dict()["lines"] == [5, 6, 7]
    assert w.message.startswith("3 row(s) repeat an earlier reading exactly") and "lines 5, 6, 7" in w.message
    pts.write_text("\n".join(lines + [",".join(near)]) + "\n")
    assert not [w for w in point_warnings(desc, read_points(pts, desc.n_joints)) if w.kind == "duplicate_rows"]


def test_joint_angles_beyond_the_limits_are_warned(tmp_path, capsys):
    lines = (RING / "points.csv").read_text().splitlines()[:4]
    head = lines[0].split(",")
    k = head.index("q2_deg")
    cells = lines[2].split(",")
    cells[k] = "-179.5"
    lines[2] = ",".join(cells)
    pts = tmp_path / "p.csv"
    pts.write_text("\n".join(lines) + "\n")
    code, _, text = run(["tip", pts, "--arm", NOMINAL, "-o", tmp_path / "t.csv"], capsys)
    assert code == 0 and "beyond the arm's declared limits: j2 (1" in text and "line 3" in text
    assert len((tmp_path / "t.csv").read_text().splitlines()) == 4        # used all the same


def test_a_limit_of_minus_zero_is_said_as_zero():
    """A description's "-0" limit is shown as 0 in the warning, not "-0" (audit round 10)."""
    from types import SimpleNamespace

    from arm_model.checks import _limits_text
    assert _limits_text(SimpleNamespace(prismatic=False, lower=-0.0, upper=3.141592653589793)) == "0 to 180 deg"
    assert _limits_text(SimpleNamespace(prismatic=True, lower=-0.1, upper=-0.0)) == "-100 to 0 mm"


# ---------------------------------------------------------------------------------------------
# written files read back, whatever the names hold

@pytest.mark.parametrize("name", ['arm "quoted"', "<b>&amp;</b> -- ]]>", "tab\tand\u0001control", "ø ünï"])
def test_hostile_names_round_trip_through_toml_and_urdf(tmp_path, name):
    import xml.etree.ElementTree as ET
    from dataclasses import replace

    from arm_model import load_description
    from arm_model.description import format_description, parse_description
    from arm_model.urdf import BALL_FRAME, urdf_text
    from arm_model.urdf_import import load_arm

    desc = load_description(NOMINAL)
    desc = replace(desc, name=name, joints=(replace(desc.joints[0], name=name + "-j1"),) + desc.joints[1:])
    if any(not c.isprintable() for c in name):
        # a control character is refused when read (round 8: names go into file names and every CSV table), at
        # its key; the writers still escape what a description built in Python holds
        from arm_model import InputError
        with pytest.raises(InputError, match=r"x.toml, line \d+, key 'name': 'name' must be one line of text"):
            parse_description(format_description(desc), "x.toml")
    else:
        back = parse_description(format_description(desc), "x.toml")
        assert back.name == name and back.joints[0].name == name + "-j1"
    urdf = tmp_path / "a.urdf"
    urdf.write_text(urdf_text(desc), encoding="utf-8")
    root = ET.parse(urdf).getroot()                       # well-formed XML
    printable = "".join(c if c.isprintable() else "\ufffd" for c in name)
    assert root.get("name") == printable
    arm = load_arm(urdf, BALL_FRAME)
    assert arm.n_joints == 7 and arm.joints[0].name == printable + "-j1"
