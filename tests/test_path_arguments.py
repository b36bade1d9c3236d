"""Every path of the command line (an input file, ``--arm``, ``--masses``, an output) has one argparse type,
:func:`arm_model.cli_options.path_arg`, which checks the text as given, whatever the spelling of its option
(``-o X``, ``-oX``, ``-o=X``, ``--output=X``, an abbreviation ``--out X``): a file given with a trailing ``/``
(``samples.csv/``) names a folder (pathlib drops the separator, so the file was read); a path with a line break, a
control, invisible or text-direction character, white space at its ends or a byte that is not UTF-8 cannot be named
by the outputs. Refused, exit 2, nothing written, never a traceback."""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, assume, given, settings, strategies as st

from arm_model.errors import InputError
from arm_model.io import read_points
from conftest import ROOT, exit_status

RING = ROOT / "examples" / "data" / "paper-ring-xyz" / "points.csv"
CAMPAIGN = ROOT / "examples" / "campaigns" / "calibration.toml"
PANDA = ROOT / "examples" / "data" / "real-panda-seats"


def _small_points(folder: Path) -> Path:
    """The ring's first 5 points, in ``folder``."""
    path = folder / "p.csv"
    path.write_text("\n".join(RING.read_text().splitlines()[:6]) + "\n")
    return path


def _listing(folder: Path) -> dict:
    return {str(p.relative_to(folder)): p.read_bytes() if p.is_file() else None for p in sorted(folder.rglob("*"))}


@pytest.mark.parametrize("where", ["points", "--arm", "--arm="])
def test_a_file_with_a_trailing_slash_is_refused_naming_it(tmp_path, capsys, where):
    arm = str(ROOT / "urdf" / "aacmm7.dh.toml")
    points, bad = (f"{RING}/", f"{RING}/") if where == "points" else (str(RING), f"{arm}/")
    arm_args = [f"--arm={bad}"] if where == "--arm=" else ["--arm", bad if where == "--arm" else arm]
    rc = exit_status(["tip", points, *arm_args, "-o", str(tmp_path / "t.csv")])
    err = capsys.readouterr().err
    assert rc == 2 and f"{bad!r}: Not a directory" in err and "Traceback" not in err, err
    assert list(tmp_path.iterdir()) == []


def test_a_reader_given_a_file_with_a_trailing_slash_refuses_it():
    with pytest.raises(InputError, match="Not a directory") as exc:
        read_points(f"{RING}/")
    assert exc.value.path == f"{RING}/"
    assert len(read_points(str(RING)).q) > 0


#: every spelling argparse takes for ``-o VALUE``: the value is checked whatever the spelling (the argv scan that
#: checked it before missed ``-oX/`` and ``-o=X/``)
SPELLINGS = [lambda v: ["-o", v], lambda v: [f"-o{v}"], lambda v: [f"-o={v}"], lambda v: [f"--output={v}"],
             lambda v: ["--out", v], lambda v: [f"--outp={v}"]]


@pytest.mark.parametrize("spell", SPELLINGS)
@pytest.mark.parametrize("command", ["tip", "urdf", "simulate", "calibrate"])
def test_an_output_given_with_a_trailing_slash_is_refused_in_every_spelling(tmp_path, capsys, monkeypatch, command,
                                                                           spell):
    """A file output (``tip -o t.csv/``): names a folder; a folder output over a file (``simulate -o afile/``): the
    system's "Not a directory". Both before any work, exit 2, nothing written."""
    monkeypatch.chdir(tmp_path)
    points = _small_points(tmp_path)
    (tmp_path / "afile").write_text("keep\n")
    before = _listing(tmp_path)
    argv, value = {"tip": (["tip", str(points), "--arm", "aacmm7"], "t.csv/"),
                   "urdf": (["urdf", "aacmm7"], "a.urdf/."),
                   "simulate": (["simulate", str(CAMPAIGN)], "afile/"),
                   "calibrate": (["calibrate", str(PANDA / "front" / "points.csv"), str(PANDA / "artefacts.toml"),
                                  "--arm", str(PANDA / "panda.urdf"), "--tip-frame", "ball_link"], "afile/")}[command]
    rc = exit_status([*argv, *spell(value)])
    err = capsys.readouterr().err
    assert rc == 2 and "Traceback" not in err, err
    if "ambiguous option: --out could match --output, --outlier-threshold" not in err:     # calibrate's --out
        assert "argument -o/--output: " in err, err
        assert ("Not a directory" in err) if value == "afile/" else ("which names a folder" in err), err
    assert _listing(tmp_path) == before


@pytest.mark.parametrize("argv", [
    ["tip", "{bad}", "--arm", "aacmm7", "-o", "t.csv"],
    ["tip", "{ok}", "--arm={bad}", "-o", "t.csv"],
    ["tip", "{ok}", "--arm", "aacmm7", "--mass={bad}", "-o", "t.csv"],
    ["tip", "{ok}", "--arm", "aacmm7", "-o{bad}"],
    ["urdf", "{bad}", "-o", "a.urdf"],
    ["simulate", "{bad}", "-o", "out"],
    ["simulate", str(CAMPAIGN), "--outp={bad}"],
    ["examples", "{bad}"],
    ["view", "{bad}", "--arm", "aacmm7", "--html", "v.html"],
    ["view", "{ok}", "--arm", "aacmm7", "--residuals", "{bad}", "--html", "v.html"],
    ["ring", "{ok}", "{bad}", "--arm", "aacmm7", "-o", "out"],
    ["ring", "{ok}", "{ok}", "--arm", "aacmm7", "--signals", "{bad}", "-o", "out"],
    ["paper", "--table2", "{bad}", "-o", "out"],
    ["calibrate", "{ok}", "{ok}", "--arm", "aacmm7", "--holdout-points", "{bad}", "-o", "out"],
    ["close-loop", "{ok}", "{ok}", "--arm", "aacmm7", "--reference-points={bad}", "-o", "out"],
    ["study", "montecarlo", "{bad}", "-o", "out"],
    ["live", "{bad}", "--arm", "aacmm7", "-o", "out"],
    ["live", "{ok}", "--arm", "aacmm7", "--plan", "{bad}", "-o", "out"],
])
@pytest.mark.parametrize("bad, words", [("a\nb.csv", "without control characters"),
                                        ("a\u202eb.csv", "invisible or text-direction"),
                                        (" a.csv", "begin or end with white space"),
                                        ("a\udcffb.csv", "is not UTF-8 text (byte 0xff)")])
def test_every_path_argument_refuses_an_unnameable_path(tmp_path, capsys, monkeypatch, argv, bad, words):
    """The check calibrate made on its points files alone (refuse_unnameable_files) is the path type's: every
    command, every path argument; the file exists, so only its name is wrong."""
    monkeypatch.chdir(tmp_path)
    ok = _small_points(tmp_path)
    try:
        (tmp_path / bad).write_text(ok.read_text())
    except (OSError, UnicodeEncodeError):
        pass
    before = _listing(tmp_path)
    rc = exit_status([a.format(bad=bad, ok=ok) for a in argv])
    err = capsys.readouterr().err
    assert rc == 2 and "the path " in err and words in err and "Traceback" not in err, err
    assert _listing(tmp_path) == before


def test_an_option_value_of_two_dashes_is_refused(tmp_path, capsys):
    """``--mc=--``: Python 3.11's argparse dropped the value "--" as the end of the options and stored an empty list:
    tip ran no Monte Carlo, exit 0; ``-o=--`` met the list as a path, exit 3. Refused, exit 2, nothing written."""
    points = _small_points(tmp_path)
    for extra in (["-o", str(tmp_path / "t.csv"), "--mc=--"], ["-o=--"], ["-o--"]):
        rc = exit_status(["tip", str(points), "--arm", "aacmm7", *extra])
        err = capsys.readouterr().err
        assert rc == 2 and "expected a value, got '--'" in err, err
    assert [p.name for p in tmp_path.iterdir()] == ["p.csv"]


_ODD = st.lists(st.sampled_from(list("a./\\-= \t\n\r~*\u202e\ufeff\u00e9\udcff") + ["..", "//", "/.", "\0"]),
               max_size=8).map("".join)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(text=_ODD, at=st.sampled_from(["points", "-o", "-o=", "--arm"]))
def test_odd_path_strings_never_give_a_traceback(capsys, text, at):
    """Any text in any path position: exit 0 or 2, never a traceback nor an internal error; an input never
    written over, nothing written outside the folder (an output named outside it is left out)."""
    assume(at in ("points", "--arm") or not (text.startswith("/") or ".." in text))
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "w"
        folder.mkdir()
        cwd = os.getcwd()
        os.chdir(folder)
        try:
            points = _small_points(folder)
            before = points.read_bytes()
            argv = {"points": ["tip", text, "--arm", "aacmm7", "-o", "t.csv"],
                    "-o": ["tip", str(points), "--arm", "aacmm7", "-o", text],
                    "-o=": ["tip", str(points), "--arm", "aacmm7", f"-o={text}"],
                    "--arm": ["tip", str(points), f"--arm={text}", "-o", "t.csv"]}[at]
            rc = exit_status(argv)
        finally:
            os.chdir(cwd)
        err = capsys.readouterr().err
        assert rc in (0, 2) and "Traceback" not in err and "internal error" not in err, (argv, err)
        assert points.read_bytes() == before
        assert {p.name for p in Path(tmp).iterdir()} == {"w"}


def test_a_path_named_inside_a_file_with_a_trailing_slash_is_refused_at_its_key(tmp_path, nominal, capsys):
    """A model file's ``covariance = "c.csv/"`` (or ``training_poses``) and a campaign's ``arm = "arm.toml/"`` read
    the file ``c.csv``, ``arm.toml`` (Path drops the slash): refused at the key, as on the command line."""
    from arm_model.model_file import format_model, parse_model
    (tmp_path / "c.csv").write_text("x\n")
    for name, tail in (("c.csv/", "'/'"), ("c.csv/.", "'/.'")):
        with pytest.raises(InputError, match=rf"key 'calibration.covariance': 'covariance': '{name}': Not a directory: "
                                             rf"a path that ends in {tail} names a folder"):
            parse_model(format_model(nominal, covariance=name), str(tmp_path / "m.toml"))
    (tmp_path / "arm.toml").write_text(Path(ROOT / "urdf" / "aacmm7.dh.toml").read_text())
    camp = tmp_path / "c.toml"
    camp.write_text(CAMPAIGN.read_text().replace('arm = "aacmm7"', 'arm = "arm.toml/"'))
    assert exit_status(["simulate", str(camp), "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "key 'arm': 'arm': 'arm.toml/': Not a directory" in err, err
    assert not (tmp_path / "out").exists()


def test_an_output_that_is_an_input_under_another_name_is_refused(tmp_path, capsys):
    """``tip -o copy.csv``, copy.csv a hard link to the points file: the guard compared resolved paths only, and
    copy.csv was replaced; now the same file (device and inode) is refused too, exit 2, nothing written."""
    points = _small_points(tmp_path)
    os.link(points, tmp_path / "copy.csv")
    before = _listing(tmp_path)
    assert exit_status(["tip", str(points), "--arm", "aacmm7", "-o", str(tmp_path / "copy.csv")]) == 2
    err = capsys.readouterr().err
    assert f"it is the input {points} under another name (a hard link)" in err, err
    assert _listing(tmp_path) == before and os.path.samefile(points, tmp_path / "copy.csv")
