"""The fast CSV reader and writer: same results as the cell-by-cell reader, every bad cell located,
blocks of any size, strict numbers; the vectorised writer equals Python's % formatting."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import example, given, settings, strategies as st

from arm_model import InputError
from arm_model.csv_io import _slow_block, format_csv, iter_csv_blocks, parse_number
from arm_model.io import iter_points, parse_points, read_force_signal

Q = ",".join(f"q{i}_deg" for i in range(1, 8))
HEADER = f"measurement,feature,{Q},fx_N,fy_N,fz_N"


def body(n: int, seed: int = 0) -> str:
    rng = np.random.default_rng(seed)
    rows = []
    for i in range(n):
        v = rng.normal(0, 100, 10)
        rows.append(",".join([f"m{i % 7}", "ring" if i % 3 else "", *(repr(float(x)) for x in v)]))
    return "\n".join(rows) + "\n"


def test_blocks_of_any_size_give_the_same_points():
    text = HEADER + "\n" + body(500)
    whole = parse_points(text, "p.csv", 7)
    for size in (64, 1000, 4096):
        parts = list(iter_points("p.csv", 7, data=text.encode(), block_bytes=size))
        assert len(parts) > 1
        q = np.vstack([p.q for p in parts])
        np.testing.assert_array_equal(q, whole.q)
        assert np.concatenate([p.lines for p in parts]).tolist() == list(range(2, 502))
        assert np.concatenate([p.measurement for p in parts]).tolist() == whole.measurement.tolist()


def test_fast_and_careful_readers_agree():
    """A quoted cell sends a block to the careful reader: same values, same lines."""
    text = HEADER + "\n" + body(50)
    fast = parse_points(text, "p.csv", 7)
    slow = parse_points(text.replace("m3,", '"m3",'), "p.csv", 7)
    np.testing.assert_array_equal(fast.q, slow.q)
    np.testing.assert_array_equal(fast.force, slow.force)
    assert fast.measurement.tolist() == slow.measurement.tolist() and fast.lines.tolist() == slow.lines.tolist()


def test_blank_lines_crlf_and_bom_keep_the_physical_line_numbers():
    rows = body(6).splitlines()
    text = "\ufeff" + HEADER + "\r\n\r\n" + "\r\n".join(rows[:3]) + "\r\n\r\n" + "\r\n".join(rows[3:]) + "\r\n"
    pts = parse_points(text, "p.csv", 7)
    assert pts.lines.tolist() == [3, 4, 5, 7, 8, 9]
    bad = text.replace(rows[4].split(",")[5], "x", 1)
    with pytest.raises(InputError) as exc:
        parse_points(bad, "p.csv", 7)
    assert exc.value.line == 8 and exc.value.column == "q4_deg"


@pytest.mark.parametrize("cell", ["4_5", "0x10", "1,5", "١٢", "1e", "--1", "1.2.3", "1 2"])
def test_strict_numbers_are_refused_with_their_place(cell):
    rows = body(40).splitlines()
    cells = rows[30].split(",")
    cells[9] = cell                                    # fx_N
    rows[30] = ",".join(cells)
    text = HEADER + "\n" + "\n".join(rows) + "\n"
    with pytest.raises(InputError) as exc:
        parse_points(text, "p.csv", 7)
    e = exc.value
    assert e.line == 32, str(e)
    if cell != "1,5":
        assert e.column == HEADER.split(",")[9] and "number" in str(e), str(e)


def test_python_float_would_have_read_underscores():
    assert float("4_5") == 45.0 and parse_number("4_5") is None and parse_number("-4.5e-3") == -4.5e-3


@pytest.mark.parametrize("header, column, words", [
    (HEADER.replace("q1_deg", "q1_deg,q1_rad"), "q1_rad", "same quantity"),
    (HEADER + ",temperature_C,temperature_m", "temperature_m", "must be a temperature"),
    (HEADER + ",x_ref_mm,y_ref_mm,z_ref_mm,x_ref_m", "x_ref_m", "same quantity"),
    (HEADER + ",operator", "operator", "unknown column"),
    (HEADER + ",pressure_N", "pressure_N", "unknown column"),
])
def test_header_refuses_unknown_and_duplicate_meanings(header, column, words):
    n = header.count(",") + 1
    text = header + "\n" + ",".join(["m", "f"] + ["0"] * (n - 2)) + "\n"
    with pytest.raises(InputError) as exc:
        parse_points(text, "p.csv", 7)
    assert exc.value.line == 1 and exc.value.column == column and words in str(exc.value), str(exc.value)


def test_every_bad_value_in_a_late_block_is_located():
    rows = body(300).splitlines()
    for k, (bad, words) in enumerate([("nan", "finite"), ("", "empty cell"), ("abc", "number")]):
        r = list(rows)
        cells = r[250 + k].split(",")
        cells[11] = bad
        r[250 + k] = ",".join(cells)
        with pytest.raises(InputError) as exc:
            list(iter_points("p.csv", 7, data=(HEADER + "\n" + "\n".join(r) + "\n").encode(), block_bytes=2048))
        assert exc.value.line == 252 + k and exc.value.column == "fz_N" and words in str(exc.value), str(exc.value)


finite = st.floats(-1e9, 1e9, allow_nan=False, allow_infinity=False)
plausible = st.floats(-1e4, 1e4, allow_nan=False, allow_infinity=False)    # joint angles [deg], forces [N]


def csv_numbers(text: str) -> np.ndarray:
    """The numbers of a points-like CSV text as the CSV layer reads them (fast path, then the careful
    one), before the points reader's checks of finiteness and plausible range."""
    blocks = iter_csv_blocks("p.csv", "the points file", lambda h, line: (list(range(2, len(h))), [0, 1]),
                             data=text.encode())
    return np.concatenate([b.numbers for _, _, b in blocks])


@settings(max_examples=40, deadline=None)
@given(st.lists(st.lists(finite, min_size=10, max_size=10), min_size=1, max_size=30),
       st.sampled_from(["r", "e", "f"]))
def test_fast_reader_equals_the_careful_one(rows, style):
    fmt = {"r": repr, "e": lambda v: f"{v:.17e}", "f": lambda v: f"{v:.6f}"}[style]
    text = "\n".join(",".join(["m", "f", *map(fmt, r)]) for r in rows) + "\n"
    header = HEADER.split(",")
    fast = csv_numbers(HEADER + "\n" + text)
    slow = _slow_block(text, "p.csv", 2, header, list(range(2, 12)), [0, 1])
    np.testing.assert_array_equal(fast, slow.numbers)


HALVES = [0.125, 2.675, 1.005, 0.5, 1.5, 2.5, -0.5, -2.5, 703688.3466426451, 1e-7, -4e-7, 0.0, -0.0]


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-1e7, 1e7, allow_nan=False), min_size=0, max_size=40), st.integers(0, 9))
@example(HALVES, 0)
@example(HALVES, 1)
@example(HALVES, 2)
@example(HALVES, 8)
def test_vectorised_fixed_format_equals_python(values, decimals):
    v = np.array(values, dtype=float)
    got = format_csv({"a_mm": v, "n": np.arange(len(v)),
                      "t": np.array(["x,y", 'q"', "plain"] * 14, dtype=object)[: len(v)]},
                     fmt=f"%.{decimals}f", header=False).decode()
    import csv
    import io
    want = io.StringIO()
    w = csv.writer(want, lineterminator="\n")
    for i, x in enumerate(v):
        s = f"%.{decimals}f" % x
        if s.startswith("-") and float(s) == 0:
            s = s[1:]                                   # no "-0.000": a zero has no sign
        w.writerow([s, i, ["x,y", 'q"', "plain"][i % 3]])
    assert got == want.getvalue()


def test_force_signal_fast_and_located(tmp_path):
    t = np.arange(2000) * 1e-3
    f = np.column_stack([np.sin(t), np.cos(t), t])
    p = tmp_path / "m.csv"
    p.write_bytes(format_csv({"time_s": t, "fx_N": f[:, 0], "fy_N": f[:, 1], "fz_N": f[:, 2]}, fmt="%.9f"))
    sig = read_force_signal(p)
    np.testing.assert_allclose(sig.force, f, atol=5e-10) and np.testing.assert_allclose(sig.time, t, atol=5e-10)
    lines = p.read_text().splitlines()
    lines[1500] = lines[1500].replace(lines[1500].split(",")[2], "1_0")
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError) as exc:
        read_force_signal(p)
    assert exc.value.line == 1501 and exc.value.column == "fy_N"



@pytest.mark.parametrize("header, bad", [("time_s,fx_N,fy_N,fz_N,temperature_C", "temperature_C"),
                                         ("time_s,f_bend_N,f_axial_N,fz_N", "fz_N"),
                                         ("time_s,fx_N,fy_N,fz_N,f_bend_N,f_axial_N", "f_bend_N")])
def test_force_signal_unknown_column_is_an_error_naming_it(tmp_path, header, bad):
    p = tmp_path / "m.csv"
    n = header.count(",") + 1
    p.write_text(header + "\n" + ",".join(["0"] * n) + "\n" + ",".join(["0.001"] * n) + "\n")
    with pytest.raises(InputError) as exc:
        read_force_signal(p)
    assert exc.value.line == 1 and exc.value.column == bad and "unknown column" in str(exc.value)

# the fast block reader (cell count checked from the comma positions, text cells decoded once per run)
# against the cell-by-cell reader: whatever the fast path accepts, the careful one reads the same;
# whatever the careful one refuses, the fast path hands over (returns None)
_ids = st.text(st.sampled_from("ab 1-_é,"), min_size=0, max_size=6)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(_ids, _ids, st.lists(finite, min_size=2, max_size=2)), min_size=1, max_size=25),
       st.lists(st.sampled_from(["", "\r", " ", "x", ",", ",,"]), min_size=1, max_size=25),
       st.sampled_from(["\n", "\r\n"]))
def test_fast_block_agrees_with_the_careful_reader(rows, extras, eol):
    from arm_model.csv_io import _fast_block
    header = ["measurement", "feature", "a_mm", "b_mm"]
    lines = []
    for (m, f, v), extra in zip(rows, extras * len(rows), strict=False):   # extras repeated to cover the rows
        lines.append(",".join([m, f, *map(repr, v)]))
        if extra in ("", "\r"):
            lines.append(extra)                       # a blank line (kept out of the rows)
        elif extra in (",", ",,"):
            lines[-1] += extra                        # a wrong cell count
    text = eol.join(lines) + eol
    try:
        slow = _slow_block(text, "p.csv", 2, header, [2, 3], [0, 1])
    except InputError:
        slow = None
    fast = _fast_block(text.encode(), text, "p.csv", 2, header, [2, 3], [0, 1])
    if slow is None:
        assert fast is None
    elif fast is not None:
        assert fast.lines.tolist() == slow.lines.tolist()
        np.testing.assert_array_equal(fast.numbers, slow.numbers)
        assert fast.texts.tolist() == slow.texts.tolist()


def test_wrong_cell_count_deep_in_a_block_is_located():
    rows = body(2000).splitlines()
    for k, (cells, words) in enumerate([(11, "11 cells"), (13, "13 cells")]):
        r = list(rows)
        c = r[1500 + k].split(",")
        r[1500 + k] = ",".join(c[:11] if cells == 11 else c + ["0"])
        with pytest.raises(InputError) as exc:
            parse_points(HEADER + "\n" + "\n".join(r) + "\n", "p.csv", 7)
        assert exc.value.line == 1502 + k and words in str(exc.value), str(exc.value)


@settings(max_examples=30, deadline=None)
@given(st.lists(st.tuples(_ids.filter(lambda s: s.strip()), st.lists(plausible, min_size=10, max_size=10)),
                min_size=1, max_size=40), st.integers(1, 9))
def test_points_written_and_read_back(rows, chunk):
    """format_csv then the points reader: the same text cells, the numbers to the written decimals."""
    ids = np.array([m.strip() for m, _ in rows], dtype=object)
    v = np.array([x for _, x in rows])
    names = [f"q{i}_deg" for i in range(1, 8)] + ["fx_N", "fy_N", "fz_N"]
    cols = {"measurement": ids, "feature": np.full(len(ids), "ring", dtype=object),
            **{k: v[:, j] for j, k in enumerate(names)}}
    text = format_csv(cols, "%.6f", chunk=chunk)
    assert text == format_csv(cols, "%.6f")           # chunk boundaries change nothing
    pts = parse_points(text.decode(), "p.csv", 7)
    assert pts.measurement.tolist() == ids.tolist() and pts.lines.tolist() == list(range(2, len(ids) + 2))
    # half a unit of the 6th decimal, plus a few ulps (the decimal text read back, deg -> rad -> deg)
    assert np.all(np.abs(np.rad2deg(pts.q) - v[:, :7]) <= 5e-7 + 1e-15 * np.abs(v[:, :7]))
    assert np.all(np.abs(pts.force - v[:, 7:]) <= 5e-7 + 1e-15 * np.abs(v[:, 7:]))


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(-9e8, 9e8, allow_nan=False), min_size=1, max_size=300), st.sampled_from([0, 3, 6]))
def test_fixed_format_of_large_values_equals_python(values, decimals):
    """Values whose scaled product is near 2**53 (many within an ulp of a half): exact either way."""
    v = np.array(values)
    got = format_csv({"a": v}, f"%.{decimals}f", header=False).decode().splitlines()
    want = [(f"%.{decimals}f" % x).replace("-0." + "0" * decimals, "0." + "0" * decimals) if decimals
            else ("%.0f" % x if "%.0f" % x != "-0" else "0") for x in v]  # noqa: UP031 (printf: the reference)
    assert got == want


def test_joint_limit_tally_of_blocks_equals_the_whole(nominal):
    from arm_model.checks import JointLimitTally, joint_limit_warning
    desc = nominal
    rng = np.random.default_rng(3)
    q = np.deg2rad(rng.uniform(-175, 175, (1000, 7)))
    lines = np.arange(2, 1002)
    whole = joint_limit_warning(desc, q, lines, "p.csv")
    tally = JointLimitTally(desc, "p.csv")
    for a in range(0, 1000, 137):
        tally.add(q[a:a + 137], lines[a:a + 137])
    assert tally.warning() == whole
    # hand count: j2 is limited to +-150 deg
    assert f"j2 ({int(np.sum(np.abs(np.rad2deg(q[:, 1])) > 150))}," in whole.message
    assert JointLimitTally(desc, "p.csv").warning() is None


# the plain decimals [+-]?[0-9]{0,10}\.?[0-9]{0,9} with a digit, built from their parts (st.from_regex drew the
# same language at 2.5x the CPU: 6.5 s of the test's 60 examples)
_digits = "0123456789"
_plain = st.builds(lambda sign, whole, dot, frac: sign + whole + dot + frac, st.sampled_from(["", "+", "-"]),
                   st.text(_digits, max_size=10), st.sampled_from(["", "."]),
                   st.text(_digits, max_size=9)).filter(lambda s: any(c.isdigit() for c in s))
_other = st.sampled_from(["1e3", "-2.5E-4", " 7.25", "nan", "inf", "12345678901234567.5", "9007199254740993"])


@settings(max_examples=60, deadline=None)
@given(st.lists(st.lists(_plain, min_size=10, max_size=10), min_size=1, max_size=60),
       st.lists(st.tuples(st.integers(0, 59), st.integers(0, 9), _other), max_size=3))
def test_plain_decimals_equal_python_float(rows, others):
    """The vectorised reading of plain decimals (and the few other cells among them, read one by one)
    gives exactly Python's float of each cell."""
    for r, c, cell in others:
        if r < len(rows):
            rows[r][c] = cell
    text = HEADER + "\n" + "\n".join(",".join(["m", "f", *r]) for r in rows) + "\n"
    got = csv_numbers(text)
    want = np.array([[float(c) for c in r] for r in rows])
    np.testing.assert_array_equal(got, want)
    assert all(math.copysign(1, a) == math.copysign(1, b) for a, b in zip(got.ravel(), want.ravel(), strict=True))


@pytest.mark.parametrize("cell", ["9007199254740992", "9007199254740993", "900719925474099.3", "0.9007199254740993",
                                  "-0.0", "+.5", "5.", "0000000000000000001.25", "1234567890.123456789",
                                  "0.1", "2.675", "-123456.7890123"])
def test_plain_decimal_edge_cases_equal_python_float(cell):
    rows = [r.split(",") for r in body(50).splitlines()]
    rows = [",".join(r[:2] + [f"{float(c):.6f}" for c in r[2:]]) for r in rows]     # plain decimals
    cells = rows[20].split(",")
    cells[9] = cell                                    # fx_N
    rows[20] = ",".join(cells)
    got = csv_numbers(HEADER + "\n" + "\n".join(rows) + "\n")[20, 7]
    assert got == float(cell) and math.copysign(1, got) == math.copysign(1, float(cell))


def test_a_line_of_empty_cells_is_blank_in_every_reader():
    rows = [r.split(",") for r in body(30).splitlines()]
    rows = [",".join(r[:2] + [f"{float(c):.4f}" for c in r[2:]]) for r in rows]
    rows.insert(10, "," * 11)
    pts = parse_points(HEADER + "\n" + "\n".join(rows) + "\n", "p.csv", 7)
    assert len(pts) == 30 and 12 not in pts.lines.tolist() and pts.lines[10] == 13
