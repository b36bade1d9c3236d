"""Reliability, round 11: what a hostile-input audit of every subcommand found after round 10 (each test named after
its finding; all fast: no fit, a few points). The audit's driver fed TOML files with 64-bit-overflowing integers,
dates, mixed arrays and nested inline tables; CSV files with Unicode line and paragraph separators, NEL, non-breaking
and other Unicode spaces, BOM, CRLF, UTF-16; URDFs as shipped by others (xacro leftovers, package:// meshes, mimic,
floating, planar and prismatic joints, two roots, zero and non-unit axes, 1e308 angles); hand-edited model and
covariance files; live streams over TCP and UDP (silent clients, 100 MB lines, resets, NaN, out-of-order and
duplicated samples); outputs on a full and a read-only file system, through links, hard links and `..`; Ctrl-C at
every instant of the start-up; 10^6-row inputs; and every numeric option with nan, inf, 1e308, 1e-320, -1, 0 and a
400-digit integer."""
from __future__ import annotations

import pytest
from test_reliability_round10 import PANDA, _panda

from arm_model import InputError
from arm_model.csv_io import SPACE
from arm_model.errors import text_lines
from conftest import ROOT, exit_status

RING = ROOT / "examples" / "data" / "paper-ring-xyz"
SAMPLES = ROOT / "examples" / "live" / "samples.csv"
HUGE = "1" + "0" * 400


def _run(argv, capsys):
    rc = exit_status([str(a) for a in argv])
    return rc, capsys.readouterr().err


# ---------------------------------------------------------------------------------------------
# a TOML integer beyond 64 bits

@pytest.mark.parametrize("text, key, line", [
    (f"a = 1\n[t]\nd_mm = {HUGE}\n", "t.d_mm", 3),
    (f"[[feature]]\nid = 'x'\n[[feature]]\nid = 'y'\nlength_mm = -{HUGE}\n", "feature[2].length_mm", 5),
    (f"centre_mm = [1.0, {2 ** 63}, 3.0]\n", "centre_mm[2]", 1),
    (f"feature = [\n  {{ id = 'a', points = {HUGE} }},\n]\n", "feature[1].points", 2)])
def test_a_toml_integer_beyond_64_bits_is_refused_at_its_key(text, key, line):
    """A 400-digit integer (or 2**63) where a number is expected was taken by Python's TOML reader and then met
    float() as an OverflowError: exit 3 (an internal error) in the arm description, the artefacts, the campaign,
    the plan and the masses file. TOML 1.0 says such an integer is an error: now exit 2 at its line and key, for
    every TOML reader (errors.parse_toml)."""
    import re

    from arm_model.errors import parse_toml
    with pytest.raises(InputError, match=rf"f.toml, line {line}, key '{re.escape(key)}': not valid TOML: an integer "
                                         r"beyond 64 bits"):
        parse_toml(text, "f.toml")
    assert parse_toml(f"a = {2 ** 63 - 1}\nb = {-2 ** 63}\n", "f.toml") == {"a": 2 ** 63 - 1, "b": -2 ** 63}


def test_a_huge_integer_in_an_artefacts_file_is_exit_2(tmp_path, capsys):
    art = tmp_path / "a.toml"
    art.write_text((RING / "artefacts.toml").read_text().replace("diameter_mm = 174.996", f"diameter_mm = {HUGE}"))
    rc, err = _run(["ring", RING / "points.csv", art, "--arm", "aacmm7", "--no-plots", "-o", tmp_path / "o"], capsys)
    assert rc == 2 and "a.toml, line 5, key 'feature[1].diameter_mm': not valid TOML: an integer beyond" in err, err
    assert not (tmp_path / "o").exists()


# ---------------------------------------------------------------------------------------------
# lines are ended by a line feed only: Unicode's other line boundaries split no row

@pytest.mark.parametrize("mark", ["\x0b", "\x0c", "\x1c", "\x1d", "\x1e", "\x85", "\u2028", "\u2029"])
def test_a_unicode_line_boundary_does_not_split_a_row(tmp_path, capsys, mark):
    """Python's splitlines() ends a line at eight more characters than a line feed (VT, FF, FS, GS, RS, NEL and the
    Unicode line and paragraph separators). The CSV readers' cell-by-cell path split rows there, their fast path
    did not: a points file with NEL after a number was read (exit 0), the same file with a quoted cell later in the
    block was refused at a wrong row ("3 cells where the header has 14 columns"), and every line after such a row
    was named one line too far. Now one rule (errors.text_lines): a line ends at LF (or CRLF); the error names the
    line a text editor shows (and the cell the character pads)."""
    rows = (RING / "points.csv").read_text().splitlines()[:5]
    r2 = rows[2].split(",")
    r2[1] = '"ring"'                        # a quoted cell: the block goes cell by cell
    r3 = rows[3].split(",")
    r3[3] = "abc"
    pts = tmp_path / "p.csv"
    pts.write_text("\n".join([rows[0], rows[1] + mark, ",".join(r2), ",".join(r3), rows[4]]) + "\n",
                   encoding="utf-8", newline="")
    rc, err = _run(["tip", pts, "--arm", "aacmm7", "-o", tmp_path / "t.csv"], capsys)
    last = rows[1].rsplit(",", 1)[1] + mark
    if mark in SPACE:           # VT and FF: ASCII white space around a number
        assert rc == 2 and "p.csv, line 4, column 'q2_deg': expected a number, got 'abc'" in err, err
    else:                       # a number padded with any other: refused since round 11 (below)
        assert rc == 2 and f"p.csv, line 2, column 'time_s': expected a number, got {last!r}" in err, err
    assert text_lines(f"a{mark}b\r\nc\n\nd") == [f"a{mark}b", "c", "", "d"]


# ---------------------------------------------------------------------------------------------
# Ctrl-C while the command line itself is imported

def test_ctrl_c_while_the_command_line_is_imported_is_one_line(tmp_path):
    """Ctrl-C in the first ~10-150 ms of `aacmm` (`timeout -s INT 0.05 aacmm ...`: while the console script imported
    arm_model.cli, before its main() could catch anything) printed a Python traceback ending in KeyboardInterrupt,
    exit 1. The entry point (arm_model.launch:main) now takes Ctrl-C before it imports anything of the toolkit: one
    line, exit 130. Here SIGINT arrives exactly while arm_model.cli is being imported."""
    import subprocess
    import sys
    code = ("import importlib.abc, os, signal, sys, time\n"
            "class Interrupt(importlib.abc.MetaPathFinder):\n"
            "    def find_spec(self, name, path, target=None):\n"
            "        if name == 'arm_model.cli':\n"
            "            os.kill(os.getpid(), signal.SIGINT)\n"
            "            time.sleep(2)\n"
            "        return None\n"
            "sys.meta_path.insert(0, Interrupt())\n"
            "from arm_model.launch import main\n"
            "sys.argv = ['aacmm', 'paper', '-o', 'out']\n"
            "sys.exit(main())\n")
    run = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=60)
    assert (run.returncode, run.stderr) == (130, "aacmm: error: interrupted; nothing written\n"), run
    assert not (tmp_path / "out").exists()
    from importlib.metadata import entry_points
    assert [e.value for e in entry_points(group="console_scripts", name="aacmm")] == ["arm_model.launch:main"]


# ---------------------------------------------------------------------------------------------
# URDFs as others ship them

SEATS = ROOT / "examples" / "data" / "real-panda-seats" / "front" / "points.csv"


def test_a_urdf_with_two_roots_is_refused(tmp_path, capsys):
    """A URDF whose links hang from two roots (a joint's parent made a link no joint leads to) was read: `urdf` wrote
    a 4-joint arm from the 7-joint Panda, `tip` then counted the points' columns against it. urdfdom (Pinocchio's and
    ROS's parser) refuses the file ("Two root links found"): now exit 2 naming both roots and their lines."""
    urdf = _panda(tmp_path, '<parent link="panda_link3" />\n    <child link="panda_link4" />',
                  '<parent link="orphan" />\n    <child link="panda_link4" />')
    urdf.write_text(urdf.read_text().replace("</robot>", '<link name="orphan"/>\n</robot>'))
    rc, err = _run(["urdf", urdf, "--tip-frame", "ball_link", "-o", tmp_path / "o.urdf"], capsys)
    line = urdf.read_text().splitlines().index('<link name="orphan"/>') + 1
    words = f"m.urdf, line {line}: two root links, 'panda_link0' (line 3) and 'orphan' (line {line})"
    assert rc == 2 and words in err, err
    assert not (tmp_path / "o.urdf").exists()


def test_an_island_link_is_a_second_root(tmp_path, capsys):
    """A link no joint reaches (an island) made the same two-roots file; it was read when the tip frame was
    elsewhere."""
    urdf = _panda(tmp_path, "</robot>", '<link name="island"/>\n</robot>')
    rc, err = _run(["tip", SEATS, "--arm", urdf, "--tip-frame", "ball_link", "-o", tmp_path / "t.csv"], capsys)
    assert rc == 2 and "two root links, 'panda_link0' (line 3) and 'island'" in err, err


# ---------------------------------------------------------------------------------------------
# a full disk names where the output would have been, never a temporary name

def _full_disk(monkeypatch, module, name, after=0):
    """``module.name`` (a write) fails with ENOSPC from its ``after``-th call on, naming its arguments as the system
    does (a copy names its source and its destination)."""
    import errno
    calls = []
    real = getattr(module, name)

    def full(*args, **kwargs):
        calls.append(args)
        if len(calls) > after:
            names = [str(a) for a in args[:2]]
            raise OSError(errno.ENOSPC, "No space left on device", names[0], None, *names[1:])
        return real(*args, **kwargs)
    monkeypatch.setattr(module, name, full)


def test_a_page_written_into_an_output_file_on_a_full_disk_names_the_page(tmp_path, monkeypatch):
    """`aacmm view --html /full/v.html` said "/full/.v.html.tmp-x5x81odc.html: cannot write the output file: No space
    left on device": the page is written by a second atomic write into the first one's temporary file (view.write_html
    in an output_file block), whose error named that temporary file. Now the page's own name (output_file turns an
    error naming its temporary file into one naming the output, as output_folder does for its files). (The view
    itself takes 7 s to start: the mechanism is tested here, as view uses it.)"""
    import pathlib

    from arm_model.io import atomic_write_text
    from arm_model.output import output_file
    _full_disk(monkeypatch, pathlib.Path, "write_bytes")
    page = tmp_path / "v.html"
    with pytest.raises(InputError) as info, output_file(page, writes=".html") as tmp:
        atomic_write_text(tmp, "<html></html>")
    assert str(info.value) == f"{page}: cannot write the output file: No space left on device; nothing written"
    assert list(tmp_path.iterdir()) == []


def test_examples_on_a_full_disk_names_the_file(tmp_path, capsys, monkeypatch):
    """`aacmm examples /full/ex` said "<the toolkit's own examples/...>/points.csv, /full/ex/.examples.tmp-j185w3ye/
    data/.../points.csv: No space left on device": the source and a temporary name. Now the file where it would
    have been written; nothing is left (the folder it would have created included)."""
    import shutil
    _full_disk(monkeypatch, shutil, "copy2", after=3)
    dest = tmp_path / "ex"
    rc, err = _run(["examples", dest], capsys)
    assert rc == 2 and f"error: {dest}/" in err and "cannot write the examples: No space left on device; nothing " \
        "written" in err and ".tmp-" not in err and str(ROOT) not in err, err
    assert list(tmp_path.iterdir()) == []


def test_a_live_session_on_a_full_disk_names_the_file_and_keeps_whole_lines(tmp_path, capsys, monkeypatch):
    """`aacmm live -o /full/s` said "No space left on device; nothing written" (no file named, and false: the session
    folder was there), left `.session.json.tmp` behind and a samples.csv ending in half a line (the write the disk cut
    short), against docs/guarantees.md section 6. Now exit 2 naming the file; the part of a write the disk took is cut
    off again, so every file still ends at a whole line and reads back."""
    import errno

    from arm_model.live import record
    from arm_model.live.samples import read_samples
    calls = []
    real = record._write_all

    def full(fd, data):
        calls.append(fd)
        if len(calls) > 2:              # a disk that fills up after the session started
            real(fd, data[: len(data) // 2])
            raise OSError(errno.ENOSPC, "No space left on device")
        real(fd, data)
    monkeypatch.setattr(record, "_write_all", full)
    sess, stream = tmp_path / "s", tmp_path / "stream.csv"
    stream.write_text("".join(SAMPLES.read_text().splitlines(keepends=True)[:300]))
    rc, err = _run(["live", stream, "--arm", "aacmm7", "--speed", "0", "--feature", "seat:a", "-o", sess], capsys)
    assert rc == 2 and f"error: {sess}/" in err and "cannot write the session's file: No space left on device" in err \
        and "nothing written" not in err, err
    assert sorted(p.name for p in sess.iterdir() if p.name.startswith(".")) == [".aacmm-output"]
    for f in sess.glob("*.csv"):
        data = f.read_bytes()
        assert data == b"" or data.endswith(b"\n"), f
        if data and f.name == "samples.csv":
            read_samples(f)


# ---------------------------------------------------------------------------------------------
# a residuals file: one residual a point

HEAD = "measurement,feature,kind,line,residual_um,dx_um,dy_um,dz_um,standardized\n"


@pytest.mark.parametrize("rows, ok", [
    (["ring-01,ring,ring,2,1,1,0,0,0.4", "ring-01,ring,ring,3,1,1,0,0,0.4"], True),
    (["ring-01,ring,ring,2,1,1,0,0,0.4", "ring-01,ring,ring,2,1,1,0,0,0.4"], False),      # a row pasted twice
    (["ring-01,ring,ring,2,1,1,0,0,0.4", "ring-01,ring,ring,2,5,5,0,0,2.0"], False),      # two residuals, one point
    (["m,t,reference,2,1,1,0,0,0.4", "m,t,reference,2,2,0,2,0,0.4"], True)])             # one a marker
def test_a_point_given_twice_in_a_residuals_file_is_refused(rows, ok):
    """A residuals file (view --residuals) holding a point's line twice with a feature's kind (a row pasted twice,
    or two files joined) was read, and both vectors drawn from the one point. Now refused at the second row, naming
    the first; a reference point keeps one row a marker."""
    from viz.residuals import parse_residuals
    text = HEAD + "\n".join(rows) + "\n"
    if ok:
        assert len(parse_residuals(text, "r.csv")) == 2
    else:
        with pytest.raises(InputError, match=r"r.csv, line 3, column 'line': point line 2 .* is given twice \(first "
                                             r"on line 2\)"):
            parse_residuals(text, "r.csv")


# ---------------------------------------------------------------------------------------------
# a number is ASCII, its padding too

@pytest.mark.parametrize("pad", ["\u00a0", "\u2003", "\u3000", "\u0085", "\u202f", "\u1680"])
def test_a_number_padded_with_unicode_space_is_refused(tmp_path, capsys, pad):
    """A number cell padded with a no-break space, an em space, an ideographic space or NEL ('12.5\\xa0', pasted
    from a word processor or a web page) was read as the number in every CSV reader and option, while another
    script's digits and the Unicode minus were refused: a number is ASCII, and so is the white space around it.
    Now 'expected a number, got '1.7038\\xa0'' at the cell, in points, streams, covariance, residuals and Table 2
    files and in options (csv_io.parse_number strips ASCII white space only)."""
    from arm_model.csv_io import parse_number
    assert parse_number(" 12.5\t") == 12.5 and parse_number(f"12.5{pad}") is None
    rows = (RING / "points.csv").read_text().splitlines()[:3]
    cells = rows[1].split(",")
    cells[2] = cells[2] + pad
    pts = tmp_path / "p.csv"
    pts.write_text("\n".join([rows[0], ",".join(cells), rows[2]]) + "\n", encoding="utf-8", newline="")
    rc, err = _run(["tip", pts, "--arm", "aacmm7", "-o", tmp_path / "t.csv"], capsys)
    assert rc == 2 and f"p.csv, line 2, column 'q1_deg': expected a number, got {cells[2]!r}" in err, err
    rc, err = _run(["tip", RING / "points.csv", "--arm", "aacmm7", "--u-probing-um", f"2{pad}", "-o",
                    tmp_path / "t.csv"], capsys)
    assert rc == 2 and "--u-probing-um" in err and "expected a finite number" in err, err
    assert not (tmp_path / "t.csv").exists()


def test_urdf_numbers_are_separated_by_xml_white_space_only(tmp_path, capsys):
    """`<origin xyz="0.0825\\xa00 0"/>` was read as three numbers (Python's split() splits at a no-break space);
    urdfdom refuses it ("Unable to parse component [0.0825 0] to a double"): now exit 2 at its line and key."""
    urdf = _panda(tmp_path, 'xyz="0.0825 0 0"', 'xyz="0.0825\u00a00 0"')
    rc, err = _run(["urdf", urdf, "--tip-frame", "ball_link", "-o", tmp_path / "o.urdf"], capsys)
    assert rc == 2 and "m.urdf, line 71, key 'origin.xyz': <origin xyz=...> must be 3 finite numbers" in err, err


def test_a_block_in_exponent_notation_keeps_the_ascii_rule(tmp_path, capsys):
    """The fast reader hands a block written in exponent notation (the Panda's points, 1.785763899444913205e+00) to
    numpy's loadtxt, which takes a no-break space around a number: the same rule now holds there."""
    rows = SEATS.read_text().splitlines()
    cells = rows[5].split(",")
    cells[3] = "\u00a0" + cells[3]
    rows[5] = ",".join(cells)
    pts = tmp_path / "p.csv"
    pts.write_text("\n".join(rows) + "\n")
    rc, err = _run(["tip", pts, "--arm", PANDA, "--tip-frame", "ball_link", "-o", tmp_path / "t.csv"], capsys)
    assert rc == 2 and f"p.csv, line 6, column 'q2_rad': expected a number, got {cells[3]!r}" in err, err


@pytest.mark.parametrize("command", [["simulate", ROOT / "examples" / "campaigns" / "paper-ring-xyz.toml"],
                                     ["tip", RING / "points.csv", "--arm", "aacmm7", "--mc", "10"]])
def test_a_seed_beyond_2_53_is_refused_at_the_option(tmp_path, capsys, command):
    """`simulate --seed 18446744073709551616` (2**64) wrote a truth.toml whose seed no TOML reader takes (64 bits at
    most; the read-back made it exit 3): a seed is now a whole number from 0 to 2**53 (exact in JSON and TOML), at
    the option, before any work."""
    rc, err = _run([*command, "--seed", str(2 ** 64), "-o", tmp_path / "o.csv"], capsys)
    assert rc == 2 and "argument --seed: must be in [0, 9.0072e+15], got 18446744073709551616" in err, err
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------------------------------
# a name with white space at its ends

def test_a_joint_name_with_white_space_at_its_ends_is_refused(tmp_path, capsys):
    """A joint named " j1" was read; calibrate then wrote a covariance file whose cell " j1.a" its reader reads
    stripped, as every CSV cell: the model file's read-back failed, exit 3 (an internal error). An id or a name the
    toolkit writes into a file has no white space at its ends (errors.id_problem, one rule for every id and name)."""
    arm = tmp_path / "arm.toml"
    arm.write_text((ROOT / "urdf" / "aacmm7.dh.toml").read_text().replace('name = "j1"', 'name = " j1"', 1))
    rc, err = _run(["tip", RING / "points.csv", "--arm", arm, "-o", tmp_path / "t.csv"], capsys)
    words = "arm.toml, line 9, key 'joint[1].name': 'name' must not begin or end with white space"
    assert rc == 2 and words in err, err


def test_a_feature_id_with_white_space_at_its_ends_is_refused():
    """Artefact features "ring" and "ring " were two features, but a points file's cell "ring " reads as "ring": the
    second could never get a point (and a plan's ids the same)."""
    from arm_model.io import parse_artefacts
    text = (RING / "artefacts.toml").read_text() + '\n[[feature]]\nid = "ring "\nkind = "seat"\n'
    with pytest.raises(InputError, match=r"a.toml, line 10, key 'feature\[2\].id': 'id' must not begin or end with "
                                         r"white space"):
        parse_artefacts(text, "a.toml")


# ---------------------------------------------------------------------------------------------
# invisible and text-direction characters

@pytest.mark.parametrize("mark", ["\ufeff", "\u200b", "\u202e", "\u2067"])
def test_an_id_with_an_invisible_or_direction_character_is_refused(tmp_path, capsys, mark):
    """A byte-order mark left inside a file (two exports joined), a zero-width space or a right-to-left override in a
    measurement id made an id that prints as another ('\\ufeffring-01' is a measurement of its own beside 'ring-01');
    an override also turns the rest of a terminal line around (an error message shown as another). Now refused in
    every id and name (errors.id_problem), and shown escaped in every message (log.escaped)."""
    from arm_model.log import escaped
    rows = (RING / "points.csv").read_text().splitlines()[:4]
    pts = tmp_path / "p.csv"
    pts.write_text("\n".join([rows[0], rows[1], mark + rows[2], rows[3]]) + "\n", encoding="utf-8")
    rc, err = _run(["tip", pts, "--arm", "aacmm7", "-o", tmp_path / "t.csv"], capsys)
    assert rc == 2 and "p.csv, line 3, column 'measurement': the measurement id must not hold an invisible or " \
        "text-direction character" in err and mark not in err, err
    assert escaped(f"a{mark}b") == "a" + mark.encode("unicode_escape").decode() + "b"


# ---------------------------------------------------------------------------------------------
# options that do nothing

@pytest.mark.parametrize("extra, words", [
    (["--contact-on-N", "1"], "--contact-on-N"),
    (["--min-dwell-s", "0.5", "--baseline-s", "0"], "--min-dwell-s, --baseline-s")])
def test_force_contact_options_with_trigger_contacts_are_refused(tmp_path, capsys, extra, words):
    """`live --contact trigger --contact-on-N 1` (or --contact-off-N, --min-dwell-s, --smooth-s, --baseline-s) was
    accepted and ignored: a trigger contact lasts while the button is held, whatever the force. As the live view's
    options without --view (round 10), exit 2 before anything is written."""
    sess = tmp_path / "s"
    rc, err = _run(["live", SAMPLES, "--arm", "aacmm7", "--speed", "0", "--feature", "seat:a", "--contact", "trigger",
                    *extra, "-o", sess], capsys)
    assert rc == 2 and f"{words}: option(s) of force contacts, which --contact trigger does not use" in err, err
    assert not sess.exists()


def test_a_fitted_probe_whose_ball_ran_behind_the_last_joint_is_a_numerical_failure_not_a_file_read_otherwise():
    """A calibration on 5000 ring points (the bundled ring repeated) let the prior-dominated probe z run from +85 to
    -93.6 mm: the written file read back put the stylus hinge behind the ball (|p|) where the fit had the ball's
    coordinate (-93.6 mm), 74 nm apart on a 5.9 N point, exit 3 ('a bug'). Such an arm is now refused by the
    writer as a numerical failure naming the probe (exit 4 at the command), as a joint origin beyond the reader's
    rules is."""
    from dataclasses import replace

    from arm_model.description import description_data, load_description
    from arm_model.errors import NumericalError
    from arm_model.shipped import shipped_path

    desc = load_description(shipped_path("urdf/aacmm7.dh.toml"))
    description_data(desc)                                   # the nominal is written
    ran = replace(desc, probe=replace(desc.probe, p_last=(2e-6, -1e-6, -0.0936)))
    with pytest.raises(NumericalError, match=r"probe .*-93\.6 mm along probe z"):
        description_data(ran)
    stated = replace(ran, probe=replace(ran.probe, lever=0.0936))   # a stylus length stated is written as stated
    assert description_data(stated)["probe"]["stylus_length_mm"] == pytest.approx(93.6)
