"""Reliability, round 3 (issue 22): non-regular outputs, the covariance file, folds beyond the data, disk
full, Ctrl-C after the output is published, stray lines on standard error, progress of a long Monte Carlo.
Each test is named after the item it checks; all are fast (a few points, no fit)."""
from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from arm_model.cli import main
from conftest import NOMINAL, ROOT

POINTS = ROOT / "examples" / "data" / "paper-ring-xyz" / "points.csv"


@pytest.fixture
def few_points(tmp_path) -> Path:
    """The first rows of the example ring campaign: tip on them takes milliseconds."""
    lines = POINTS.read_text(encoding="utf-8").splitlines()[:9]
    p = tmp_path / "in" / "points.csv"
    p.parent.mkdir()
    p.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return p


def tip(points, out, *more) -> int:
    return main(["tip", str(points), "--arm", str(NOMINAL), "-o", str(out), *more])


# ---------------------------------------------------------------------------------------------
# 1. outputs that are not regular files

def _device(path: Path) -> bool:
    try:
        os.mknod(path, 0o644 | stat.S_IFCHR, os.makedev(1, 3))      # the same device as /dev/null
        return True
    except (PermissionError, OSError):
        return False


@pytest.mark.parametrize("kind", ["fifo", "device", "dev-null", "link-to-fifo"])
def test_item1_non_regular_output_is_never_replaced(tmp_path, few_points, capsys, kind):
    target = tmp_path / "n"
    if kind == "fifo":
        os.mkfifo(target)
    elif kind == "device":
        if not _device(target):
            pytest.skip("mknod needs root (CAP_MKNOD)")
    elif kind == "dev-null":
        target = Path(os.devnull)
    else:
        os.mkfifo(tmp_path / "fifo")
        os.symlink("fifo", target)
    mode = os.stat(target).st_mode
    assert tip(few_points, target) == 2
    err = capsys.readouterr().err
    assert "is never replaced" in err and ("a device" in err or "FIFO" in err), err
    assert os.stat(target).st_mode == mode                  # still the device / FIFO
    assert not stat.S_ISREG(os.stat(target).st_mode)
    if kind != "dev-null":                                  # and nothing else written beside it
        assert {p.name for p in tmp_path.iterdir()} <= {"in", "n", "fifo"}


def test_item1_non_regular_output_folder_is_refused(tmp_path, capsys):
    os.mkfifo(tmp_path / "n")
    assert main(["paper", "-o", str(tmp_path / "n")]) == 2
    assert "FIFO" in capsys.readouterr().err
    assert stat.S_ISFIFO(os.stat(tmp_path / "n").st_mode)


def test_item1_output_through_a_link_replaces_its_target_not_the_link(tmp_path, few_points, capsys):
    """A link to a regular file is written through (as the shell's > does): the link stays a link. (As
    root, replacing the link itself would replace e.g. /dev/stdout with a regular file.)"""
    (tmp_path / "real.csv").write_text("old\n")
    os.symlink("real.csv", tmp_path / "link.csv")
    assert tip(few_points, tmp_path / "link.csv") == 0
    assert (tmp_path / "link.csv").is_symlink()
    assert (tmp_path / "real.csv").read_text().startswith("measurement,")


# ---------------------------------------------------------------------------------------------
# 2. the covariance file beside a model file

GOOD_COV = ("parameter,unit,value,u,j2.d,j3.a\n"
            "j2.d,um,{v},{u},1,{c}\n"
            "j3.a,um,-3,2,{c},1\n")


def _model_with_covariance(tmp_path: Path, **cells) -> Path:
    cov = dict(v="12.5", u="4", c="0.25") | cells
    d = tmp_path / "model"
    d.mkdir(exist_ok=True)
    (d / "cov.csv").write_text(GOOD_COV.format(**cov), encoding="utf-8")
    model = d / "arm.toml"
    model.write_text(NOMINAL.read_text(encoding="utf-8") + '\n[calibration]\ncovariance = "cov.csv"\n',
                     encoding="utf-8")
    return model


def test_item2_a_good_covariance_file_is_read(tmp_path, few_points, capsys):
    from arm_model.model_file import read_covariance
    cov = read_covariance(_model_with_covariance(tmp_path).parent / "cov.csv")
    assert cov.units == ("m", "m") and cov.lines == (2, 3)
    assert abs(cov.values[0] - 12.5e-6) < 1e-18 and abs(cov.matrix[0, 1] - 0.25 * 4e-6 * 2e-6) < 1e-24
    assert tip(few_points, tmp_path / "t.csv", "--uncertainty") == 0


@pytest.mark.parametrize("cells, line, column, words", [
    ({"u": "4", "v": "12.5"}, None, None, None),                                       # the good file (control)
    ({"v": "12.5,furlong"}, 2, "unit", "unknown unit 'furlong'"),
    ({"u": "-4"}, 2, "u", "must not be negative"),
    ({"v": "0_0"}, 2, "value", "expected a finite number, got '0_0'"),
    ({"u": "4_5"}, 2, "u", "expected a finite number, got '4_5'"),
    ({"v": "nan"}, 2, "value", "expected a finite number, got 'nan'"),
    ({"u": "inf"}, 2, "u", "expected a finite number, got 'inf'"),
    ({"u": "1e300"}, 2, "u", "not a plausible length"),
    ({"c": "1.5"}, 2, "j3.a", "in [-1, 1]"),
    ({"c": "nan"}, 2, "j3.a", "expected a finite number"),
])
def test_item2_covariance_file_cells_are_checked(tmp_path, few_points, capsys, cells, line, column, words):
    if "v" in cells and "," in cells["v"]:          # the unit column: rewrite the row's unit
        model = _model_with_covariance(tmp_path)
        cov = model.parent / "cov.csv"
        cov.write_text(cov.read_text().replace("j2.d,um,", "j2.d,furlong,"))
    else:
        model = _model_with_covariance(tmp_path, **cells)
    out = tmp_path / "t.csv"
    code = main(["tip", str(few_points), "--arm", str(model), "-o", str(out)])
    err = capsys.readouterr().err
    if words is None:
        assert code == 0, err
        return
    assert code == 2, err
    assert err.count("\n") == 1 and "overflow" not in err.lower() and "Warning" not in err, err
    assert f"cov.csv, line {line}, column '{column}': " in err and words in err, err
    assert not out.exists()


def test_item2_covariance_unit_must_match_the_parameter(tmp_path, few_points, capsys):
    model = _model_with_covariance(tmp_path)
    cov = model.parent / "cov.csv"
    cov.write_text(cov.read_text().replace("j2.d,um,", "j2.d,urad,"))
    assert main(["tip", str(few_points), "--arm", str(model), "-o", str(tmp_path / "t.csv")]) == 2
    assert "cov.csv, line 2, column 'unit': parameter 'j2.d' is a 'm' quantity" in capsys.readouterr().err


# ---------------------------------------------------------------------------------------------
# 5. disk full: the message names the file or folder

def test_item5_disk_full_names_the_output_file(tmp_path, few_points):
    """A real failed write: the file size limit (RLIMIT_FSIZE) makes every write past 200 bytes fail
    with EFBIG, as a full disk makes them fail with ENOSPC."""
    import resource
    import signal
    import subprocess
    import sys

    def limit():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (200, 200))

    out = tmp_path / "tips.csv"
    proc = subprocess.run([sys.executable, "-c", "import sys; from arm_model.cli import main; sys.exit(main())",
                           "tip", str(few_points), "--arm", str(NOMINAL), "-o", str(out)], preexec_fn=limit,
                          capture_output=True, text=True, cwd=tmp_path, timeout=120,
                          env=dict(os.environ, PYTHONDONTWRITEBYTECODE="1"))
    assert proc.returncode == 2, proc.stderr
    assert f"error: {out}: cannot write the output file: File too large; nothing written" in proc.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in"]


@pytest.mark.parametrize("filename", [None, "stage"])
def test_item5_disk_full_names_the_output_folder(tmp_path, filename):
    import errno

    from arm_model import InputError
    from arm_model.output import output_folder
    final = tmp_path / "out"
    with pytest.raises(InputError) as info:
        with output_folder(final, (), "demo") as out:
            (out.dir / "a.txt").write_text("a")
            name = None if filename is None else str(out.dir / "sub" / "b.png")
            raise OSError(errno.ENOSPC, "No space left on device", name)
    where = final if filename is None else final / "sub" / "b.png"
    assert str(info.value) == f"{where}: cannot write the output folder: No space left on device; nothing written"
    assert list(tmp_path.iterdir()) == []


def test_item5_an_input_error_inside_the_output_is_not_renamed(tmp_path):
    from arm_model import InputError
    from arm_model.output import output_folder
    with pytest.raises(InputError, match="^elsewhere.csv, line 3: bad$"):
        with output_folder(tmp_path / "out", (), "demo"):
            raise InputError("bad", "elsewhere.csv", 3)


# ---------------------------------------------------------------------------------------------
# 6. Ctrl-C after the output is published

@pytest.mark.parametrize("exc, code, word", [(KeyboardInterrupt, 130, "interrupted"),
                                             (ZeroDivisionError, 3, "internal error")])
def test_item6_interrupt_after_publishing_says_the_output_is_there(tmp_path, few_points, monkeypatch, capsys,
                                                                   exc, code, word):
    import arm_model.commands as commands

    def late(*a, **k):                       # the last step of tip, after its output is in place
        raise exc()

    monkeypatch.setattr(commands, "log_warnings", late)
    out = tmp_path / "tips.csv"
    assert tip(few_points, out) == code
    err = capsys.readouterr().err
    assert word in err and f"the output was already written completely: {out}" in err, err
    assert "nothing written" not in err
    assert len(out.read_text().splitlines()) == 9           # complete: the header and the 8 points


def test_item6_interrupt_before_publishing_says_nothing_written(tmp_path, few_points, monkeypatch, capsys):
    import arm_model.commands as commands

    def early(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(commands, "tip_table", early)
    assert tip(few_points, tmp_path / "tips.csv") == 130
    assert "interrupted; nothing written" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in"]


def test_item6_files_written_inside_an_output_folder_are_not_outputs_of_their_own(tmp_path):
    from arm_model.io import atomic_write_text
    from arm_model.output import output_folder, published_outputs
    written = []
    with published_outputs(written):
        with output_folder(tmp_path / "out", (), "demo") as out:
            atomic_write_text(out.dir / "a.txt", "a")
            assert written == []
    assert written == [tmp_path / "out"]


# ---------------------------------------------------------------------------------------------
# 7. no line on standard error that the project did not write; names escaped

ENTITY_URDF = """<?xml version="1.0"?>
<!DOCTYPE robot [
<!ENTITY % ext SYSTEM "http://127.0.0.1:9/evil.dtd">
%ext;
]>
<robot name="r">
  <link name="base"/>
  <link name="tip"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="tip"/><origin xyz="0 0 0.5"/>
    <axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
</robot>
"""


@pytest.mark.parametrize("doctype", [
    '<!DOCTYPE robot [\n<!ENTITY % ext SYSTEM "http://127.0.0.1:9/evil.dtd">\n%ext;\n]>',
    '<!DOCTYPE robot [\n<!ENTITY name "r2">\n]>',
    '<!DOCTYPE robot SYSTEM "file:///etc/passwd">',
])
def test_item7_urdf_with_entities_is_one_error_and_no_library_line(tmp_path, few_points, capsys, doctype):
    urdf = tmp_path / "r.urdf"
    urdf.write_text(ENTITY_URDF.replace(ENTITY_URDF.splitlines()[1] + "\n" + "\n".join(ENTITY_URDF.splitlines()[2:5]),
                                        doctype))
    assert main(["tip", str(few_points), "--arm", str(urdf), "--tip-frame", "tip", "-o", str(tmp_path / "t.csv")]) == 2
    err = capsys.readouterr().err
    assert err.splitlines() == [f"aacmm tip: error: {urdf}, line 2: a <!DOCTYPE> that declares entities or names an "
                                "external DTD: a URDF needs neither (entities could read other files or the network); "
                                "remove it"], err


def test_item7_a_plain_doctype_is_accepted(tmp_path):
    from arm_model.urdf_import import _parse_xml
    data = ENTITY_URDF.replace("\n".join(ENTITY_URDF.splitlines()[1:5]), "<!DOCTYPE robot>").encode()
    assert _parse_xml(tmp_path / "r.urdf", data).getroot().get("name") == "r"


def test_item7_library_log_records_go_through_the_console(capsys):
    import logging

    from arm_model.log import console
    with console():
        logging.getLogger("yourdfpy.urdf").error("Entity 'ext' not defined\nUsing different parsing approach.")
        logging.getLogger("yourdfpy.urdf").info("not shown")
    assert capsys.readouterr().err == "error: Entity 'ext' not defined\\nUsing different parsing approach.\n"


@pytest.mark.parametrize("where", ["points", "output", "option"])
def test_item7_control_characters_in_names_are_escaped(tmp_path, few_points, capsys, where):
    name = "x\nwarning: forged\x1b[31m\u2028.csv"
    evil = tmp_path / name
    args = {"points": [str(evil), "--arm", str(NOMINAL), "-o", str(tmp_path / "t.csv")],
            "output": [str(few_points), "--arm", str(NOMINAL), "-o", str(tmp_path / "d" / name)],
            "option": [str(few_points), "--arm", str(NOMINAL), "--mc", name, "-o", str(tmp_path / "t.csv")]}[where]
    if where == "output":
        (tmp_path / "d").mkdir()
        os.mkfifo(tmp_path / "d" / name)            # refused (item 1): the error names it
    with pytest.raises(SystemExit, match="2"):      # a path naming it is refused by the path type (argparse's exit 2)
        main(["tip", *args])
    err = capsys.readouterr().err
    lines = [s for s in err.splitlines() if not s.startswith(("usage:", " "))]
    assert len(lines) == 1 and lines[0].startswith("aacmm tip: error:"), err
    assert "\x1b" not in err and "\u2028" not in err and "\\n" in err
    # the option's value is quoted escaped; a path is named by its first characters and the character it holds
    assert ("\\x1b[31m" if where == "option" else "one line of text without control characters") in err


# ---------------------------------------------------------------------------------------------
# 4. more folds than poses

def test_item4_close_loop_folds_beyond_the_poses_are_refused(tmp_path, capsys):
    lines = POINTS.read_text(encoding="utf-8").splitlines()
    pts = tmp_path / "points.csv"
    pts.write_text("\n".join(lines[:61]) + "\n", encoding="utf-8")             # 60 poses
    out = tmp_path / "loop"
    assert main(["close-loop", str(pts), str(POINTS.parent / "artefacts.toml"), "--arm", str(NOMINAL),
                 "--fold-by", "pose", "--folds", "1000", "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "--folds 1000: the data hold 60 poses" in err and "at most 60 folds" in err, err
    assert not out.exists()


def test_item4_folds_up_to_the_poses_pass_the_check():
    import numpy as np

    from arm_model import InputError
    from arm_model.io import PointSet
    from calibration.loop_cli import _check_folds
    feature = np.array(["ring"] * 5 + [""] * 3, dtype=object)
    points = PointSet(path="p.csv", measurement=np.array(["m"] * 8, dtype=object), feature=feature,
                      q=np.zeros((8, 7)), lines=np.arange(2, 10))
    _check_folds(5, points, None)
    with pytest.raises(InputError, match="5 poses"):
        _check_folds(6, points, None)
    _check_folds(7, points, points.select(np.arange(8) < 2))             # 2 reference points count too


# ---------------------------------------------------------------------------------------------
# 8. a long Monte Carlo shows its progress and the time left

def test_item8_monte_carlo_shows_progress_and_time_left(few_points, tmp_path, capsys):
    out = tmp_path / "t.csv"
    assert tip(few_points, out, "--mc", "3000") == 0
    steps = [s for s in capsys.readouterr().err.splitlines() if "Monte Carlo, 8 points: samples" in s]
    assert steps[0].endswith(("s left", "min left", "h left")) and "3/3000 (0 %), about " in steps[0], steps
    assert steps[-1].endswith("samples 3000/3000 (100 %)") and 10 <= len(steps) <= 13, steps
    assert tip(few_points, out, "--mc", "3000", "-q") == 0                  # --quiet: no progress
    assert capsys.readouterr().err == ""


def test_item8_progress_estimate_is_the_rate_so_far(monkeypatch):
    import logging

    import arm_model.log as _log
    clock = iter([0.0, 0.0, 10.0, 20.0])            # created (and drawn) at 0 s; 1/4 done at 10 s; 2/4 at 20 s
    monkeypatch.setattr(_log.time, "perf_counter", lambda: next(clock))
    records = []
    logger = logging.getLogger("test_item8")
    logger.setLevel(logging.INFO)
    logger.addHandler(type("H", (logging.Handler,), {"emit": lambda self, r: records.append(r.getMessage())})())
    bar = _log.Progress(4, "s", logger=logger, stream=None, estimate=True, every_pct=50)
    bar.update()
    bar.update()
    assert records == ["s 1/4 (25 %), about 30 s left", "s 2/4 (50 %), about 20 s left"]
