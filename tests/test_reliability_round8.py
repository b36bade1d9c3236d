"""Reliability, round 8: the leftovers of round 7 (control characters in a points file's ids, a calibration with
nothing free, reference options without reference points, a live stream with old Mac line ends, one mass bound)
and what a hostile-input audit of every subcommand found. Each test is named after what it checks; all are fast
(no fit beyond a few points)."""
from __future__ import annotations

import pytest

from conftest import NOMINAL, ROOT, exit_status

QCOLS = ",".join(f"q{k}_deg" for k in range(1, 8))
RING = ROOT / "examples" / "data" / "paper-ring-xyz"
SAMPLES = ROOT / "examples" / "live" / "samples.csv"


def _points(tmp_path, rows=("m,f,10,20,30,40,50,60,70",), name="p.csv", header=None):
    path = tmp_path / name
    path.write_text((header or f"measurement,feature,{QCOLS}") + "\n" + "".join(r + "\n" for r in rows))
    return path


@pytest.fixture(scope="module")
def ring_points(tmp_path_factory):
    """The first 40 points (one measurement) of the example ring campaign: enough for the readers, fast to load."""
    path = tmp_path_factory.mktemp("ring") / "points.csv"
    path.write_text("\n".join((RING / "points.csv").read_text().splitlines()[:41]) + "\n")
    return path


def _run(argv, capsys):
    rc = exit_status([str(a) for a in argv])
    return rc, capsys.readouterr().err


# ---------------------------------------------------------------------------------------------
# a points file's ids are one line of text, as every id the toolkit writes

@pytest.mark.parametrize("row, column, char", [
    ("m\x01,f,10,20,30,40,50,60,70", "measurement", "\\x01"),
    ("m,f\x7f,10,20,30,40,50,60,70", "feature", "\\x7f"),
    ("m,a\x1bb,10,20,30,40,50,60,70", "feature", "\\x1b"),
    ("m,a\u2028b,10,20,30,40,50,60,70", "feature", "\\u2028"),
    ('"m\tx",f,10,20,30,40,50,60,70', "measurement", "\\t"),
])
def test_a_control_character_in_a_points_id_is_refused_at_its_cell(tmp_path, capsys, row, column, char):
    """`m\\x01` or `f\\x7f` in a measurement or feature id was read and written back into tip's table (and into
    every file that carries the id); the live session and the artefacts reader refused the same ids. One rule
    (`arm_model.io.id_problem`), at the file, line and column."""
    pts = _points(tmp_path, ("m,f,1,2,3,4,5,6,7", row))
    out = tmp_path / "t.csv"
    rc, err = _run(["tip", pts, "--arm", "aacmm7", "-o", out], capsys)
    assert rc == 2 and f"p.csv, line 3, column '{column}'" in err and "without control characters" in err, err
    assert char in err and not out.exists()


def test_a_control_character_in_a_session_id_is_refused_too():
    from arm_model.errors import InputError
    from arm_model.io import parse_points
    with pytest.raises(InputError, match=r"line 2, column 'session'.*control characters"):
        parse_points(f"measurement,feature,session,{QCOLS}\nm,f,s\x00x,1,2,3,4,5,6,7\n".replace("\x00", "\x05"),
                     "p.csv")


# ---------------------------------------------------------------------------------------------
# calibrate: nothing free, reference options without reference points

def test_calibrate_with_every_parameter_held_is_refused(tmp_path, capsys, ring_points):
    """`calibrate --hold '*'` ran a fit of 0 parameters and wrote `aacmm7-calibrated.toml`, the nominal model
    under a calibrated name, with exit 0. Nothing left to estimate is bad input: exit 2, nothing written."""
    out = tmp_path / "o"
    rc, err = _run(["calibrate", ring_points, RING / "artefacts.toml", "--arm", "aacmm7", "--hold", "*",
                    "-o", out], capsys)
    assert rc == 2 and "nothing is left to estimate: --hold * holds every parameter" in err, err
    assert not out.exists()
    rc, err = _run(["calibrate", ring_points, RING / "artefacts.toml", "--arm", "aacmm7", "--free", "j1.d",
                    "--hold", "j*", "-o", out], capsys)
    assert rc == 2 and "every parameter of --free j1.d (1)" in err, err


@pytest.mark.parametrize("options, words", [
    (["--reference", "identity"], "--reference identity concerns the reference instrument's points"),
    (["--marker-offset", "fit"], "--marker-offset fit concerns"),
    (["--marker-offset", "zero", "--reference", "identity"], "--reference identity and --marker-offset zero concern"),
])
def test_reference_options_without_reference_points_are_refused(tmp_path, capsys, options, words, ring_points):
    """`--reference identity` and `--marker-offset fit` on data without a reference point were silently ignored."""
    out = tmp_path / "o"
    rc, err = _run(["calibrate", ring_points, RING / "artefacts.toml", "--arm", "aacmm7", *options,
                    "-o", out], capsys)
    assert rc == 2 and words in err and "the data hold none" in err, err
    assert not out.exists()


# ---------------------------------------------------------------------------------------------
# live: old Mac line ends, a header CSV cannot read

def _cr_stream(tmp_path):
    path = tmp_path / "cr.csv"
    path.write_bytes(b"\r".join(SAMPLES.read_bytes().splitlines()[:50]) + b"\r")
    return path


def test_live_a_stream_with_old_mac_line_ends_is_said_as_such(tmp_path, capsys):
    """A stream whose lines end with a carriage return alone ended in an internal error (exit 3: csv's "new-line
    character seen in unquoted field") instead of the readers' own words for old Mac line ends."""
    out = tmp_path / "s"
    rc, err = _run(["live", _cr_stream(tmp_path), "--arm", "aacmm7", "--speed", "0", "-o", out], capsys)
    assert rc == 2 and "cr.csv, line 1: a carriage return alone ends a line (old Mac line ends)" in err, err
    assert not out.exists()


def test_live_a_stream_source_says_old_mac_line_ends_without_waiting_for_a_megabyte(monkeypatch):
    """Standard input or TCP: a part of a line holding a carriage return alone is passed on at once (its reader says
    what it is), not kept until 1 MiB came without a line end."""
    import os
    import sys

    from arm_model.errors import InputError
    from arm_model.live.sources import line_text, open_source
    r, w = os.pipe()
    os.write(w, b"time_s,q1_deg\r0,1\r0.001,2\r")          # and the writer stays open: no end of stream
    with os.fdopen(r, "rb") as stdin:
        monkeypatch.setattr(sys, "stdin", stdin)
        src = open_source("-")
        try:
            for ticks, item in enumerate(src.lines()):            # an idle tick (None) every 0.25 s
                assert ticks < 8, "no line 2 s after a part holding carriage returns alone"
                if item is not None:
                    no, raw = item
                    break
            with pytest.raises(InputError, match="line 1: a carriage return alone ends a line"):
                line_text(raw, src.name, no)
        finally:
            os.close(w)


def test_live_a_header_csv_cannot_read_is_one_located_error(tmp_path, capsys):
    """A header cell beyond csv's field limit (131072 characters) was an internal error (exit 3)."""
    path = tmp_path / "h.csv"
    path.write_text("time_s,q1_deg," + "x" * 200_000 + "\n")
    rc, err = _run(["live", path, "--arm", "aacmm7", "--speed", "0", "-o", tmp_path / "s"], capsys)
    assert rc == 2 and "h.csv, line 1: the header is not valid CSV: field larger than field limit" in err, err


# ---------------------------------------------------------------------------------------------
# one plausible mass, said alike by every reader

@pytest.mark.parametrize("mass, words", [
    ("5e4", "50000 kg is not a plausible mass (|value| at most 10000 kg)"),
    ("2e6", "2e+06 kg is not a plausible mass (|value| at most 10000 kg)"),
    ("-1", "mass must not be negative, got -1 kg"),
])
def test_a_mass_beyond_the_plausible_bound_is_said_with_that_bound(tmp_path, capsys, mass, words):
    """The masses file refused 5e4 kg as "must be in [0, 10000] kg" and 2e6 kg as "at most 1e+06 kg" (the plausible
    range of every other reader): one bound, PLAUSIBLE_SI["mass"]."""
    masses = tmp_path / "m.toml"
    masses.write_text(f'[[link]]\nname = "link_1"\nmass_kg = {mass}\n')
    rc, err = _run(["tip", _points(tmp_path), "--arm", NOMINAL.with_suffix("").with_suffix(".urdf"), "--tip-frame",
                    "ball", "--masses", masses, "-o", tmp_path / "t.csv"], capsys)
    assert rc == 2 and "m.toml, line 3, key 'link[1].mass_kg'" in err and words in err, err


# ---------------------------------------------------------------------------------------------
# what the audit of every subcommand found

@pytest.mark.parametrize("old, new, key", [
    ('name = "aacmm7"', 'name = "a\\u0000b"', "key 'name'"),
    ('name = "j2"', 'name = "j\\n2"', "key 'joint[2].name'"),
])
def test_an_arm_or_joint_name_with_a_control_character_is_refused(tmp_path, capsys, old, new, key):
    """An arm named "a\\x00b" was read (its name goes into every model file, URDF and report, and names output files),
    and a joint named "j\\n2" too (it names parameters in every CSV table): the id rule of the other readers."""
    arm = tmp_path / "arm.toml"
    arm.write_text(NOMINAL.read_text().replace(old, new, 1))
    rc, err = _run(["tip", _points(tmp_path), "--arm", arm, "-o", tmp_path / "t.csv"], capsys)
    assert rc == 2 and "arm.toml, line" in err and key in err and "without control characters" in err, err


def test_a_urdf_joint_name_with_a_control_character_is_refused_at_its_line(tmp_path, capsys):
    """A URDF may write a line break into a name (`name="j&#10;2"`); the name then names parameters in the covariance
    CSV, whose reader refuses a cell spanning lines: refused when the URDF is read, at the joint's line."""
    urdf = NOMINAL.with_suffix("").with_suffix(".urdf").read_text()
    arm = tmp_path / "a.urdf"
    arm.write_text(urdf.replace('<joint name="j2" ', '<joint name="j&#10;2" '))
    rc, err = _run(["tip", _points(tmp_path), "--arm", arm, "--tip-frame", "ball", "-o", tmp_path / "t.csv"], capsys)
    assert rc == 2 and "a.urdf, line 11, key 'joint.name': a <joint> name must be one line of text" in err, err


def test_simulate_a_truth_the_workspace_cannot_hold_is_a_numerical_failure(tmp_path, capsys):
    """Random length errors of 1 km (within the plausible bound) made the ball bar's placement fail in LAPACK: the
    message was "key 'task[1]': Singular matrix", exit 2, as if the task were wrong. It is the arithmetic: exit 4,
    said with the task and what to check."""
    camp = tmp_path / "c.toml"
    camp.write_text('arm = "aacmm7"\nsensor = "none"\n[truth]\nlength_error_um = 1e9\n[[task]]\nkind = "ballbar"\n')
    rc, err = _run(["simulate", camp, "-o", tmp_path / "o"], capsys)
    assert rc == 4 and "numerical failure: task[1] (ballbar): placing it in the true arm's workspace failed" in err, err
    assert not (tmp_path / "o").exists()


def test_simulate_a_frame_key_on_a_description_arm_is_refused(tmp_path, capsys):
    """A campaign's `tip_frame = "ball"` on the shipped DH arm was silently ignored (`--tip-frame` on the same arm
    is refused by every command)."""
    camp = tmp_path / "c.toml"
    camp.write_text('arm = "aacmm7"\nsensor = "none"\ntip_frame = "ball"\n[[task]]\nkind = "seat"\n')
    rc, err = _run(["simulate", camp, "-o", tmp_path / "o"], capsys)
    assert rc == 2 and "c.toml, line 3, key 'tip_frame': 'tip_frame' is for an arm given as a URDF" in err, err


@pytest.mark.parametrize("command, option, words", [
    ("calibrate", ["--holdout", "ring-01,ring-02,ring-01"], "--holdout names ring-01 twice"),
    ("close-loop", ["--candidates", ""], "an empty argument"),      # every empty argument: round 9
    ("close-loop", ["--candidates", " , "], "--candidates names no family"),
    ("close-loop", ["--candidates", "thermal,thermal"], "--candidates names thermal twice"),
    ("close-loop", ["--hold", "*", "--max-effects", "0"], "nothing is left to estimate"),
])
def test_a_list_option_that_names_nothing_or_twice_is_refused(tmp_path, capsys, command, option, words, ring_points):
    """`close-loop --candidates ""` ran with the default families and `--candidates ,` with none; `--holdout a,b,a`
    was read as a, b; `close-loop --hold '*' --max-effects 0` wrote the nominal model as the loop's."""
    out = tmp_path / "o"
    rc, err = _run([command, ring_points, RING / "artefacts.toml", "--arm", "aacmm7", *option, "-o", out],
                   capsys)
    assert rc == 2 and words in err, err
    assert not out.exists()


_RESIDUALS = "measurement,feature,kind,line,residual_um,dx_um,dy_um,dz_um,standardized\n"


@pytest.mark.parametrize("row, column, words", [
    ("m,f,seat,2,nan,1,2,3,0.5", "residual_um", "expected a finite number, got 'nan'"),
    ("m,f,seat,2,1,1,2,3,inf", "standardized", "expected a finite number"),
    ("m\x01,f,seat,2,1,1,2,3,0.5", "measurement", "without control characters"),
    ("m,f,seat,99999999999999999999,1,1,2,3,0.5", "line", "expected a line number"),
])
def test_a_residuals_file_is_held_to_the_rules_of_every_reader(tmp_path, capsys, row, column, words):
    """`view --residuals`: a line number beyond a C long was an internal error (OverflowError, exit 3); `nan` in the
    residual or standardized columns (read and not used) and a control character in an id were accepted."""
    res = tmp_path / "r.csv"
    res.write_text(_RESIDUALS + row + "\n")
    out = tmp_path / "v.html"
    rc, err = _run(["view", _points(tmp_path), "--arm", "aacmm7", "--residuals", res, "--html", out], capsys)
    assert rc == 2 and f"r.csv, line 2, column '{column}'" in err and words in err, err
    assert not out.exists()


def test_live_an_empty_measurement_id_is_refused_not_replaced(tmp_path, capsys):
    """`live --measurement ""` named the session's points after the folder, as if the option were not given."""
    rc, err = _run(["live", SAMPLES, "--arm", "aacmm7", "--speed", "0", "--measurement", "", "-o", tmp_path / "s"],
                   capsys)
    assert rc == 2 and "an empty argument" in err, err         # every empty argument is refused (round 9)
    assert not (tmp_path / "s").exists()


def test_an_output_inside_an_input_folder_is_refused(tmp_path, capsys):
    """`ring --signals DIR -o DIR/out` wrote its report folder among the force signals it read."""
    from arm_model.errors import InputError
    from arm_model.output import guard_output
    signals = tmp_path / "signals"
    signals.mkdir()
    with pytest.raises(InputError, match="refusing to write the output into the input folder"):
        guard_output(signals / "out", [tmp_path / "p.csv"], [signals])
    assert guard_output(tmp_path / "out", [tmp_path / "p.csv"], [signals]) == tmp_path / "out"
    assert guard_output(tmp_path / "out.csv", [tmp_path]) == tmp_path / "out.csv"     # beside an input file: fine


@pytest.mark.parametrize("edit, words", [
    (lambda rows: rows[:1] + ["\x01" + rows[1]] + rows[2:], "the measurement id must be one line of text"),
    (lambda rows: rows[:2] + [rows[1]] + rows[2:], "is given twice (one row a measurement)"),
])
def test_paper_table_ids_are_one_line_and_each_once(tmp_path, capsys, edit, words):
    """`paper --table2`: a control character in a measurement id went into the report's figures (matplotlib's
    "Glyph 1 missing" warning) and a measurement given twice was counted twice in the correlations."""
    text = (ROOT / "correction" / "data" / "paper_table2.csv").read_text().splitlines()
    head = next(i for i, line in enumerate(text) if line and not line.startswith("#"))
    table = tmp_path / "t2.csv"
    table.write_text("\n".join(text[:head] + edit(text[head:])) + "\n")
    rc, err = _run(["paper", "--table2", table, "-o", tmp_path / "o"], capsys)
    assert rc == 2 and "t2.csv, line" in err and "column 'measurement'" in err and words in err, err
    assert not (tmp_path / "o").exists()


def test_close_loop_on_one_pose_says_so_without_asking_for_an_impossible_fold_count(tmp_path, capsys):
    """A points file of one row: "--folds 4: the data hold 1 poses ... ask for at most 1 folds", while --folds must
    be at least 2."""
    rows = (RING / "points.csv").read_text().splitlines()[:2]
    pts = tmp_path / "p.csv"
    pts.write_text("\n".join(rows) + "\n")
    rc, err = _run(["close-loop", pts, RING / "artefacts.toml", "--arm", "aacmm7", "-o", tmp_path / "o"], capsys)
    assert rc == 2 and "p.csv: the data hold 1 pose (points on a feature and reference points)" in err, err
    assert "at most 1 folds" not in err and not (tmp_path / "o").exists()


@pytest.mark.parametrize("argv, option", [
    (["tip", "p.csv", "--arm", "aacmm7", "--arm", "a.toml", "-o", "t.csv"], "--arm"),
    (["live", "s.csv", "--arm", "aacmm7", "--feature", "seat:a", "--feature", "seat:b", "-o", "s"], "--feature"),
    (["calibrate", "p.csv", "a.toml", "--arm", "aacmm7", "--covariance-scale", "stated", "--covariance", "residual",
      "-o", "o"], "--covariance-scale/--covariance"),
])
def test_an_option_of_one_value_given_twice_is_refused(capsys, argv, option):
    """`--arm a --arm b` ran with b, `live --feature seat:a --feature seat:b` planned seat b alone: argparse's last
    value won without a word. An option that takes one value is refused when given twice (repeatable options, such
    as --free or --hold-joint, append)."""
    rc, err = _run(argv, capsys)
    assert rc == 2 and f"argument {option}: given twice" in err, err


def test_repeatable_options_still_repeat():
    from arm_model.cli import build_parser
    argv = ["calibrate", "p.csv", "a.toml", "--arm", "aacmm7", "--free", "j1.*", "--free", "j2.*", "-o", "o"]
    assert build_parser(argv).parse_args(argv).free == ["j1.*", "j2.*"]


def test_an_id_longer_than_the_limit_is_refused_and_not_reprinted(tmp_path, capsys):
    """A 2 MB measurement id (a payload, not a name: it was read and would be repeated on every row and message)
    is refused at its cell, exit 2, and the message quotes the start of it, not all of it."""
    from arm_model.errors import MAX_ID_LENGTH
    pts = _points(tmp_path, ("m,f,1,2,3,4,5,6,7", "m" * 2_000_000 + ",f,10,20,30,40,50,60,70"))
    out = tmp_path / "t.csv"
    rc, err = _run(["tip", pts, "--arm", "aacmm7", "-o", out], capsys)
    assert rc == 2 and f"at most {MAX_ID_LENGTH} characters" in err and len(err) < 2000, err[:500]
    assert "p.csv, line 3, column 'measurement'" in err and not out.exists()
