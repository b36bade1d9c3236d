"""Reliability, round 9: what a hostile-input audit of every subcommand found after round 8 (each test named after
its finding; all fast: no fit, a few points). The audit's driver fed every reader of every command empty files,
header-only files, BOMs, CRLF, tabs, duplicated and unknown columns and keys, NaN/inf/1e308/-0/huge integers, wrong
TOML types, long lines, non-UTF-8 bytes, garbage, a folder, /dev/null, a FIFO, a missing file and symbolic-link loops
in place of each file, and hostile live streams (stdin, TCP, UDP: cut mid-line, garbage between good lines)."""
from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest

from arm_model.checks import RADIAN_LIKE_RAD, JointLimitTally, radians_warning
from conftest import NOMINAL, ROOT, exit_status

QCOLS = ",".join(f"q{k}_deg" for k in range(1, 8))
DEG = ("deg",) * 7
RING = ROOT / "examples" / "data" / "paper-ring-xyz"


def _run(argv, capsys):
    rc = exit_status([str(a) for a in argv])
    return rc, capsys.readouterr().err


def _points(tmp_path, rows, name="p.csv"):
    path = tmp_path / name
    path.write_text(f"measurement,feature,{QCOLS}\n" + "".join(r + "\n" for r in rows))
    return path


# ---------------------------------------------------------------------------------------------
# a loop of symbolic links where a model file names its covariance or training-poses file

MODEL = """name = "m"
convention = "dh"
{joints}
[probe]
x_mm = 0.0
y_mm = 0.0
z_mm = 85.0
ball_diameter_mm = 4.0
max_force_N = 13.0
bending_compliance_mm_per_N = 0.0142
axial_compliance_mm_per_N = 8.76e-05

[calibration]
covariance = "cov.csv"
model_discrepancy_um = 1.0
model_discrepancy_growth_um_per_mm = 0.01
training_poses = "poses.csv"
"""


@pytest.mark.parametrize("looped", ["cov.csv", "poses.csv"])
def test_a_link_loop_at_a_file_the_model_file_names_is_exit_2(tmp_path, capsys, looped):
    """`covariance = "cov.csv"` (or `training_poses`) where cov.csv is a symbolic link to itself was an internal
    error (exit 3, RuntimeError of Path.resolve before Python 3.13); now exit 2 naming the link, nothing written.
    One helper resolves every user path (`arm_model.errors.resolved`)."""
    joints = NOMINAL.read_text().split("[[joint]]", 1)[1].split("[probe]")[0]
    (tmp_path / "m.toml").write_text(MODEL.format(joints="[[joint]]" + joints))
    (tmp_path / "cov.csv").write_text("parameter,unit,value,u,j1.d\nj1.d,mm,0,0.001,1\n")
    _points(tmp_path, ["m,f,10,20,30,40,50,60,70"], "poses.csv")
    (tmp_path / looped).unlink()
    os.symlink(looped, tmp_path / looped)
    pts = _points(tmp_path, ["m,f,10,20,30,40,50,60,70"])
    rc, err = _run(["tip", pts, "--arm", tmp_path / "m.toml", "--covariance", "-o", tmp_path / "t.csv"], capsys)
    assert rc == 2 and f"{looped}: cannot follow the path: a loop of symbolic links" in err, err
    assert "internal error" not in err and not (tmp_path / "t.csv").exists()


def test_a_link_loop_as_holdout_points_is_exit_2(tmp_path, capsys):
    os.symlink("h.csv", tmp_path / "h.csv")
    pts = tmp_path / "p.csv"
    pts.write_text("\n".join((RING / "points.csv").read_text().splitlines()[:41]) + "\n")
    rc, err = _run(["calibrate", pts, RING / "artefacts.toml", "--arm", "aacmm7", "--holdout-points",
                    tmp_path / "h.csv", "-o", tmp_path / "o"], capsys)
    assert rc == 2 and "h.csv" in err and "internal error" not in err, err
    assert not (tmp_path / "o").exists()


# ---------------------------------------------------------------------------------------------
# angles written in radians under the _deg columns

def test_angles_in_radians_are_warned_by_tip(tmp_path, capsys):
    """Every angle within +-2 pi degrees (radians written in degree columns: values tiny) was read without a word;
    tip (and every command that reads points: `arm_model.checks.point_warnings`) now warns, naming the file and the
    lines, and uses the angles as the columns say."""
    rows = [f"m,f,{','.join(repr(math.radians(a)) for a in (10 + k, 20, 30, 40, 50, 60, 70 - k))}" for k in range(5)]
    pts = _points(tmp_path, rows)
    rc, err = _run(["tip", pts, "--arm", "aacmm7", "-o", tmp_path / "t.csv"], capsys)
    assert rc == 0 and "were the angles written in radians?" in err and "p.csv lines 2, 3, 4, 5, 6" in err, err
    rc, err = _run(["tip", _points(tmp_path, ["m,f,10,20,30,40,50,60,70", "m,f,1,2,3,4,5,6,7"], "q.csv"), "--arm",
                    "aacmm7", "-o", tmp_path / "u.csv"], capsys)
    assert rc == 0 and "radians" not in err, err
    rad = tmp_path / "r.csv"                    # the same numbers under _rad columns are what the file says
    rad.write_text(pts.read_text().replace("_deg", "_rad"))
    rc, err = _run(["tip", rad, "--arm", "aacmm7", "-o", tmp_path / "w.csv"], capsys)
    assert rc == 0 and "radians" not in err, err


def test_the_radians_tally_over_blocks_agrees_with_the_whole(nominal):
    """tip reads a big file in blocks, in parallel parts: the tally merged over parts gives the warning of the whole
    file, and one block with a real angle clears it."""
    rng = np.random.default_rng(0)
    q = rng.uniform(-0.9, 0.9, (40, 7)) * RADIAN_LIKE_RAD
    lines = np.arange(2, 42)
    whole = radians_warning(nominal, q, lines, "p.csv", DEG)
    assert whole is not None and whole.count == 40
    parts = [JointLimitTally(nominal, "p.csv") for _ in range(2)]
    parts[0].add(q[:25], lines[:25], DEG)
    parts[1].add(q[25:], lines[25:], DEG)
    parts[0].merge(parts[1])
    (w,) = parts[0].warnings()
    assert w.message == whole.message and w.lines == whole.lines
    q[30, 2] = math.radians(45.0)
    late = JointLimitTally(nominal, "p.csv")
    late.add(q[:25], lines[:25], DEG)
    late.add(q[25:], lines[25:], DEG)
    assert late.warnings() == [] and radians_warning(nominal, q, lines, "p.csv", DEG) is None
    q[30, 2] = 0.0
    assert radians_warning(nominal, q, lines, "p.csv", ("rad",) * 7) is None       # radians where the file says so
    assert radians_warning(nominal, q[:2], lines[:2], "p.csv", DEG) is None        # two poses near the straight arm



def test_input_warnings_are_said_before_a_fit_can_fail(tmp_path, capsys):
    """calibrate, close-loop and study poses logged the input warnings (radians, over-force, joint limits) only with
    their results: a fit that then failed (Levenberg-Marquardt on radians read as degrees: exit 4) or a later
    refusal left the user without the one hint that explains it. They are logged as soon as the points are read."""
    rows = (RING / "points.csv").read_text().splitlines()
    head = rows[0].split(",")
    deg = [k for k, c in enumerate(head) if c.endswith("_deg")]
    out = [rows[0]]
    for r in rows[1:41]:
        cells = r.split(",")
        for k in deg:
            cells[k] = repr(math.radians(float(cells[k])))
        out.append(",".join(cells))
    pts = tmp_path / "rad.csv"
    pts.write_text("\n".join(out) + "\n")
    rc, err = _run(["study", "poses", pts, RING / "artefacts.toml", "--arm", "aacmm7", "--count", "5", "-o",
                    tmp_path / "o"], capsys)
    assert rc == 2 and "--count 5: the points file has 1 measurement(s)" in err, err
    assert err.index("were the angles written in radians?") < err.index("error:"), err


# ---------------------------------------------------------------------------------------------
# stated uncertainties that weight a fit; the simulator's encoder step

DISTANCE = ('feature = [{ id = "a", kind = "sphere", diameter_mm = 25.0 }, { id = "b", kind = "sphere", '
            'diameter_mm = 25.0 }]\n[[distance]]\nbetween = ["a", "b"]\nlength_mm = 600.0\n')


@pytest.mark.parametrize("line, ok", [
    ("u_length_mm = 1e-320", False), ("u_length_mm = 1e-300", False), ("u_length_um = 1e-9", False),
    ("u_length_m = 0.2", False), ("u_length_mm = 1e-9", True), ("u_length_um = 0.5", True),
])
def test_a_certified_distance_u_is_a_usable_weight(line, ok):
    """`u_length_mm = 1e-300` was accepted (> 0) and calibrate then died inside LAPACK (exit 3, "SVD did not
    converge", numpy overflow lines). A distance's u weights the fit as --sigma-length-um does, so it keeps the
    option's range, one constant (`arm_model.units.STATED_SIGMA_M`: 1 pm to 100 mm), at its line and key."""
    from arm_model import InputError
    from arm_model.io import parse_artefacts
    text = DISTANCE + line + "\n"
    if ok:
        assert parse_artefacts(text, "a.toml").distances[0].u_length > 0
    else:
        with pytest.raises(InputError, match=r"a.toml, line 5, key 'distance\[1\].u_length_.*must be in \[1e-"):
            parse_artefacts(text, "a.toml")


@pytest.mark.parametrize("text, ok, where", [
    (DISTANCE.replace("length_mm = 600.0", "length_mm = 1e-320"), False, r"line 4, key 'distance\[1\].length_mm'"),
    (DISTANCE.replace("length_mm = 600.0", "length_um = 0.5"), False, r"line 4, key 'distance\[1\].length_um'"),
    (DISTANCE.replace("length_mm = 600.0", "length_um = 1.0"), True, None),
    (DISTANCE.replace("diameter_mm = 25.0 }, {", "diameter_mm = 1e-320 }, {"), False, "diameter_mm"),
    (DISTANCE.replace("diameter_mm = 25.0 }, {", "diameter_um = 0.9 }, {"), False, "diameter_mm"),
    (DISTANCE.replace("diameter_mm = 25.0 }, {", "diameter_um = 1.0 }, {"), True, None),
])
def test_an_artefact_smaller_than_a_micrometre_is_refused_at_its_key(text, ok, where):
    """A diameter or a certified distance of 1e-320 mm was accepted (> 0) and the fit ran 800 iterations to exit 4;
    below 1 um (`arm_model.units.SMALLEST_ARTEFACT_M`) nothing is an artefact a ball probes: refused at its key."""
    from arm_model import InputError
    from arm_model.io import parse_artefacts
    if ok:
        parse_artefacts(text, "a.toml")
    else:
        with pytest.raises(InputError, match=rf"a\.toml, .*{where}.*below 0\.001 mm"):
            parse_artefacts(text, "a.toml")

def test_calibrate_with_a_tiny_distance_u_is_exit_2(tmp_path, capsys):
    art = tmp_path / "a.toml"
    art.write_text(DISTANCE + "u_length_mm = 1e-300\n")
    pts = _points(tmp_path, ["m,a,10,20,30,40,50,60,70"])
    rc, err = _run(["calibrate", pts, art, "--arm", "aacmm7", "-o", tmp_path / "o"], capsys)
    assert rc == 2 and "a.toml, line 5" in err and "internal error" not in err, err


@pytest.mark.parametrize("step, ok", [("1e-320", False), ("1e-10", False), ("0", True), ("1e-9", True)])
def test_the_simulated_encoder_step_is_0_or_a_real_step(step, ok):
    """`[noise] encoder_resolution_deg = 1e-320` quantised every reading to infinity; simulate then refused its
    own points file as bad input, naming `points.csv` the user never gave (exit 2). The step is 0 or >= 1e-9 deg."""
    from arm_model import InputError
    from arm_model.sim import campaign_from_dict
    data = {"seed": 1, "noise": {"encoder_resolution_deg": float(step)},
            "task": [{"kind": "seat", "articulations": 3}]}
    if ok:
        campaign_from_dict(data)
    else:
        with pytest.raises(InputError, match="encoder_resolution.*must be 0 .*or at least 1e-09 deg"):
            campaign_from_dict(data)


def test_a_simulated_points_file_its_reader_refuses_is_an_internal_error():
    """Whatever else would make the simulator write a points file its reader refuses is the simulator's bug
    (exit 3, docs/guarantees.md section 1b), never an input error about a file the user did not give."""
    from arm_model.readback import UnreadableOutput
    from arm_model.sim.run import _own_points
    with pytest.raises(UnreadableOutput, match="points.csv: the simulated points file is refused.*finite"):
        _own_points(f"measurement,feature,{QCOLS}\nm,f,inf,0,0,0,0,0,0\n", "points.csv", None)


# ---------------------------------------------------------------------------------------------
# an empty argument

@pytest.mark.parametrize("argv", [
    ["examples", ""], ["tip", "", "--arm", "aacmm7", "-o", "t.csv"], ["tip", "p.csv", "--arm=", "-o", "t.csv"],
    ["simulate", "c.toml", "-o", ""],
])
def test_an_empty_argument_is_refused(tmp_path, capsys, monkeypatch, argv):
    """`aacmm examples ""` (a script's "$DIR" of an unset variable) copied the examples into the current folder:
    "" is "." to every path. Every empty argument is now refused before anything is read or written."""
    monkeypatch.chdir(tmp_path)
    rc, err = _run(argv, capsys)
    assert rc == 2 and "an empty argument" in err and "unset shell variable" in err, err
    assert list(tmp_path.iterdir()) == []


def test_a_residual_of_an_unknown_kind_is_refused():
    """`view --residuals`: a `kind` of `abc` (or `refrence`) was read and drawn as a feature's residual; `reference`
    changes where a vector starts, so a typo changed the drawing without a word. One word of the known kinds."""
    from arm_model import InputError
    from viz.residuals import parse_residuals
    head = "measurement,feature,kind,line,residual_um,dx_um,dy_um,dz_um,standardized\n"
    assert list(parse_residuals(head + "m,f,reference,2,1,1,0,0,0.5\nm,f,,3,1,1,0,0,0.5\n", "r.csv").kind) == [
        "reference", ""]
    with pytest.raises(InputError, match=r"r.csv, line 3, column 'kind': unknown kind 'refrence'"):
        parse_residuals(head + "m,f,seat,2,1,1,0,0,0.5\nm,f,refrence,3,1,1,0,0,0.5\n", "r.csv")


@pytest.mark.parametrize("section, key, value, words", [
    ("noise", "probing_repeatability_um", 1e9, "'probing_repeatability' must be at most 100 mm"),
    ("noise", "temperature_noise_C", 1000.0, "'temperature_noise' must be at most 10 C"),
    ("noise", "encoder_noise_deg", 11.0, "'encoder_noise' must be at most 10 deg"),
    ("noise", "force_noise_N", 1e4, "'force_noise' must be at most 1000 N"),
])
def test_a_simulated_noise_beyond_any_instrument_is_refused(section, key, value, words):
    """A probing noise of 1 km or a temperature noise of 1000 C made simulate write readings its own readers refuse
    (angles beyond 10 000 deg, temperatures below absolute zero): an internal error. The campaign's [noise] is
    bounded where it is read, at its key."""
    from arm_model import InputError
    from arm_model.sim import campaign_from_dict
    with pytest.raises(InputError, match=f"key '{section}.{key.rsplit('_', 1)[0]}.*{words}"):
        campaign_from_dict({"seed": 1, section: {key: value}, "task": [{"kind": "seat", "articulations": 3}]})


@pytest.mark.parametrize("key", ["length_error_um", "angle_error_deg", "probe_error_um"])
def test_a_negative_zero_in_a_campaign_is_zero(tmp_path, capsys, key):
    """`[truth] length_error_um = -0.0` passed the "not negative" check and numpy's random draw refused it ("scale
    < 0": exit 3). Every number of a campaign is read with -0.0 as 0."""
    camp = tmp_path / "c.toml"
    camp.write_text(f'seed = 1\nsensor = "none"\n[signals]\nenabled = false\n[truth]\n{key} = -0.0\n'
                    '[[task]]\nkind = "seat"\narticulations = 3\n')
    rc, err = _run(["simulate", camp, "-o", tmp_path / "o"], capsys)
    assert rc == 0 and "internal error" not in err, err


# ---------------------------------------------------------------------------------------------
# a live stream that never starts

def test_live_a_stream_that_sends_no_header_stops_after_idle(tmp_path, capsys):
    """`live udp://...` (or a TCP server that accepts and stays silent) with `--stop-after-idle-s 0.3` waited for
    its header for ever: the idle limit only counted once the session had begun. No line for that long before the
    header is exit 2, nothing written."""
    out = tmp_path / "s"
    rc, err = _run(["live", "udp://127.0.0.1:0", "--arm", "aacmm7", "--feature", "plane:p", "--stop-after-idle-s",
                    "0.3", "-o", out], capsys)
    assert rc == 2 and "no line came for 0.3 s (--stop-after-idle-s): the stream sent no header" in err, err
    assert not out.exists()


def test_live_reads_standard_input_redirected_from_a_file(tmp_path):
    """`aacmm live - < samples.csv` (or `< /dev/null`) stopped at once with "Operation not permitted" and no file
    named: epoll refuses a regular file. Standard input from a file (here its descriptor, as `live -` reads fd 0) is
    read as any stream, to its end."""
    from arm_model.live.sources import _FdSource
    path = tmp_path / "samples.csv"
    path.write_bytes(b"time_s,q1_deg\r\n0,1\n0.001,2")
    for file, want in ((path, [(1, b"time_s,q1_deg"), (2, b"0,1"), (3, b"0.001,2")]), (Path(os.devnull), [])):
        fd = os.open(file, os.O_RDONLY)
        try:
            assert [x for x in _FdSource(fd, "<stdin>").lines() if x is not None] == want
        finally:
            os.close(fd)


@pytest.mark.parametrize("option", ["--scale", "--residual-scale", "--ellipsoid-scale"])
def test_a_drawing_scale_that_draws_nothing_is_refused(tmp_path, capsys, option):
    """`view --residual-scale 1e-320` wrote a page whose arrows were all 0 long; every scale is 0.001 to 1e9."""
    out = tmp_path / "v.html"
    rc, err = _run(["view", _points(tmp_path, ["m,f,10,20,30,40,50,60,70"]), "--arm", "aacmm7", option, "1e-320",
                    "--html", out], capsys)
    assert rc == 2 and f"argument {option}: must be in [0.001, 1e+09], got 1e-320" in err, err
    assert not out.exists()
