"""Reliability, round 12: the leftovers of round 11 (a TCP reset read as the stream's end, a repeatable option given
the same value twice, an output whose suffix contradicts its option, live's reproduce line run where it says) and
what a hostile-input audit of the readers and options the earlier rounds touched least found. The audit's driver
(about 880 command runs in process, and 1 450 calls of the readers themselves) fed: 88 URDFs odd but valid or hostile
(XML declarations in other encodings, UTF-16, BOM, CR/CRLF, comments, CDATA, processing instructions, DOCTYPEs with
internal and external entities, a billion laughs, character references in numbers, default and prefixed namespaces,
continuous joints with limits, mimic chains, 20 000 extra links, a 10^7-character name), each to `tip` and to `urdf`;
163 targeted and 260 random edits of a calibrated model file's [[effect]] tables, [calibration] table and covariance
file; 52 points files (BOM, mixed line ends, 20 000 columns, 10^5 cells, 10 MB cells, other encodings); every
numeric option at its range ends (parser-level: 22 values each), and `live` (55 runs: thresholds, rates, speeds,
streams with BOM, wide headers, clocks at 1e15 s); 47 `-o` targets (links to files, inputs, folders, pipes, loops,
dangling; hard links; `..`; FIFOs; 300-byte names) and concurrent writers; 66 tip/base frame pairs; `view`'s
options; the readers of points, artefacts, plans, descriptions, model files, residuals, Table 2, force signals and
masses files under random edits. Each test is named after its finding; all are fast (no fit, a few points)."""
from __future__ import annotations

import json
import socket
import struct
import threading

import pytest

from conftest import ROOT, exit_status

RING = ROOT / "examples" / "data" / "paper-ring-xyz"
SAMPLES = ROOT / "examples" / "live" / "samples.csv"


def _run(argv, capsys):
    rc = exit_status([str(a) for a in argv])
    return rc, capsys.readouterr().err


# ---------------------------------------------------------------------------------------------
# leftovers of round 11

def test_a_tcp_reset_is_a_failed_stream_not_its_end(tmp_path, capsys):
    """A server that resets the connection (a crashed adapter, a cable pulled: RST) was read as the stream's normal
    end: exit 0, session.json 'complete', though what the server still had to send never came. Now exit 2 naming the
    connection, the session kept (every sample read until then) as 'stopped' and said to be partial."""
    import time

    from arm_model.io import read_points
    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]
    sess = tmp_path / "s"

    def serve():
        conn, _ = server.accept()
        conn.sendall(b"".join(SAMPLES.read_bytes().splitlines(keepends=True)[:2500]))
        end = time.monotonic() + 30
        while time.monotonic() < end and len((sess / "points.csv").read_bytes().splitlines()
                                             if (sess / "points.csv").exists() else ()) < 2:
            time.sleep(0.05)            # the first point is recorded: the client reads on, the server then fails
        conn.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        conn.close()                    # RST, not FIN
        server.close()
    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    spec = f"tcp://127.0.0.1:{port}"
    rc, err = _run(["live", spec, "--arm", "aacmm7", "--feature", "seat:a", "-o", sess], capsys)
    thread.join(5)
    status = json.loads((sess / "session.json").read_text())
    assert rc == 2 and f"error: {spec}: the stream failed: the server broke the connection" in err \
        and "the session is partial" in err, err
    assert status["status"] == "stopped" and "partial" in status["message"] and spec in status["message"]
    assert len(read_points(sess / "points.csv", 7)) >= 1


@pytest.mark.parametrize("argv, words", [
    (["calibrate", "--hold", "j1.d", "--hold", "j1.d"], "argument --hold: j1.d given more than once"),
    (["calibrate", "--free", "j*.a", "--free", "j*.a"], "argument --free: j*.a given more than once"),
    (["close-loop", "--effect", "thermal", "--effect", "thermal"], "argument --effect: thermal given more than once"),
    (["tip", "--hold-joint", "j7", "--hold-joint", "j7=5"], "argument --hold-joint: j7 given more than once")])
def test_a_repeatable_option_given_the_same_value_twice_is_refused(tmp_path, capsys, argv, words):
    """`calibrate --hold j1.d --hold j1.d` (or --free) was taken as once: a pattern given twice is a slip (another
    pattern was meant). Now every repeatable option refuses a value given twice at the parser (`--hold-joint J` by
    its joint, whatever the value; `--effect` had its own check, now the parser's)."""
    command, *rest = argv
    inputs = [RING / "points.csv"] + ([RING / "artefacts.toml"] if command != "tip" else [])
    rc, err = _run([command, *inputs, "--arm", "aacmm7", *rest, "-o", tmp_path / "o"], capsys)
    assert rc == 2 and words in err, err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("name, writes, ok", [
    ("x.png", ".html", False), ("x.html", ".png", False), ("x.jpg", ".png", False), ("x.pdf", ".csv", False),
    ("x.svg", ".urdf", False), ("x.htm", ".html", True), ("x.HTML", ".html", True), ("x.PNG", ".png", True),
    ("x.xml", ".urdf", True), ("x.txt", ".csv", True), ("x", ".csv", True), ("x.tsv.csv", ".csv", True)])
def test_an_output_whose_suffix_is_another_format_is_refused(name, writes, ok):
    """`view --html x.png` wrote a page named as an image (and `--screenshot x.html` an image named as a page, `tip -o
    t.png` a CSV): only suffixes a reader of the toolkit takes were checked. Now a suffix of any known other format
    is refused before any work; a suffix of none (.txt, .xml for a URDF) stays free."""
    from pathlib import Path

    from arm_model import InputError
    from arm_model.output import check_suffix
    if ok:
        check_suffix(Path(name), writes)
    else:
        with pytest.raises(InputError, match=rf"{name}: a '\.[a-z]+' file is [A-Z]+, but [A-Z]+ is written there"):
            check_suffix(Path(name), writes)


def test_an_image_named_as_the_page_of_view_is_refused_before_any_work(tmp_path, capsys):
    rc, err = _run(["tip", RING / "points.csv", "--arm", "aacmm7", "-o", tmp_path / "t.png"], capsys)
    assert rc == 2 and "t.png: a '.png' file is PNG, but CSV is written there: name the output '.csv'" in err, err
    assert list(tmp_path.iterdir()) == []


def test_the_reproduce_line_runs_in_the_session_folder(tmp_path, capsys, monkeypatch):
    """session.json's `reproduce` (docs/live.md: `cd out/live-1 && <it>`) named the arm as given on the command line:
    an arm given by a relative path was not found from the session folder (and a path with a space split in two).
    Now relative to the session folder and quoted for a shell; run there with a model file of a joint's hysteresis
    (the points' last moves in points.csv's move columns), it writes tips.csv byte for byte."""
    import shlex

    from arm_model.effects import JointHysteresis
    from arm_model.model_file import format_model, load_model
    (tmp_path / "my arms").mkdir()
    model = tmp_path / "my arms" / "h.toml"
    model.write_text(format_model(load_model("aacmm7").desc, (JointHysteresis(joints=(1, 3)),),
                                  {"j2.hysteresis": 1e-4, "j4.hysteresis": -5e-5}))
    stream = tmp_path / "stream.csv"
    stream.write_text("".join(SAMPLES.read_text().splitlines(keepends=True)[:4200]))
    monkeypatch.chdir(tmp_path)
    rc, err = _run(["live", "stream.csv", "--arm", "my arms/h.toml", "--speed", "0", "-o", "out/s"], capsys)
    assert rc == 0, err
    line = json.loads((tmp_path / "out" / "s" / "session.json").read_text())["reproduce"]
    assert line == "aacmm tip points.csv --arm '../../my arms/h.toml' --uncertainty -o tips-again.csv"
    monkeypatch.chdir(tmp_path / "out" / "s")
    assert _run(shlex.split(line)[1:], capsys)[0] == 0
    sess = tmp_path / "out" / "s"
    assert (sess / "tips-again.csv").read_bytes() == (sess / "tips.csv").read_bytes()
    moves = (sess / "points.csv").read_text().splitlines()[0]
    assert moves.endswith(",q7_move_sign")


# ---------------------------------------------------------------------------------------------
# round 12: URDFs that are odd but valid XML

def test_a_urdf_in_a_default_namespace_reads_as_urdfdom_reads_it(tmp_path):
    """`<robot name="panda" xmlns="http://www.ros.org/urdf">` (a default namespace; urdfdom, Pinocchio's parser,
    reads the names as written and takes the file) was refused: "a URDF's root element is <robot>, got
    <{http://www.ros.org/urdf}robot>". Now the default namespace is dropped on reading: the same arm as without it.
    (The audit's other 87 odd-but-valid or hostile URDFs, entities, comments, CDATA, processing instructions,
    character references in numbers, prefixed foreign elements, continuous joints with limits, mimic chains,
    UTF-16 and BOM, 20 000 extra links, were read as before or refused at their line.)"""
    import numpy as np
    from test_reliability_round10 import PANDA, _panda

    from arm_model.model_file import load_model
    ns = _panda(tmp_path, '<robot name="panda">', '<robot name="panda" xmlns="http://www.ros.org/urdf">')
    arm, plain = load_model(ns, "ball_link"), load_model(PANDA, "ball_link")
    assert arm.desc == plain.desc
    q = np.random.default_rng(12).uniform(-1.0, 1.0, (5, plain.desc.n_joints))
    np.testing.assert_array_equal(arm.model.ball_centres(q, None, arm.p), plain.model.ball_centres(q, None, plain.p))


# ---------------------------------------------------------------------------------------------
# round 12: the model file's [calibration] table

def test_a_nul_in_a_file_the_model_file_names_is_refused_at_its_key():
    """`covariance = "c.csv\\u0000"` (TOML's escape makes a NUL, which no system takes in a file name) was exit 3, an
    internal error: os.stat raised ValueError where the reader looked whether the file was the model file itself.
    Now exit 2 at the key's line, for `covariance` and `training_poses` alike."""
    from arm_model import InputError
    from arm_model.model_file import parse_model
    text = (ROOT / "urdf" / "aacmm7.dh.toml").read_text()
    for key in ("covariance", "training_poses"):
        bad = text + f'\n[calibration]\n{key} = "c.csv\\u0000"\n'
        line = len(bad.splitlines())
        with pytest.raises(InputError, match=rf"m.toml, line {line}, key 'calibration.{key}': '{key}' holds a NUL "
                                             "character: not a file name"):
            parse_model(bad, str(ROOT / "m.toml"))


# ---------------------------------------------------------------------------------------------
# round 12: -o at a link to a pipe

def test_an_output_linked_to_a_pipe_is_refused_by_its_own_name(tmp_path, capsys):
    """`aacmm tip ... -o /dev/stdout | cat` said "/proc/4242/fd/pipe:[794503]: cannot write the output file: No such
    file or directory": the link was followed to its target, which for a pipe is no path, before the output was
    checked for being a pipe. Now the link's target is checked first: "/dev/stdout: the output exists and is a FIFO
    (named pipe), not a regular file" (a file output) or "not a folder" (a folder output); `live -o /dev/stdout` the
    same ("cannot create the session folder" at /proc/.../pipe:[n] before). Here a link to a FIFO."""
    import os
    os.mkfifo(tmp_path / "fifo")
    os.symlink(tmp_path / "fifo", tmp_path / "out")
    for command, what in ((["tip", RING / "points.csv", "--arm", "aacmm7"], "the output exists and is a FIFO (named "
                                                                            "pipe), not a regular file"),
                          (["simulate", ROOT / "examples" / "campaigns" / "paper-ring-xyz.toml"],
                           "the output exists and is a FIFO (named pipe), not a folder"),
                          (["live", SAMPLES, "--arm", "aacmm7"], "the session folder must be a new folder, but a file "
                                                                 "of that name exists")):
        rc, err = _run([*command, "-o", tmp_path / "out"], capsys)
        assert rc == 2 and f"{tmp_path / 'out'}: {what}" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fifo", "out"]


# ---------------------------------------------------------------------------------------------
# round 12: an output inside an input folder

@pytest.mark.parametrize("inside", ["examples/data/copy", "docs/x", "examples"])
def test_examples_into_the_folder_they_are_copied_from_is_refused(capsys, inside):
    """`aacmm examples examples/data/copy` in a clone (or into the installed package's own folder) wrote a copy of the
    examples inside the toolkit's examples: the next `aacmm examples` shipped that copy as an example of its own, one
    more level each time. The rule of every command (docs/guarantees.md: no output inside a folder the command reads
    files from) now holds for `examples` too: exit 2, nothing written."""
    from arm_model.shipped import shipped_path
    dest = shipped_path(".") / inside
    existed = dest.exists()
    rc, err = _run(["examples", dest], capsys)
    assert rc == 2 and "refusing to write the examples into the folder" in err and "they are copied from" in err, err
    assert dest.exists() == existed


@pytest.mark.parametrize("name, words", [
    ("x&#10;y", "must be one line of text without control characters"),
    ("a&#9;b", "must be one line of text without control characters"),
    (" panda", "must not begin or end with white space"),
    ("pan&#x202e;da", "must not hold an invisible or text-direction character"),
    ("x" * 100_001, "must be at most 100000 characters long")])
def test_a_robot_name_follows_the_rule_of_every_name(tmp_path, capsys, name, words):
    """A URDF's `<robot name="x&#10;y">` (or with a tab, white space at its ends, a text-direction character) was read:
    `calibrate` then wrote a model file named after it that its own reader refuses, exit 3 ("a bug"); a name of 10^7
    characters made `urdf` write a comment libxml2 refuses (exit 3). A DH table's `name` was held to the rule of every
    id and name (errors.id_problem), the URDF's robot name was not: now it is, exit 2 at its line."""
    from test_reliability_round10 import _panda
    urdf = _panda(tmp_path, '<robot name="panda">', f'<robot name="{name}">')
    rc, err = _run(["urdf", urdf, "--tip-frame", "ball_link", "-o", tmp_path / "o.urdf"], capsys)
    assert rc == 2 and f"m.urdf, line 1, key 'robot.name': the <robot> name {words}" in err, err
    assert not (tmp_path / "o.urdf").exists()


def test_a_task_id_leaves_room_for_its_measurements_number(tmp_path, capsys):
    """`simulate` with a task id of 100 000 characters (the longest id) ran the campaign, then its points file's read-
    back refused the measurement id "<id>-01" (100 003 characters): exit 3 after the work. The task id is now held
    to the longest id less the suffix its measurements add, at its key, before any work."""
    camp = tmp_path / "c.toml"
    text = (ROOT / "examples" / "campaigns" / "paper-ring-xyz.toml").read_text()
    camp.write_text(text.replace('id = "ring"', f'id = "{"r" * 99_990}"'))
    rc, err = _run(["simulate", camp, "-o", tmp_path / "o"], capsys)
    assert rc == 2 and "c.toml, line 44, key 'task[1].id': 'id' must be at most 99968 characters long" in err, err
    assert not (tmp_path / "o").exists()


def test_the_calibrated_name_of_the_longest_arm_name_is_a_name():
    """`calibrate` (and `close-loop`) on an arm named with the longest name a reader takes (10^5 characters, a URDF's
    robot or a DH table's name) fitted, then refused its own model file: its name "<arm>-calibrated" was 11
    characters too long, exit 3 after the fit (measured on the Panda's front seats, 13 s). The name is now made in one
    place for both commands, cut with a checksum of the whole when it would pass the longest name."""
    from arm_model.errors import MAX_ID_LENGTH, id_problem
    from calibration.model_output import calibrated_name
    assert calibrated_name("panda") == "panda-calibrated"
    near = "p" * (MAX_ID_LENGTH - len("-calibrated"))
    assert calibrated_name(near) == near + "-calibrated"
    longest, other = "p" * MAX_ID_LENGTH, "p" * (MAX_ID_LENGTH - 1) + "q"
    assert id_problem(calibrated_name(longest)) is None and calibrated_name(longest).endswith("-calibrated")
    assert calibrated_name(longest) != calibrated_name(other)       # two arms never get one name


# ---------------------------------------------------------------------------------------------
# round 12: options that do nothing

@pytest.mark.parametrize("argv, words", [
    (["tip", RING / "points.csv", "--arm", "aacmm7", "--u-probing-um", "3"],
     "--u-probing-um: option(s) of the uncertainty, which is not asked for (add --uncertainty"),
    (["tip", RING / "points.csv", "--arm", "aacmm7", "--encoder-resolution-deg", "0.001", "--u-force-N", "1", "1"],
     "--encoder-resolution-deg, --u-force-N: option(s) of the uncertainty"),
    (["tip", RING / "points.csv", "--arm", "aacmm7", "--uncertainty", "--seed", "4"],
     "--seed: option(s) of the Monte Carlo, which is not asked for (add --mc N)"),
    (["view", RING / "points.csv", "--arm", "aacmm7", "--u-compliance-rel", "0.5", "--ellipsoid-scale", "10"],
     "--u-compliance-rel, --ellipsoid-scale: option(s) of the ellipsoids, which is not asked for (add --ellipsoids)"),
    (["view", RING / "points.csv", "--arm", "aacmm7", "--fps", "4"],
     "--points-per-s: option(s) of the animation, which is not asked for (add --animate)"),
    (["view", RING / "points.csv", "--arm", "aacmm7", "--browser", "chromium"],
     "--browser: option(s) of the screenshot, which is not asked for (add --screenshot OUT.png)"),
    (["live", "-", "--arm", "aacmm7", "--speed", "2"],
     "--speed: option(s) of a file's replay, which is not asked for (- is a stream, taken as its lines come)"),
    (["live", SAMPLES, "--arm", "aacmm7", "--stop-after-idle-s", "2"],
     "--stop-after-idle-s: option(s) of a stream that may fall silent, which is not asked for (the file")])
def test_an_option_that_would_do_nothing_is_refused(tmp_path, capsys, argv, words):
    """`tip --u-probing-um 3` without --uncertainty wrote the centres without any uncertainty and said nothing of the
    option (the input uncertainties, and --seed without --mc, were read and dropped); so were view's input
    uncertainties and --ellipsoid-scale without --ellipsoids, --points-per-s without --animate, --browser without
    --screenshot, live's --speed on a stream (paced as it comes) and --stop-after-idle-s on a file (never idle). As
    round 10 and 11 did for live's view and contact options: exit 2 naming them and what they belong to, before any
    work (tip: once the arm says whether a covariance makes the uncertainty anyway)."""
    out = ["-o", tmp_path / "o.csv"] if argv[0] == "tip" else ["--html", tmp_path / "o.html"] \
        if argv[0] == "view" else ["-o", tmp_path / "s"]
    rc, err = _run([*argv, *out], capsys)
    assert rc == 2 and words in err, err
    assert list(tmp_path.iterdir()) == []


def test_a_shipped_arm_named_on_the_command_line_is_not_a_file_of_the_current_folder(tmp_path, capsys, monkeypatch):
    """`aacmm tip points.csv --arm aacmm7 -o aacmm7` was refused ("refusing to write the output over an input file"):
    the shipped arm's name was taken for a file of the current folder among the inputs an output must not replace
    (and `ring ... --arm aacmm7 -o .` said "the output folder holds the input aacmm7"). The inputs now hold the shipped
    arm's own file, as the arm is read."""
    monkeypatch.chdir(tmp_path)
    rc, err = _run(["tip", RING / "points.csv", "--arm", "aacmm7", "-o", "aacmm7"], capsys)
    assert rc == 0, err
    assert (tmp_path / "aacmm7").read_text().startswith("measurement,feature,x_rigid_mm")
    from arm_model.shipped import shipped_path
    (tmp_path / "aacmm7").unlink()          # (a file of the name would be the arm read)
    rc, err = _run(["urdf", "aacmm7", "-o", shipped_path("urdf/aacmm7.dh.toml")], capsys)
    assert rc == 2 and "refusing to write the output over an input file" in err, err


@pytest.mark.parametrize("diameter", ["2_5", "\u0661\u0662", "\uff12\uff15", "25\u00a0", "0x19"])
def test_a_feature_option_s_diameter_is_a_number_by_the_one_rule(diameter):
    """`live --feature sphere:a:2_5` made a 25 mm sphere and `--feature sphere:a:١٢` (Arabic digits) a 12 mm one:
    the option's diameter went through Python's float(), which takes underscores and any script's digits, where
    every other number of the toolkit (files and options) is ASCII without underscores (csv_io.parse_number)."""
    from arm_model import InputError
    from arm_model.live import single_feature_plan
    with pytest.raises(InputError, match="--feature: the diameter must be a number in mm"):
        single_feature_plan(f"sphere:a:{diameter}")
    assert single_feature_plan("sphere:a: 25").entries[0].feature.diameter == pytest.approx(0.025)


def test_a_free_pattern_whose_parameters_are_all_held_is_refused():
    """`calibrate --free j1.a --free j2.a --hold j1.a` fitted j2.a alone and said nothing of `--free j1.a`: the hold
    undid it (the two options contradict each other on j1.a). A --free pattern every parameter of which --hold holds
    is now an error naming both, before the fit (calibrate and close-loop choose their free set there); a glob that
    --hold narrows (`--free 'j*.a' --hold j1.a`) stays."""
    from types import SimpleNamespace

    from arm_model import InputError
    from arm_model.model_file import load_model
    from calibration.cli import free_names
    model = load_model("aacmm7").model
    with pytest.raises(InputError, match=r"--free j1.a: every parameter it names is held by --hold j1.a"):
        free_names(model, SimpleNamespace(free=["j1.a", "j2.a"], hold=["j1.a"]))
    assert free_names(model, SimpleNamespace(free=["j*.a"], hold=["j1.a"])) == [f"j{k}.a" for k in range(2, 8)]


_GAPS = ["<!-- a comment, <joint name='x'/> -->", "\n\t  \r\n", "<gazebo><![CDATA[<joint/>]]></gazebo>",
         '<g:plugin xmlns:g="urn:g" g:x="1"/>']


def test_what_urdfdom_reads_past_changes_nothing(tmp_path):
    """A property over the audit's valid odd URDFs: comments, white space (CRLF too), CDATA in a foreign element and
    foreign namespaced elements, put between any two elements, with or without an XML declaration, a byte-order mark
    or a default namespace, read as the same arm (hypothesis, 5 variants here; the audit ran 60). It found the two
    defects below."""
    from hypothesis import HealthCheck, given, settings, strategies as st
    from test_reliability_round10 import PANDA

    from arm_model.model_file import load_model
    text = PANDA.read_text()
    gaps = [i + 1 for i in range(len(text) - 1) if text[i] == ">"]
    plain = load_model(PANDA, "ball_link").desc

    @settings(max_examples=5, deadline=None, derandomize=True, database=None,
              suppress_health_check=list(HealthCheck))
    @given(st.lists(st.tuples(st.sampled_from(gaps), st.sampled_from(_GAPS)), max_size=6),
           st.sampled_from(["", "\ufeff", '<?xml version="1.0" encoding="UTF-8"?>\n']), st.booleans(), st.integers())
    def same(inserts, head, ns, salt):
        t = text
        for at, gap in sorted(inserts, reverse=True):
            t = t[:at] + gap + t[at:]
        if ns:
            t = t.replace('<robot name="panda">', '<robot name="panda" xmlns="http://www.ros.org">', 1)
        path = tmp_path / "v.urdf"
        path.write_text(head + t, encoding="utf-8")
        assert load_model(path, "ball_link").desc == plain
    same()


@pytest.mark.parametrize("old, new", [('<child link="panda_link1" />', '<child link="panda_link1" /><?foo bar?>'),
                                      ("</robot>", "<?foo bar?></robot>")])
def test_a_processing_instruction_inside_the_robot_is_refused_at_its_line(tmp_path, capsys, old, new):
    """`<?foo bar?>` inside <robot> was read where it sat between joints (and the URDF written back with it, which
    Pinocchio then refused) and failed elsewhere as "yourdfpy cannot read the URDF: Unknown tag: <cyfunction
    ProcessingInstruction at 0x7f...>" (found by the property above). urdfdom, Pinocchio's and ROS's parser, refuses
    every such file ("XML_ERROR_PARSING_DECLARATION"): now exit 2 at its line. One before <robot>
    (`<?xml-stylesheet ...?>`), which urdfdom takes, is read as before."""
    from test_reliability_round10 import PANDA, _panda
    urdf = _panda(tmp_path, old, new)
    line = next(k for k, t in enumerate(urdf.read_text().splitlines(), 1) if "<?foo" in t)
    rc, err = _run(["urdf", urdf, "--tip-frame", "ball_link", "-o", tmp_path / "o.urdf"], capsys)
    assert rc == 2 and f"m.urdf, line {line}: a processing instruction <?foo ...?> inside <robot>: urdfdom" in err, err
    assert not (tmp_path / "o.urdf").exists()
    before = tmp_path / "b.urdf"
    before.write_text('<?xml-stylesheet href="x"?>\n' + PANDA.read_text())
    assert _run(["urdf", before, "--tip-frame", "ball_link", "-o", tmp_path / "b-out.urdf"], capsys)[0] == 0


@pytest.mark.parametrize("old, new, what", [("<geometry>", "<geometry><gazebo/>", "<gazebo>"),
                                            ('<mesh filename="../meshes/panda/link0.dae" />', "", "nothing")])
def test_a_visual_without_a_shape_is_left_out_as_urdfdom_leaves_it(tmp_path, caplog, old, new, what):
    """A <visual> whose <geometry> is empty or starts with another element was "yourdfpy cannot read the URDF: list
    index out of range" (or "Unknown tag: gazebo"), exit 2 without a line, where urdfdom leaves that visual out and
    Pinocchio reads the file (found by the property above). Now it is left out with a warning at its line; the arm
    is the same."""
    from test_reliability_round10 import PANDA, _panda

    from arm_model.model_file import load_model
    urdf = _panda(tmp_path, old, new)
    assert load_model(urdf, "ball_link").desc == load_model(PANDA, "ball_link").desc
    assert f"m.urdf, line 5: a <visual> whose <geometry> holds {what} where a box, cylinder, sphere or mesh is " \
        "expected: left out, as urdfdom leaves it out" in caplog.text
