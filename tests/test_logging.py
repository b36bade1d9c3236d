"""One way to talk: -q/--quiet and -v/--verbose on every subcommand (defined once in arm_model/cli.py),
messages through `logging`, progress without carriage returns when standard error is not a terminal."""
from __future__ import annotations

import io
import logging
import subprocess
import sys

import pytest
from test_reliability_inputs import RING, run

from arm_model.cli import COMMANDS, build_parser, main
from arm_model.log import Progress, console, counted
from conftest import NOMINAL, ROOT


def _subcommand_parsers(parser):
    for action in parser._actions:
        if hasattr(action, "choices") and isinstance(action.choices, dict):
            for name, sub in action.choices.items():
                yield name, sub
                yield from _subcommand_parsers(sub)


def test_every_subcommand_accepts_quiet_and_verbose():
    names = []
    for name, sub in _subcommand_parsers(build_parser()):
        opts = {o for a in sub._actions for o in a.option_strings}
        assert {"-q", "--quiet", "-v", "--verbose"} <= opts, name
        names.append(name)
    assert set(COMMANDS) <= set(names) and {"montecarlo", "poses"} <= set(names)


@pytest.mark.parametrize("where", ["before", "after"])
def test_quiet_silences_tip_and_keeps_the_output(tmp_path, capsys, where):
    args = ["tip", RING / "points.csv", "--arm", NOMINAL, "-o", tmp_path / "t.csv"]
    code, out, err = run(["-q", *args] if where == "before" else [*args, "--quiet"], capsys)
    assert code == 0 and out == "" and err == ""
    assert len((tmp_path / "t.csv").read_text().splitlines()) == 1225          # header + 1224 points
    code, out, err = run(args, capsys)
    assert code == 0 and out.startswith("1224 points in 17 measurement(s)") and "deflection: mean" in out
    assert "debug:" not in out + err


def test_quiet_silences_urdf_examples_and_simulate(tmp_path, capsys):
    for argv in (["urdf", NOMINAL, "-o", tmp_path / "a.urdf"],
                 ["examples", tmp_path / "ex"],
                 ["simulate", ROOT / "examples" / "campaigns" / "paper-ring.toml", "--no-signals",
                  "-o", tmp_path / "sim"]):
        code, out, err = run([*argv, "-q"], capsys)
        assert (code, out, err) == (0, "", ""), argv[0]
    # without -q the same commands talk (simulate: progress on stderr, summary on stdout)
    code, out, err = run(["simulate", ROOT / "examples" / "campaigns" / "paper-ring.toml", "--no-signals",
                          "-o", tmp_path / "sim"], capsys)
    assert code == 0 and "campaign 'paper-ring'" in out and "inverse kinematics on the true arm" in err
    assert "\r" not in err and err.lstrip().startswith("[")


def test_quiet_keeps_warnings_on_stderr(tmp_path, capsys):
    lines = (RING / "points.csv").read_text().splitlines()[:4]
    k = lines[0].split(",").index("fx_N")
    cells = lines[2].split(",")
    cells[k] = "40.0"
    lines[2] = ",".join(cells)
    (tmp_path / "p.csv").write_text("\n".join(lines) + "\n")
    code, out, err = run(["tip", tmp_path / "p.csv", "--arm", NOMINAL, "-o", tmp_path / "t.csv", "-q"], capsys)
    assert code == 0 and out == ""
    assert err.startswith("warning: 1 point(s) over the probe's calibrated force range (13 N)") and "lines 3" in err


def test_verbose_adds_debug_lines(tmp_path, capsys):
    code, out, err = run(["tip", RING / "points.csv", "--arm", NOMINAL, "-o", tmp_path / "t.csv", "-v"], capsys)
    assert code == 0 and out.startswith("1224 points in 17 measurement(s)")    # the summary as without -v
    debug = [ln for ln in err.splitlines() if ln.startswith("debug: ")]
    assert any("1224 point row(s) read" in ln and "points.csv" in ln for ln in debug)
    assert any("'aacmm7', 7 joints" in ln for ln in debug)
    assert any(f"{tmp_path / 't.csv'}: written" in ln for ln in debug)
    assert any("aacmm tip: done in" in ln for ln in debug)


def test_quiet_and_verbose_together_are_refused(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["tip", "x.csv", "--arm", str(NOMINAL), "-o", "y.csv", "-q", "-v"])
    assert exc.value.code == 2 and "not allowed with" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["-q", "tip", "x.csv", "--arm", str(NOMINAL), "-o", "y.csv", "-v"])
    assert exc.value.code == 2 and "exclude each other" in capsys.readouterr().err


def test_errors_go_to_stderr_with_exit_2_even_quiet(tmp_path, capsys):
    code, out, err = run(["tip", tmp_path / "missing.csv", "--arm", NOMINAL, "-o", tmp_path / "t.csv", "-q"], capsys)
    assert code == 2 and out == ""
    assert err == (f"aacmm tip: error: {tmp_path / 'missing.csv'}: cannot read the points file: "
                   "No such file or directory\n")


def test_the_loggers_are_left_as_they_were(tmp_path, capsys):
    before = [(logging.getLogger(n).level, list(logging.getLogger(n).handlers)) for n in ("arm_model", "viz")]
    run(["urdf", NOMINAL, "-o", tmp_path / "a.urdf", "-v"], capsys)
    assert [(logging.getLogger(n).level, list(logging.getLogger(n).handlers)) for n in ("arm_model", "viz")] == before


class _Tty(io.StringIO):
    def isatty(self):
        return True


def test_progress_redraws_on_a_terminal(capsys):
    buf = _Tty()
    with console(logging.INFO):
        bar = Progress(4, "runs", stream=buf, width=8)
        for _ in range(4):
            bar.update()
    text = buf.getvalue()
    assert text.count("\r") == 5 and "runs [........] 0/4" in text and "runs [########] 4/4" in text
    assert text.endswith("\n") and capsys.readouterr() == ("", "")


def test_progress_in_a_file_has_plain_lines(capsys):
    with console(logging.INFO):
        bar = Progress(25, "runs", stream=io.StringIO())        # not a terminal
        for _ in range(25):
            bar.update()
    out, err = capsys.readouterr()
    assert out == "" and "\r" not in err
    steps = [ln.split("] ", 1)[1] for ln in err.splitlines()]
    # the first step past every 10 %, then the last
    assert steps == [f"runs {k}/25 ({100 * k / 25:.0f} %)" for k in (1, 3, 5, 8, 10, 13, 15, 18, 20, 23, 25)]
    with console(logging.WARNING):                                 # --quiet
        bar = Progress(3, "runs", stream=_Tty())
        bar.update(3)
    assert capsys.readouterr() == ("", "") and not bar.enabled


def test_study_progress_into_a_log_file_has_no_carriage_return(tmp_path):
    """A real command, its standard error a file (as `aacmm ... 2> log`). The campaign: a quick synthetic one
    (arm_model.sim.quick, 0.3 s of CPU; the simulator's campaign of test_reliability_inputs cost this module 3 s
    more): what is checked is the progress lines, not the study."""
    from arm_model import load_description
    from arm_model.model import ArmModel
    from arm_model.sim.quick import SynthSpec, make_campaign
    small = tmp_path / "small"
    make_campaign(ArmModel(load_description(NOMINAL)), SynthSpec(ballbars=4, seats=2, articulations=6, spheres=2,
                                                                 sphere_points=8), seed=5).write(small)
    log = tmp_path / "log.txt"
    with open(log, "w") as fh:
        r = subprocess.run([sys.executable, "-m", "arm_model.cli", "study", "poses", str(small / "points.csv"),
                            str(small / "artefacts.toml"), "--arm", str(NOMINAL), "--count", "4",
                            "-o", str(tmp_path / "o")], stdout=subprocess.PIPE, stderr=fh, text=True, cwd=ROOT)
    text = log.read_text()
    assert r.returncode == 0, text
    assert "\r" not in text and "selecting 4/4 (100 %)" in text
    assert "chosen measurements" in r.stdout


@pytest.mark.parametrize("n, word, plural, expect", [
    (0, "point", None, "0 points"), (1, "point", None, "1 point"), (2, "point", None, "2 points"),
    (1, "training point", None, "1 training point"), (1, "analysis", "analyses", "1 analysis"),
    (3, "analysis", "analyses", "3 analyses"),
])
def test_counted_puts_the_noun_in_the_right_number(n, word, plural, expect):
    assert counted(n, word, plural) == expect


def test_a_library_warning_is_one_console_line_without_its_source(capsys):
    """numpy's overflow (and any Python warning) inside a command: one ``warning:`` line, no file path or
    source line (those only with -v); the previous ``showwarning`` restored afterwards."""
    import warnings

    import numpy as np
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        before = warnings.showwarning
        with console(logging.INFO):
            with np.errstate(over="warn"):
                np.array([1e308]) * 10.0
        err = capsys.readouterr().err
        assert err.splitlines() == ["warning: RuntimeWarning: overflow encountered in multiply"], err
        with console(logging.DEBUG):
            warnings.warn("plain", UserWarning, stacklevel=1)
        err = capsys.readouterr().err
        assert "warning: UserWarning: plain" in err and "test_logging.py" in err
        assert warnings.showwarning is before
