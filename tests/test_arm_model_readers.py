"""Readers: the formats of docs/formats.md exactly; bad input -> one clear error naming file, line, column."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from arm_model import InputError, parse_description
from arm_model.description import format_description
from arm_model.io import parse_artefacts, parse_points
from conftest import NOMINAL

HEADER = "measurement,feature," + ",".join(f"q{i}_deg" for i in range(1, 8)) + ",fx_N,fy_N,fz_N"


def row(meas="ring-01", feat="ring", q=(0,) * 7, f=(0.5, -0.2, 0.1)):
    return ",".join([meas, feat, *map(repr, map(float, q)), *map(repr, map(float, f))])


# --- description ------------------------------------------------------------------------------

def test_description_roundtrip_exact(nominal):
    assert parse_description(format_description(nominal)) == nominal


@pytest.mark.parametrize("edit, line_key", [
    (lambda t: t.replace("d_mm = 420.0", "d = 420.0"), "joint[3].d"),
    (lambda t: t.replace("d_mm = 420.0", "d_deg = 420.0"), "joint[3].d_deg"),
    (lambda t: t.replace("d_mm = 420.0", 'd_mm = "420"'), "joint[3].d_mm"),
    (lambda t: t.replace("d_mm = 420.0", "d_mm = nan"), "joint[3].d_mm"),
    (lambda t: t.replace("d_mm = 420.0\n", ""), "joint[3]"),
    (lambda t: t.replace("z_mm = 85.0", "z_mm = 0.0"), "probe.z_mm"),     # a compliant probe at the joint origin
    (lambda t: t.replace('convention = "dh"', 'convention = "xyz"'), "convention"),
    (lambda t: t.replace("ball_diameter_mm = 4.0\n", ""), "probe"),
])
def test_description_errors_name_line_and_key(edit, line_key):
    text = edit(NOMINAL.read_text())
    with pytest.raises(InputError) as exc:
        parse_description(text, "arm.toml")
    msg = str(exc.value)
    assert msg.startswith("arm.toml, line ") and line_key in msg, msg


def test_description_accepts_other_units():
    text = NOMINAL.read_text().replace("d_mm = 420.0", "d_m = 0.42").replace("alpha_deg = 90.0",
                                                                             "alpha_rad = 1.5707963267948966", 1)
    d = parse_description(text)
    assert d.joints[2].d == pytest.approx(0.42, abs=1e-15)
    assert d.joints[0].alpha == pytest.approx(math.pi / 2, abs=1e-15)


# --- points ---------------------------------------------------------------------------------

def test_points_read_units_to_si():
    text = HEADER + "\n" + row(q=(90, 0, 0, 0, 0, 0, 180)) + "\n"
    pts = parse_points(text, "p.csv", 7)
    assert pts.q[0, 0] == pytest.approx(math.pi / 2) and pts.q[0, 6] == pytest.approx(math.pi)
    assert pts.force_kind == "xyz" and pts.force.tolist() == [[0.5, -0.2, 0.1]]
    assert pts.lines.tolist() == [2]


def test_points_two_channel_sensor_sets_probe_y_to_zero():
    header = "measurement,feature," + ",".join(f"q{i}_rad" for i in range(1, 8)) + ",f_bend_N,f_axial_N,temperature_C"
    pts = parse_points(header + "\nm,ring,0,0,0,0,0,0,0,1.5,-0.3,20.5\n", "p.csv", 7)
    assert pts.force_kind == "two-channel"
    assert pts.force.tolist() == [[1.5, 0.0, -0.3]]
    assert pts.temperature.tolist() == [20.5]


def test_prismatic_joint_columns_are_lengths():
    """A prismatic joint's column is a length (q3_mm, q3_m, q3_um) read to metres; an angle there, or a
    length for a revolute joint, is refused naming the column; without the arm's kinds the unit decides."""
    kinds = ("angle", "angle", "length") + ("angle",) * 4
    text = HEADER.replace("q3_deg", "q3_mm") + "\n" + row(q=(90, 0, 250, 0, 0, 0, 0)) + "\n"
    pts = parse_points(text, "p.csv", kinds)
    assert pts.q[0, 2] == 0.25 and pts.q[0, 0] == pytest.approx(math.pi / 2)
    assert parse_points(text.replace("q3_mm", "q3_m").replace(",250.0,", ",0.25,"), "p.csv", kinds).q[0, 2] == 0.25
    with pytest.raises(InputError, match="prismatic: its column is a length") as exc:
        parse_points(HEADER + "\n" + row() + "\n", "p.csv", kinds)
    assert exc.value.column == "q3_deg" and exc.value.line == 1
    with pytest.raises(InputError, match="plausible length") as exc:
        parse_points(text.replace(",250.0,", ",1e7,"), "p.csv", kinds)
    assert exc.value.column == "q3_mm" and exc.value.line == 2
    assert parse_points(text, "p.csv", 7).q[0, 2] == 0.25
    with pytest.raises(InputError, match="angle .* or, for a prismatic joint, a length"):
        parse_points(HEADER.replace("q3_deg", "q3_N") + "\n" + row() + "\n", "p.csv", 7)


@pytest.mark.parametrize("text, line, column, words", [
    ("", 1, None, "empty"),
    (HEADER + "\n", 2, None, "no points"),
    (HEADER.replace("fz_N", "fz") + "\n" + row() + "\n", 1, "fz", "unit suffix"),
    (HEADER + "\n" + row() + "\n" + row().replace("0.5", "nan") + "\n", 3, "fx_N", "finite"),
    (HEADER + "\n" + row() + "\n" + row().replace("0.5", "inf") + "\n", 3, "fx_N", "finite"),
    (HEADER + "\n" + row().replace("0.5", "abc") + "\n", 2, "fx_N", "number"),
    (HEADER + "\n" + row().replace("0.5", "") + "\n", 2, "fx_N", "empty cell"),
    (HEADER.replace(",q7_deg", "") + "\n" + row()[: row().rindex(",0.0,0.5")] + ",0.5,-0.2,0.1\n", 1, "q6_deg",
     "arm has 7"),
    (HEADER + "\n" + row() + ",9\n", 2, None, "cells"),
    (HEADER.replace("measurement,", "id,") + "\n" + row() + "\n", 1, "measurement", "missing"),
    (HEADER.replace("q3_deg", "q3_mm") + "\n" + row() + "\n", 1, "q3_mm", "angle"),
])
def test_points_errors_name_line_and_column(text, line, column, words):
    with pytest.raises(InputError) as exc:
        parse_points(text, "pts.csv", ("angle",) * 7)
    e = exc.value
    assert e.path == "pts.csv" and e.line == line and e.column == column, str(e)
    assert words in str(e)


def test_unknown_feature_is_an_error_with_its_line():
    from arm_model.io import check_features
    pts = parse_points(HEADER + "\n" + row() + "\n" + row(feat="sphere-Z") + "\n", "pts.csv", 7)
    arts = parse_artefacts('[[feature]]\nid = "ring"\nkind = "ring"\ndiameter_mm = 174.996\n', "a.toml")
    with pytest.raises(InputError) as exc:
        check_features(pts, arts)
    assert exc.value.line == 3 and exc.value.column == "feature" and "sphere-Z" in str(exc.value)


def test_forces_over_range_are_flagged_not_dropped():
    pts = parse_points(HEADER + "\n" + row() + "\n" + row(f=(12.0, 6.0, 0.0)) + "\n", "p.csv", 7)
    assert len(pts) == 2 and pts.over_force(13.0).tolist() == [False, True]


# within the plausible ranges (docs/formats.md §1)
finite = st.floats(-1e4, 1e4, allow_nan=False, allow_infinity=False)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.text("abcXYZ-_0123456789", min_size=1, max_size=8),
                          st.lists(finite, min_size=10, max_size=10)), min_size=1, max_size=20))
def test_points_roundtrip_property(rows):
    lines = [HEADER] + [",".join([m, "f", *map(repr, v)]) for m, v in rows]
    pts = parse_points("\n".join(lines) + "\n", "p.csv", 7)
    vals = np.array([v for _, v in rows])
    np.testing.assert_allclose(pts.q, np.deg2rad(vals[:, :7]), rtol=1e-15, atol=0)
    np.testing.assert_array_equal(pts.force, vals[:, 7:])
    assert pts.measurement.tolist() == [m for m, _ in rows]


@settings(max_examples=40, deadline=None)       # 40: 2.4 -> 1.2 s of CPU; tests/test_reliability_properties.py fuzzes
@given(st.text(max_size=300))                   # the readers' cells too
def test_points_reader_never_crashes_on_garbage(text):
    """Any text either parses or raises InputError: never another exception."""
    try:
        parse_points(text, "g.csv", 7)
    except InputError:
        pass


@settings(max_examples=60, deadline=None)
@given(st.text(max_size=300))
def test_description_reader_never_crashes_on_garbage(text):
    try:
        parse_description(text, "g.toml")
    except InputError:
        pass


def test_artefacts_reader_spec_example():
    text = '''
[[feature]]
id = "ring"
kind = "ring"
diameter_mm = 174.996
u_diameter_mm = 0.00105
form_error_mm = 0.005

[[feature]]
id = "sphere-A"
kind = "sphere"
diameter_mm = 25.0

[[feature]]
id = "sphere-B"
kind = "sphere"
diameter_mm = 25.0

[[feature]]
id = "seat"
kind = "seat"

[[feature]]
id = "table"
kind = "plane"

[[distance]]
between = ["sphere-A", "sphere-B"]
length_mm = 600.004
u_length_mm = 0.0008
'''
    a = parse_artefacts(text, "a.toml")
    assert a.features["ring"].diameter == pytest.approx(0.174996, abs=1e-15)
    assert a.features["ring"].u_diameter == pytest.approx(1.05e-6, abs=1e-18)
    assert a.distances[0].length == pytest.approx(0.600004, abs=1e-15)
    bad = text.replace('between = ["sphere-A", "sphere-B"]', 'between = ["sphere-A", "sphere-C"]')
    with pytest.raises(InputError) as exc:
        parse_artefacts(bad, "a.toml")
    assert exc.value.line == 28 and "sphere-C" in str(exc.value)


def test_every_description_written_reads_back_or_is_not_written(nominal):
    """The writer and the reader share one rule: a probe whose z points back up the arm with its stylus
    length (the issue's `z_mm = -78.39`), a rigid tip (stylus 0) and a prismatic joint are written and read
    back; a joint origin beyond the reader's 1 km is a NumericalError naming it, never a file."""
    from dataclasses import replace

    from arm_model import NumericalError
    from arm_model.description import format_description, parse_description
    for probe in (dict(p_last=(0.0, 0.0, -0.07839), lever=0.07839), dict(p_last=(0.01, 0.0, 0.0), lever=0.0,
                  bending_compliance_x=0.0, bending_compliance_y=0.0, axial_compliance=0.0)):
        d = nominal.with_probe(**probe)
        assert parse_description(format_description(d)).probe == d.probe
    joints = list(nominal.joints)
    joints[2] = replace(joints[2], kind="prismatic", lower=-0.05, upper=0.25)
    d = replace(nominal, joints=tuple(joints))
    back = parse_description(format_description(d))
    assert back.joints[2].prismatic and back.joints[2].upper == pytest.approx(0.25, abs=1e-15)
    joints[2] = replace(joints[2], d=1500.0)
    with pytest.raises(NumericalError, match="joint 'j3'.*its d value"):
        format_description(replace(nominal, joints=tuple(joints)))
    with pytest.raises(NumericalError, match="no stylus"):
        format_description(nominal.with_probe(lever=0.0))


@settings(max_examples=40, deadline=None)
@given(st.lists(st.sampled_from(["a", "b", "m-10", "m-2", "Z"]), max_size=30))
def test_measurement_rows_are_each_measurements_rows_in_order(ids):
    """:meth:`PointSet.measurement_rows` (one sort) equals a pass over every row a measurement, in order of first
    appearance (:meth:`PointSet.measurements`)."""
    from arm_model.io import PointSet
    m = np.array(ids, dtype=object)
    pts = PointSet(None, m, m, np.zeros((len(m), 7)))
    got = pts.measurement_rows()
    assert list(got) == pts.measurements()
    for k, rows in got.items():
        np.testing.assert_array_equal(rows, np.flatnonzero(m == k))
