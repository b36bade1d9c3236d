"""Reliability, round 10: what a hostile-input audit of every subcommand found after round 9 (each test named after
its finding; all fast: no fit, a few points). The audit's driver mutated every cell, key and option of the bundled
examples (NaN, inf, 1e308, -0, huge integers, non-ASCII digits, BOM, CRLF, tabs, duplicated headers, quoted cells,
wrong TOML types, arrays for scalars), fed hostile URDFs (cycles, zero axes, NaN and negative inertials, limits
reversed, 10 000 links) and hostile outputs, and ran each command under a timeout."""
from __future__ import annotations

import json

import pytest

from arm_model.csv_io import blank_record
from arm_model.live.samples import read_samples
from conftest import ROOT, exit_status

RING = ROOT / "examples" / "data" / "paper-ring-xyz"
SAMPLES = ROOT / "examples" / "live" / "samples.csv"


def _run(argv, capsys):
    rc = exit_status([str(a) for a in argv])
    return rc, capsys.readouterr().err


# ---------------------------------------------------------------------------------------------
# a row of only commas: one rule for files and streams

@pytest.mark.parametrize("line, blank", [("", True), ("  \t", True), (",,,,", True), (" , ,\t,", True),
                                         ('"",""', True), ('" ", ,""', True), (",,0", False), ('"x",,', False),
                                         ('"', False), ("0,1", False)])
def test_blank_record(line, blank):
    assert blank_record(line) is blank


def test_a_row_of_only_commas_is_a_blank_line_in_files_and_streams(tmp_path, capsys):
    """A row of only commas (a spreadsheet's empty row) was skipped by the file readers and counted as a bad line by
    `live` (and refused by the sample stream's read-back); now it is a blank line everywhere (csv_io.blank_record)."""
    lines = SAMPLES.read_text().splitlines()
    stream = tmp_path / "s.csv"
    stream.write_text("\n".join([",,,,", lines[0], *lines[1:40], ",,,,,,,,,,,", '"",""', ",,", *lines[40:80]]) + "\n")
    assert read_samples(stream) == 79
    rc, err = _run(["live", stream, "--arm", "aacmm7", "--speed", "0", "--feature", "seat:a", "-o",
                    tmp_path / "sess"], capsys)
    assert rc == 0, err
    counts = json.loads((tmp_path / "sess" / "session.json").read_text())["counts"]
    assert counts["bad_lines"] == 0 and "bad_line" not in err, (counts, err)
    pts = (RING / "points.csv").read_text().splitlines()
    points = tmp_path / "p.csv"
    points.write_text("\n".join([",,,", pts[0], pts[1], ",,,,,,,,,,,,", pts[2]]) + "\n")
    rc, err = _run(["tip", points, "--arm", "aacmm7", "-o", tmp_path / "t.csv"], capsys)
    assert rc == 0 and len((tmp_path / "t.csv").read_text().splitlines()) == 3, err


# ---------------------------------------------------------------------------------------------
# a URDF's <inertial>: non-finite or implausible numbers refused, tensors no body has warned

PANDA = ROOT / "examples" / "data" / "real-panda-seats" / "panda-with-inertials.urdf"
LINK1 = '<mass value="4.97068" /><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01" />'


def _panda(tmp_path, old, new):
    text = PANDA.read_text()
    assert old in text
    path = tmp_path / "m.urdf"
    path.write_text(text.replace(old, new, 1))
    return path


LINK0 = '<link name="panda_link0">'


@pytest.mark.parametrize("old, new, line, words", [
    (LINK1, LINK1.replace('ixx="0.01"', 'ixx="nan"'), 16, "key 'inertia.ixx': <inertia ixx=...> must be 1 finite"),
    (LINK1, LINK1.replace('ixy="0"', 'ixy="inf"'), 16, "key 'inertia.ixy'"),
    (LINK1, LINK1.replace('ixx="0.01"', 'ixx="1e308"'), 16, "not a plausible inertia"),
    (LINK0, LINK0 + '<inertial><origin xyz="nan 0 0"/><mass value="1"/></inertial>', 3, "key 'origin.xyz'"),
    (LINK0, LINK0 + '<inertial><mass value="nan"/></inertial>', 3, "key 'mass.value'")])
def test_a_urdf_inertial_that_is_not_a_number_is_refused(tmp_path, capsys, old, new, line, words):
    """NaN, inf or 1e308 in an <inertia>, and a NaN mass or centre of mass of a link off the chain, were accepted
    (urdfdom refuses them, and Pinocchio then drops the link's inertial without a word; a calibrated URDF carried
    them on): exit 0 -> 2, at its line and key."""
    urdf = _panda(tmp_path, old, new)
    pts = tmp_path / "p.csv"
    pts.write_text("measurement,feature," + ",".join(f"q{k}_deg" for k in range(1, 8)) + "\nm,f,1,2,3,-4,5,6,7\n")
    rc, err = _run(["tip", pts, "--arm", urdf, "--tip-frame", "ball_link", "-o", tmp_path / "t.csv"], capsys)
    assert rc == 2 and f"m.urdf, line {line}" in err and words in err, err
    assert not (tmp_path / "t.csv").exists()


@pytest.mark.parametrize("old, new, words", [
    ('<link name="panda_link0">', '<link name="panda_link0"><inertial><mass value="-2"/></inertial>',
     "a negative mass, which no body has, on 1 link(s) off the chain: link 'panda_link0', -2 kg (line 3)"),
    ('<link name="panda_link0">', '<link name="panda_link0"><inertial><mass value="-1e-12"/></inertial>', None),
    (LINK1, LINK1.replace('ixx="0.01"', 'ixx="-5"'), None),
    (LINK1, '<mass value="0" /><inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0" />', None)])
def test_a_negative_mass_off_the_chain_is_warned(tmp_path, caplog, old, new, words):
    """A negative mass on a link the chain does not use was read without a word: now one warning naming the link
    and the line (on the chain it stays refused, round 8); rounding noise says nothing. Inertia tensors are used by
    no computation of the toolkit and are not judged (21 of the 55 URDFs of example-robot-data hold placeholder
    tensors no body has: a warning there would be noise); only their numbers are checked (the test above)."""
    from arm_model.urdf_import import description_from_urdf
    desc = description_from_urdf(_panda(tmp_path, old, new), "ball_link")
    assert len(desc.joints) == 7
    said = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    if words is None:
        assert not said, said
    else:
        assert len(said) == 1 and words in said[0], said


# ---------------------------------------------------------------------------------------------
# absurd durations, and options of a live view not asked for

@pytest.mark.parametrize("extra, words", [
    (["--view", "--linger-s", "1e308"], "--linger-s: must be in [0, 1e+07], got 1e308"),
    (["--stop-after-idle-s", "1e300"], "--stop-after-idle-s: must be in (0, 1e+07], got 1e300"),
    (["--linger-s", "5"], "--linger-s: option(s) of the live view, which is not asked for (add --view)"),
    (["--port", "7001", "--fps", "5"], "--port, --fps: option(s) of the live view"),
    (["--speed", "1e-300"], "--speed: must be 0 (as fast as possible) or in [0.001, 1e+06], got 1e-300")])
def test_live_absurd_durations_and_view_options_without_a_view_are_refused(tmp_path, capsys, extra, words):
    """`live --view --linger-s 1e308` served the view until Ctrl-C, and --linger-s, --port, --fps without --view were
    silently ignored: exit 0 -> 2, nothing written (one type, cli_options.duration_s, for every wait). `--speed 1e-300`
    replayed one sample and then waited 1e297 s (a hang): exit 2."""
    speed = [] if "--speed" in extra else ["--speed", "0"]
    rc, err = _run(["live", SAMPLES, "--arm", "aacmm7", *speed, "--feature", "seat:a", "-o", tmp_path / "s", *extra],
                   capsys)
    assert rc == 2 and words in err, err
    assert not (tmp_path / "s").exists()


def test_view_open_s_keeps_its_bound(capsys):
    rc, err = _run(["view", RING / "points.csv", "--arm", "aacmm7", "--open-s", "1e308"], capsys)
    assert rc == 2 and "--open-seconds: must be in (0, 1e+07], got 1e308" in err, err


def test_a_quoted_number_in_a_live_stream_reads_as_in_a_file():
    """`0.1,"1",2` (a CSV writer that quotes every cell) was a bad line of a live stream, read as 1 by every file
    reader and by the stream's own header reader: now the same number; broken quoting stays a located bad line."""
    from arm_model import InputError
    from arm_model.live.samples import SampleLayout
    layout = SampleLayout(["time_s", "q1_deg", "q2_deg"], 2, "s")
    assert layout.parse('0.1,"1"," 2"', 3) == layout.parse("0.1,1,2", 3)
    with pytest.raises(InputError, match=r"s, line 3: not valid CSV"):
        layout.parse('0.1,"1,2', 3)


@pytest.mark.parametrize("option, value, words", [
    ("--mpe-e-uni-um", "1e308", "must be in [1e-06, 100000], got 1e308"),
    ("--mpe-spat-um", "1e-300", "must be in [1e-06, 100000], got 1e-300"),
    ("--outlier-threshold", "1e-300", "must be in [1, 1e+06], got 1e-300"),
    ("--gross-threshold", "0.5", "must be in [1, 1e+06], got 0.5")])
def test_a_verdict_or_threshold_without_meaning_is_refused(tmp_path, capsys, option, value, words):
    """`calibrate --mpe-e-uni-um 1e308` passed every item (1e-300 failed every one) and `--outlier-threshold 1e-300`
    reported every point as an outlier, exit 0 -> 2 before any work."""
    rc, err = _run(["calibrate", RING / "points.csv", RING / "artefacts.toml", "--arm", "aacmm7", option, value,
                    "-o", tmp_path / "o"], capsys)
    assert rc == 2 and f"{option}: {words}" in err, err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("kind, n, ok", [("plane", 2, False), ("plane", 3, True), ("sphere", 4, False),
                                         ("ring", 3, False), ("seat", 1, True)])
def test_a_plan_asking_fewer_points_than_a_fit_needs_is_refused(kind, n, ok):
    """A plan's `points = 2` on a plane was read, and the session then never fitted the plane (a note "2 of the 3
    points a plane needs" as its only result): now refused at its key, exit 2 (live.plan.NEEDED_POINTS, the tracker's
    own counts)."""
    from arm_model import InputError
    from arm_model.live import parse_plan
    size = ", diameter_mm = 20.0" if kind in ("sphere", "ring") else ""
    text = f'feature = [{{ id = "f", kind = "{kind}"{size}, points = {n} }}]\n'
    if ok:
        assert parse_plan(text, "p.toml").entries[0].points == n
    else:
        with pytest.raises(InputError, match=rf"p.toml, .*key 'feature\[1\].points': a {kind} needs at least"):
            parse_plan(text, "p.toml")


# ---------------------------------------------------------------------------------------------
# a campaign's task sizes: signs and counts

RING_TASK = {"kind": "ring", "diameter_mm": 50.0, "centre_mm": [600.0, 0.0, 50.0], "points_per_row": 4}


@pytest.mark.parametrize("task, key, words", [
    ({**RING_TASK, "u_diameter_mm": -1.0}, "u_diameter", "must not be negative"),
    ({**RING_TASK, "form_error_mm": -1.0}, "form_error", "must not be negative"),
    ({**RING_TASK, "true_form_error_mm": -1.0}, "true_form_error", "must not be negative"),
    ({**RING_TASK, "depths_mm": [-1.0, 5.0]}, "depths", "must not be negative"),
    ({**RING_TASK, "form_lobes": 0}, "form_lobes", "must be at least 2"),
    ({"kind": "plane", "size_mm": [0.0, 10.0]}, "size", "must be > 0"),
    ({"kind": "ballbar", "positions": 2, "true_length_mm": -600.0}, "true_length", "must be at least 0.001 mm"),
    ({"kind": "tracker", "nests": 2, "distance_mm": 0.0}, "distance", "must be > 0"),
    ({"kind": "mocap", "postures": 4, "noise_mm": -1.0}, "noise", "must not be negative"),
    ({"kind": "mocap", "postures": 4, "markers": 10 ** 7}, "markers", "must be from 1 to 100")])
def test_a_campaign_task_size_that_cannot_be_is_refused(task, key, words):
    """A ring's u_diameter_mm or form_error_mm of -1 and a mocap noise of -1 mm were internal errors (exit 3); a
    negative true form error, depth or bar length, a plane or an instrument distance of 0, and 0 form lobes were
    simulated as given (exit 0); 10^7 mocap markers ran past 90 s on 4 postures: now exit 2 at the key."""
    from arm_model import InputError
    from arm_model.sim import campaign_from_dict
    with pytest.raises(InputError, match=rf"key 'task\[1\]\.{key}.*'{key}' {words}"):
        campaign_from_dict({"seed": 1, "sensor": "none", "task": [task]})


@pytest.mark.parametrize("section, key, value, words", [
    ("environment", "cycle_period_s", 0.0, "'cycle_period' must be at least 1 s"),
    ("environment", "cycle_period_s", -1.0, "'cycle_period' must be at least 1 s"),
    ("signals", "sample_period_s", 1e-320, "'sample_period' must be from 1e-06 s"),
    ("signals", "sample_period_s", 1e9, "'sample_period' must be from 1e-06 s"),
    ("operator", "measurement_gap_s", -1.0, "'measurement_gap' must not be negative")])
def test_a_campaign_clock_that_cannot_be_is_refused(section, key, value, words):
    """`cycle_period_s = 0` or `sample_period_s = 1e-320` made every temperature NaN (internal error, exit 3);
    `sample_period_s = 1e9` put every time stamp at 0 and a negative measurement gap ran the clock backwards (exit 0):
    now exit 2 at the key."""
    from arm_model import InputError
    from arm_model.sim import campaign_from_dict
    with pytest.raises(InputError, match=rf"key '{section}\.{key.rsplit('_', 1)[0]}.*{words}"):
        campaign_from_dict({"seed": 1, "sensor": "none", section: {key: value},
                            "task": [{"kind": "seat", "articulations": 3}]})


@pytest.mark.parametrize("old, new, line, link", [
    ('<child link="panda_link1" />', '<child link="panda_link0" />', 19, "panda_link0"),
    ('<parent link="panda_link2" />', '<parent link="panda_link5" />', 53, "panda_link3")])
def test_a_loop_of_joints_anywhere_in_a_urdf_is_refused(tmp_path, capsys, old, new, line, link):
    """A joint whose child is its own parent (the rest of the tree then hangs from another root) was read: `urdf`
    wrote a 6-joint arm from the 7-joint Panda, exit 0; a loop is now refused wherever it is, at its joint's line."""
    rc, err = _run(["urdf", _panda(tmp_path, old, new), "--tip-frame", "ball_link", "-o", tmp_path / "o.urdf"], capsys)
    assert rc == 2 and f"m.urdf, line {line}" in err and f"a loop through link '{link}'" in err, err
    assert not (tmp_path / "o.urdf").exists()


@pytest.mark.parametrize("effect, value", [("joint_compliance", {"stiffness_Nm_per_rad": [1e4, 1e4]}),
                                           ("thermal", {"alpha_per_K": [1e-5, 1e-5]}),
                                           ("lateral_compliance", {"stiffness_x_Nm_per_rad": [1e5, 1e5]})])
def test_a_true_effect_naming_a_joint_twice_is_refused(effect, value):
    """`[truth.joint_compliance] joints = ["j2", "j2"]` (or thermal) was an internal error (the effect's own check,
    exit 3); one rule for every effect's joints now, at the key (lateral_compliance had it alone)."""
    from arm_model import InputError
    from arm_model.sim import campaign_from_dict
    with pytest.raises(InputError, match=rf"key 'truth\.{effect}\.joints'.*a joint is named twice"):
        campaign_from_dict({"seed": 1, "sensor": "xyz", "truth": {effect: {"joints": ["j2", "j2"], **value}},
                            "task": [{"kind": "seat", "articulations": 3}]})


def test_ctrl_c_while_the_commands_load_is_one_line(monkeypatch, capsys):
    """Ctrl-C in the first second (`timeout -s INT 1 aacmm calibrate ...`: while the commands' modules load) printed a
    Python traceback ending in KeyboardInterrupt; now one line, exit 130."""
    import arm_model.cli as cli

    def interrupted(argv):
        raise KeyboardInterrupt
    monkeypatch.setattr(cli, "build_parser", interrupted)
    assert cli.main(["paper", "-o", "x"]) == 130
    err = capsys.readouterr().err
    assert err == "aacmm: error: interrupted; nothing written\n", err


@pytest.mark.parametrize("command", [["tip", "p.csv", "--arm", "aacmm7", "-o"], ["paper", "-o"],
                                     ["urdf", "aacmm7", "-o"], ["view", "p.csv", "--arm", "aacmm7", "--html"],
                                     ["examples"]])
def test_output_dash_is_refused(tmp_path, capsys, monkeypatch, command):
    """`aacmm tip ... -o -` (standard output meant) wrote a file named "-" in the current folder (`view --html -`,
    `examples -` too), exit 0 -> 2."""
    monkeypatch.chdir(tmp_path)
    rc, err = _run([*command, "-"], capsys)
    assert rc == 2 and "'-' (standard output) is not an output of the toolkit" in err, err
    assert not (tmp_path / "-").exists()


def test_an_effect_given_twice_is_named_at_the_option(tmp_path, capsys):
    """``--effect X --effect X`` is refused at the option (it named the arm file, as if the arm declared it twice);
    nothing written."""
    seats = ROOT / "examples" / "data" / "real-panda-seats"
    out = tmp_path / "out"
    rc, err = _run(["calibrate", seats / "front" / "points.csv", seats / "artefacts.toml", "--arm",
                    seats / "panda-with-inertials.urdf", "--tip-frame", "ball_link", "--effect", "eccentricity",
                    "--effect", "eccentricity", "-o", out], capsys)
    assert rc == 2 and "argument --effect: eccentricity given more than once" in err and ".urdf" not in err
    assert not out.exists()
