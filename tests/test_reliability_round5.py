"""Reliability, round 5: a hostile-input audit of every command and of the Python API (arm_model, calibration,
correction). Each test is named after what it checks; all are fast (a few points, no long fit)."""
from __future__ import annotations

import dataclasses
import math

import pytest
from hypothesis import HealthCheck, given, settings, strategies as st
from test_reliability_properties import _mutate_lines

from arm_model.cli import main
from conftest import NOMINAL

# ---------------------------------------------------------------------------------------------
# the Python API: an Arm refuses what its model file's reader would refuse

@pytest.mark.parametrize("kw, match", [
    ({"discrepancy_growth": 0.02}, "needs 'model_discrepancy_um'"),
    ({"model_discrepancy": 5e-6, "discrepancy_growth": 0.02}, "needs 'training_poses'"),
    ({"model_discrepancy": 5e-6, "discrepancy_growth": -0.02}, "model_discrepancy_growth_um_per_mm"),
    ({"model_discrepancy": math.nan}, "model_discrepancy_um"),
    ({"model_discrepancy": 1.0}, "model_discrepancy_um"),
    ({"probing_scatter": math.inf}, "probing_scatter_um"),
])
def test_an_arm_built_in_python_refuses_a_growth_it_would_ignore(kw, match):
    """Arm(model_discrepancy=None, discrepancy_growth>0) silently dropped the growth (discrepancy was then None);
    it is a ValueError now, as the model file's reader refuses the same [calibration] table."""
    from arm_model.model_file import load_model
    arm = load_model(str(NOMINAL))
    with pytest.raises(ValueError, match=match):
        dataclasses.replace(arm, **kw)


def test_an_arm_with_its_growth_and_poses_is_accepted(tmp_path):
    from arm_model.model_file import load_model
    arm = dataclasses.replace(load_model(str(NOMINAL)), model_discrepancy=5e-6, discrepancy_growth=0.0)
    assert arm.discrepancy == 5e-6
    arm = dataclasses.replace(arm, discrepancy_growth=0.02, training_poses=tmp_path / "tp.csv")
    assert arm.discrepancy_growth == 0.02


# ---------------------------------------------------------------------------------------------
# a long text cell: memory in proportion to the file, not to the square of the cell

def test_a_long_measurement_id_reads_and_writes_in_memory_in_proportion_to_the_file(tmp_path):
    """A 10 000-character measurement id in a 2000-row points file: the fast reader built a (width + 1, width)
    mask table (800 MB here, 20 GB for a 100 kB id in a 30-row file: `tip` ended "out of memory") and both the
    reader and the CSV writer a (rows, widest cell) matrix (a 17 MB file with one 100 kB id: 94 s, 4.9 GB)."""
    import tracemalloc

    import numpy as np

    from arm_model.csv_io import format_csv
    from arm_model.io import read_points
    from arm_model.model_file import load_model
    joints = load_model(str(NOMINAL)).desc.joint_quantities
    long_id = "m" * 10_000
    cols = ",".join(f"q{k + 1}_deg" for k in range(7))
    rows = [f"{long_id if i == 0 else 'short'},seat," + ",".join(f"{10 + k + i * 1e-3:.6f}" for k in range(7)) + "\n"
            for i in range(2000)]
    (tmp_path / "p.csv").write_text(f"measurement,feature,{cols}\n" + "".join(rows))
    tracemalloc.start()
    try:
        pts = read_points(tmp_path / "p.csv", joints)
        text = format_csv({"measurement": np.asarray(pts.measurement, dtype=object), "x_mm": pts.q[:, 0]})
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert pts.measurement[0] == long_id and pts.measurement[1] == "short" and len(pts.q) == 2000
    assert text.decode().splitlines()[1].startswith(long_id + ",")
    assert peak < 30e6, f"peak {peak / 1e6:.0f} MB for a {(tmp_path / 'p.csv').stat().st_size / 1e6:.1f} MB file"


def test_a_megabyte_value_in_an_error_is_cut_in_its_middle(tmp_path, capsys):
    """A key holding a 1 MB text where a number belongs: the error quoted it whole (one 1 MB line on standard
    error); the line keeps its start (file, line, key) and end, the middle cut and counted."""
    from arm_model.log import MAX_LINE
    text = NOMINAL.read_text().replace("d_mm = 200.0", 'd_mm = "' + "a" * 1_000_000 + '"', 1)
    (tmp_path / "arm.toml").write_text(text)
    (tmp_path / "p.csv").write_text("measurement,feature," + ",".join(f"q{k}_deg" for k in range(1, 8)) + "\n"
                                    "m,f,1,2,3,4,5,6,7\n")
    assert main(["tip", str(tmp_path / "p.csv"), "--arm", str(tmp_path / "arm.toml"),
                 "-o", str(tmp_path / "o.csv")]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and len(err) < MAX_LINE + 100, len(err)
    assert "arm.toml, line 11, key 'joint[1].d_mm'" in err and "characters left out" in err
    assert not (tmp_path / "o.csv").exists()


# ---------------------------------------------------------------------------------------------
# hostile URDFs

def _urdf(tmp_path, lim='<limit lower="-3" upper="3" effort="1" velocity="1"/>', extra="", xyz="0 0 0.1"):
    joints = "".join(f'<joint name="j{i}" type="revolute"><parent link="l{i - 1}"/><child link="l{i}"/>'
                     f'<origin xyz="{xyz}" rpy="0 0 0"/><axis xyz="0 0 1"/>{lim}</joint><link name="l{i}"/>\n'
                     for i in range(1, 4))
    path = tmp_path / "r.urdf"
    path.write_text(f'<?xml version="1.0"?>\n<robot name="r" {extra}>\n<link name="l0"/>\n{joints}</robot>\n')
    return path


def test_urdf_limits_beyond_plausible_are_no_limits_and_the_model_file_reads_back(tmp_path):
    """<limit lower="-1e308" upper="1e308"> (URDFs from SDF write +-1e16 for "unlimited") were kept: a model file
    of that arm could not be written (its lower_deg -inf: a NumericalError blaming the fit) and no point was
    ever beyond them. Now they are no limits, as for a continuous joint."""
    from arm_model.model_file import format_model, load_model, parse_model
    arm = load_model(str(_urdf(tmp_path, '<limit lower="-1e308" upper="1e308" effort="1" velocity="1"/>')),
                     tip_frame="l3")
    assert all(j.lower is None and j.upper is None for j in arm.desc.joints)
    back = parse_model(format_model(arm.desc), "m.toml")
    assert all(j.lower is None for j in back.desc.joints)
    arm = load_model(str(_urdf(tmp_path)), tip_frame="l3")         # ordinary limits are kept
    assert arm.desc.joints[0].lower == -3.0


@pytest.mark.parametrize("extra, xyz, words", [
    ('xmlns:xacro="http://www.ros.org/wiki/xacro"><xacro:property name="l" value="0.1"/', "0 0 0.1",
     ("line 2", "<property> of the xacro namespace", "expand it first")),
    ("", "0 0 ${l}", ("line 4", "key 'origin.xyz'", "a xacro expression")),
    ("", "0 0 $(arg l)", ("line 4", "a xacro expression")),
])
def test_an_unexpanded_xacro_file_is_refused_with_its_line(tmp_path, capsys, extra, xyz, words):
    """A xacro file given as a URDF was read (its macros and properties silently ignored) or refused at a number
    that is an expression as "must be 3 finite numbers"; it is one error naming xacro."""
    path = _urdf(tmp_path, extra=extra, xyz=xyz)
    (tmp_path / "p.csv").write_text("measurement,feature,q1_deg,q2_deg,q3_deg\nm,f,1,2,3\n")
    rc = main(["tip", str(tmp_path / "p.csv"), "--arm", str(path), "--tip-frame", "l3", "-o", str(tmp_path / "o.csv")])
    err = capsys.readouterr().err
    assert rc == 2 and not (tmp_path / "o.csv").exists(), err
    for w in words:
        assert w in err, err


def test_an_implausible_number_too_large_for_the_display_unit_is_shown_as_written(tmp_path, capsys):
    """<origin xyz="0 0 1e308"> said "inf mm is not a plausible length": the value the file holds is shown."""
    path = _urdf(tmp_path, xyz="0 0 1e308")
    (tmp_path / "p.csv").write_text("measurement,feature,q1_deg,q2_deg,q3_deg\nm,f,1,2,3\n")
    assert main(["tip", str(tmp_path / "p.csv"), "--arm", str(path), "--tip-frame", "l3",
                 "-o", str(tmp_path / "o.csv")]) == 2
    err = capsys.readouterr().err
    assert "1e+308 m is not a plausible length" in err and "inf" not in err, err


# ---------------------------------------------------------------------------------------------
# live sources: a line that never ends

def _sample_lines(n: int = 60) -> list[str]:
    from conftest import ROOT
    return (ROOT / "examples" / "live" / "samples.csv").read_text().splitlines(keepends=True)[:n]


def test_a_stream_line_that_never_ends_is_one_bad_line_in_bounded_memory():
    """A peer (standard input, TCP) that sends 8 MB without a newline: the source kept the whole line and copied it
    at every chunk (a peer never sending a newline filled the memory). It keeps its first bytes, counts the rest,
    and gives one line the session calls bad; the lines around it are read as sent."""
    import os
    import threading
    import tracemalloc

    from arm_model import InputError
    from arm_model.live.sources import MAX_LINE_BYTES, LongLine, _FdSource, line_text
    lines = _sample_lines(4)
    r, w = os.pipe()
    sevens, eights = b"7" * 1_000_000, b"8" * 1_000_000         # made before the memory is traced
    payload = ["".join(lines[:2]).encode()] + [sevens] * 3 + [eights] * 5 + [
        b"\r\n" + "".join(lines[2:]).encode(), b"9" * (MAX_LINE_BYTES + 1)]

    def write():
        with os.fdopen(w, "wb") as fh:
            for part in payload:
                fh.write(part)
    tracemalloc.start()
    threading.Thread(target=write, daemon=True).start()
    try:
        got = [item for item in _FdSource(r, "<pipe>").lines() if item is not None]
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
        os.close(r)
    assert [no for no, _ in got] == [1, 2, 3, 4, 5, 6]
    assert [raw.decode() for _, raw in got[:2]] + [got[3][1].decode(), got[4][1].decode()] == \
        [x.rstrip("\n") for x in lines]
    assert isinstance(got[2][1], LongLine) and got[2][1].length == 8_000_001 and got[2][1].startswith(b"777")
    assert isinstance(got[5][1], LongLine) and got[5][1].length == MAX_LINE_BYTES + 1
    with pytest.raises(InputError, match=r"<pipe>, line 3: a line of 8000001 bytes or more"):
        line_text(got[2][1], "<pipe>", 3)
    assert peak < 3 * MAX_LINE_BYTES, f"peak {peak / 1e6:.1f} MB"


def test_a_recorded_stream_with_a_huge_line_counts_it_and_goes_on(tmp_path, capsys):
    lines = _sample_lines()
    (tmp_path / "s.csv").write_text("".join(lines[:30]) + "1," * 1_000_000 + "\n" + "".join(lines[30:]))
    out = tmp_path / "session"
    assert main(["live", str(tmp_path / "s.csv"), "--arm", "aacmm7", "-o", str(out), "--speed", "0",
                 "--feature", "plane:p"]) == 0
    err = capsys.readouterr().err
    assert "line 31: a line of 2000001 bytes or more" in err, err
    import json
    assert json.loads((out / "session.json").read_text())["counts"]["bad_lines"] == 1


# ---------------------------------------------------------------------------------------------
# a model file edited by hand

@pytest.mark.parametrize("old, new, key", [
    ("ball_diameter_mm = 4.0", "ball_diameter_mm = -4.0", "ball_diameter_mm"),
    ("max_force_N = 13.0                      # calibrated range of the force sensor", "max_force_N = 0",
     "max_force_N"),
    ("axial_compliance_mm_per_N = 0.0000876", "axial_compliance_mm_per_N = -1e-5", "axial_compliance_mm_per_N"),
])
def test_a_bad_probe_value_names_its_own_line_and_key(old, new, key):
    """ball_diameter_mm = -4 was reported at the [probe] table's line as key 'probe.ball_diameter' (no such key in
    the file): the line and the key are the value's own."""
    from arm_model import InputError
    from arm_model.description import parse_description
    text = NOMINAL.read_text()
    assert old in text
    text = text.replace(old, new)
    line = text.splitlines().index(new) + 1
    with pytest.raises(InputError) as exc:
        parse_description(text, "arm.toml")
    assert exc.value.line == line and key in str(exc.value) and f"'probe.{key}'" in str(exc.value), str(exc.value)


# ---------------------------------------------------------------------------------------------
# the correction API: a NaN in is an error, never a NaN out

@pytest.mark.parametrize("x, y, match", [
    ([1.0, 2.0, float("nan"), 4.0], [1.0, 3.0, 4.0, 5.0], "x: value 2 is nan, not finite"),
    ([1.0, 2.0, 3.0, 4.0], [1.0, float("inf"), 4.0, 5.0], "y: value 1 is inf, not finite"),
    ([1.0, 2.0, 3.0, 4.0], [1.0, 2.0, 3.0], "one length"),
])
def test_correlate_refuses_what_would_give_a_nan_r(x, y, match):
    """correlate returned r = p = slope = NaN for one NaN force: a numerical failure returned silently."""
    from correction import correlate
    with pytest.raises(ValueError, match=match):
        correlate(x, y)


@pytest.mark.parametrize("dof, p", [(0, 95.0), (-3, 95.0), (math.nan, 95.0), (5, math.nan), (5, 100.0), (5, 0.0)])
def test_student_k_refuses_what_has_no_coverage_factor(dof, p):
    """student_k(5, nan) returned NaN, student_k(0, 95) raised GTC's RuntimeError: both a ValueError."""
    from correction import student_k
    with pytest.raises(ValueError):
        student_k(dof, p)
    assert student_k(math.inf, 95.0) == pytest.approx(1.959963984540054)


# ---------------------------------------------------------------------------------------------
# the paper's Table 2 and the residuals file: the toolkit's number rule and range

def _table2(tmp_path, cell: str):
    from correction.paper import TABLE2_PATH
    rows = [line for line in TABLE2_PATH.read_text().splitlines(keepends=True) if not line.startswith("#")]
    first = rows[1].split(",")
    first[2] = cell
    path = tmp_path / "t2.csv"
    path.write_text(rows[0] + ",".join(first) + "".join(rows[2:]))
    return path


@pytest.mark.parametrize("cell, words", [
    ("1e308", "1e+308 mm is not a plausible length"),     # overflowed the fits: exit 3 after publishing
    ("１", "expected a number, got '１'"),                  # float() reads a full-width digit
])
def test_paper_table2_cells_follow_the_number_rule_and_range(tmp_path, capsys, cell, words):
    out = tmp_path / "out"
    assert main(["paper", "--table2", str(_table2(tmp_path, cell)), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "t2.csv, line 2, column 'point_force_mm'" in err and words in err and not out.exists(), err


def _residuals(tmp_path, cells: dict):
    header = ["measurement", "feature", "line", "dx_um", "dy_um", "dz_um"]
    row = {"measurement": "m", "feature": "f", "line": "2", "dx_um": "1.5", "dy_um": "-2", "dz_um": "0.5", **cells}
    path = tmp_path / "residuals.csv"
    path.write_text(",".join(header) + "\n" + ",".join(row[h] for h in header) + "\n")
    (tmp_path / "p.csv").write_text("measurement,feature," + ",".join(f"q{k}_deg" for k in range(1, 8)) + "\n"
                                    "m,f,10,20,-30,40,5,-15,25\n")
    return path


@pytest.mark.parametrize("cells, column, words", [
    ({"line": "²"}, "line", "expected a line number"),                 # isdigit() yet no int(): exit 3
    ({"dx_um": "1e308"}, "dx_um", "not a plausible length"),           # overflowed the drawing
    ({"dy_um": "1_0"}, "dy_um", "expected a finite number, got '1_0'"),
])
def test_view_residuals_cells_are_checked(tmp_path, capsys, cells, column, words):
    from arm_model import InputError
    from viz.residuals import read_residuals
    path = _residuals(tmp_path, cells)
    with pytest.raises(InputError) as exc:
        read_residuals(path)
    assert exc.value.line == 2 and column in str(exc.value) and words in str(exc.value), str(exc.value)
    read_residuals(_residuals(tmp_path, {}))


@pytest.mark.parametrize("rate", [1e308, 5e-324, 2e6])
def test_a_live_sample_rate_beyond_its_range_is_refused(tmp_path, capsys, rate):
    """--rate-Hz 1e308 counted 1e305 dropped samples a millisecond gap; 5e-324 made the period infinite."""
    from arm_model.live import Session
    with pytest.raises(ValueError, match="nominal sample rate"):
        Session("aacmm7", rate=rate)
    with pytest.raises(SystemExit) as exc:
        main(["live", "x.csv", "--arm", "aacmm7", "-o", str(tmp_path / "s"), "--rate-Hz", repr(rate)])
    assert exc.value.code == 2
    assert "--rate-Hz: must be in [0.001, 1e+06]" in capsys.readouterr().err
    assert not (tmp_path / "s").exists()


# ---------------------------------------------------------------------------------------------
# aacmm examples: whole or nothing, never through a link

def test_examples_never_writes_through_a_link_in_the_folder(tmp_path, capsys):
    """DIR/docs a symbolic link to a folder elsewhere: the copy wrote the docs there (outside DIR). An existing
    entry (file, folder or link) of those examples writes is refused, and nothing is written."""
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    dest = tmp_path / "ex"
    dest.mkdir()
    (dest / "docs").symlink_to(elsewhere)
    assert main(["examples", str(dest)]) == 2
    assert "ex/docs" in capsys.readouterr().err
    assert not list(elsewhere.iterdir()) and sorted(p.name for p in dest.iterdir()) == ["docs"]


def test_examples_is_whole_or_nothing(tmp_path, monkeypatch, capsys):
    """A copy that fails part way (disk full) left part of the examples in DIR; now nothing, not DIR either."""
    import shutil as sh
    calls = {"n": 0}
    real = sh.copy2

    def failing(src, dst, *a, **k):
        calls["n"] += 1
        if calls["n"] == 20:
            raise OSError(28, "No space left on device")
        return real(src, dst, *a, **k)
    monkeypatch.setattr(sh, "copy2", failing)
    dest = tmp_path / "ex"
    assert main(["examples", str(dest)]) == 2
    assert "No space left on device" in capsys.readouterr().err
    assert not dest.exists() and list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------------------------------
# hypothesis: the readers this round fixed return or say where

CELL = st.one_of(st.text(alphabet="0123456789.-+eE_ xnaif,\"'²１\u00a0", max_size=8),
                 st.sampled_from(["nan", "inf", "1e308", "-1e308", "1e999", "4_5", "", " ", '"', "0x10", "²"]),
                 st.floats(allow_nan=True, allow_infinity=True).map(repr))


def _hostile_reader_case(tmp_path_factory, data, text: str, name: str, read):
    from arm_model import InputError
    path = tmp_path_factory.mktemp("r") / name
    path.write_text(_mutate_lines(text, data, cell_values=CELL), encoding="utf-8", errors="surrogateescape")
    try:
        return read(path)
    except InputError as exc:
        assert str(exc).startswith(str(path)), str(exc)
        return None


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_the_residuals_reader_returns_finite_plausible_vectors_or_says_where(tmp_path_factory, data):
    import numpy as np

    from viz.residuals import read_residuals
    text = "measurement,feature,x_mm,y_mm,z_mm,dx_um,dy_um,dz_um\n" + "".join(
        f"m{i % 2},f,{100 + i},{-20 + i},{300 - i},{1.5 * i},-2,{0.5 + i}\n" for i in range(6))
    res = _hostile_reader_case(tmp_path_factory, data, text, "residuals.csv", read_residuals)
    if res is not None:
        assert np.all(np.isfinite(res.vectors)) and np.all(np.abs(res.vectors) <= 1e3)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_the_table2_reader_returns_finite_plausible_errors_or_says_where(tmp_path_factory, data):
    import numpy as np

    from correction.paper import TABLE2_PATH, load_paper_table2
    table = _hostile_reader_case(tmp_path_factory, data, TABLE2_PATH.read_text(), "t2.csv", load_paper_table2)
    if table is not None:
        for v in table.columns.values():
            assert np.all(np.isfinite(v)) and np.all(np.abs(v) <= 1e3)



@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -1e308, 2e3])
def test_a_point_set_built_in_python_refuses_what_the_reader_refuses(bad):
    """A PointSet made in Python with a joint value the points reader would refuse (not finite, beyond the
    plausible +-1000 rad or m) is a ValueError naming the row and joint, not a number out of a fit."""
    import numpy as np

    from arm_model.io import PointSet
    ids, feats = np.array(["m", "m"]), np.array(["f", "f"])
    with pytest.raises(ValueError, match=r"joint 2 of row 2, line 7 is .*finite and within \+-1000"):
        PointSet("p.csv", ids, feats, np.array([[0.1, 0.2, 0.3], [0.1, bad, 0.3]]), lines=np.array([6, 7]))
    assert len(PointSet("p.csv", ids, feats, np.array([[0.1, 0.2, 0.3], [0.1, 999.0, -0.3]]))) == 2
