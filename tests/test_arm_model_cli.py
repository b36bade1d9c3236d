"""`aacmm tip` / `aacmm urdf`: outputs, flags, and bad input -> message, exit 2, nothing written."""
from __future__ import annotations

import csv
import subprocess
import sys

import numpy as np
import pytest

from arm_model import ball_centres
from arm_model.cli import main
from conftest import NOMINAL, ROOT, assert_close

HEADER = "measurement,feature," + ",".join(f"q{i}_deg" for i in range(1, 8))


def write_points(path, rows, force_cols="fx_N,fy_N,fz_N"):
    path.write_text(HEADER + ("," + force_cols if force_cols else "") + "\n" +
                    "\n".join(",".join(map(str, r)) for r in rows) + "\n")
    return path


def test_tip_writes_rigid_corrected_and_deflection(tmp_path, nominal, capsys):
    rng = np.random.default_rng(0)
    q = rng.uniform(-90, 90, (6, 7))
    f = rng.normal(0, 2, (6, 3))
    f[5] = [10.0, 9.0, 0.0]                         # 13.45 N > 13 N: flagged, kept
    pts = write_points(tmp_path / "p.csv", [["m1", "ring", *qi, *fi] for qi, fi in zip(q, f, strict=True)])
    out = tmp_path / "tips.csv"
    assert main(["tip", str(pts), "--arm", str(NOMINAL), "-o", str(out)]) == 0
    rows = list(csv.DictReader(out.open()))
    assert len(rows) == 6
    got = np.array([[float(r[k]) for k in ("x_mm", "y_mm", "z_mm")] for r in rows])
    rigid = np.array([[float(r[k]) for k in ("x_rigid_mm", "y_rigid_mm", "z_rigid_mm")] for r in rows])
    assert_close(got, ball_centres(nominal, np.deg2rad(q), f) * 1e3, atol=1e-6)
    assert_close(rigid, ball_centres(nominal, np.deg2rad(q)) * 1e3, atol=1e-6)
    defl = np.array([float(r["deflection_um"]) for r in rows])
    assert_close(defl, np.linalg.norm(got - rigid, axis=1) * 1e3, atol=2e-3)
    assert [r["over_force"] for r in rows] == ["0"] * 5 + ["1"]
    assert "flagged" in capsys.readouterr().err          # a warning: on standard error


def test_tip_two_channel_says_missing_component(tmp_path, capsys):
    pts = write_points(tmp_path / "p.csv", [["m1", "ring", *[10] * 7, 1.0, 0.0]], "f_bend_N,f_axial_N")
    assert main(["tip", str(pts), "--arm", str(NOMINAL), "-o", str(tmp_path / "o.csv")]) == 0
    assert "taken as zero" in capsys.readouterr().out


@pytest.mark.parametrize("content, words", [
    ("", "empty"),
    (HEADER + ",fx_N,fy_N,fz\n" + "m,f," + "0," * 7 + "1,2,3\n", "column 'fz'"),
    (HEADER + ",fx_N,fy_N,fz_N\n" + "m,f," + "0," * 7 + "1,nan,3\n", "line 2, column 'fy_N'"),
    (HEADER.replace(",q7_deg", "") + "\n" + "m,f," + ",".join(["0"] * 6) + "\n", "arm has 7"),
])
def test_tip_bad_input_exit_2_and_nothing_written(tmp_path, capsys, content, words):
    pts = tmp_path / "p.csv"
    pts.write_text(content)
    out = tmp_path / "o.csv"
    assert main(["tip", str(pts), "--arm", str(NOMINAL), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert str(pts) in err and words in err
    assert not out.exists() and list(tmp_path.iterdir()) == [pts]


def test_tip_refuses_to_write_over_its_input(tmp_path, capsys):
    pts = write_points(tmp_path / "p.csv", [["m1", "ring", *[0] * 7, 1, 0, 0]])
    before = pts.read_bytes()
    assert main(["tip", str(pts), "--arm", str(NOMINAL), "-o", str(pts)]) == 2
    assert pts.read_bytes() == before and "over an input" in capsys.readouterr().err


def test_urdf_command_regenerates_committed_file(tmp_path):
    out = tmp_path / "a.urdf"
    assert main(["urdf", str(NOMINAL), "-o", str(out)]) == 0
    assert out.read_text() == (ROOT / "urdf" / "aacmm7.urdf").read_text()


def test_entry_point_help_and_exit_code(tmp_path):
    exe = [sys.executable, "-m", "arm_model.cli"]
    helptext = subprocess.run(exe + ["--help"], capture_output=True, text=True, check=True).stdout
    assert "tip" in helptext and "urdf" in helptext
    tip_help = subprocess.run(exe + ["tip", "--help"], capture_output=True, text=True, check=True).stdout
    assert "over_force" in tip_help and "--arm" in tip_help
    bad = subprocess.run(exe + ["tip", str(tmp_path / "missing.csv"), "--arm", str(NOMINAL), "-o",
                                str(tmp_path / "o.csv")], capture_output=True, text=True)
    assert bad.returncode == 2 and "cannot read" in bad.stderr


def test_tip_with_a_urdf_arm_and_tip_frame(tmp_path, nominal):
    from test_arm_model_urdf_chain import arm_urdf
    urdf = tmp_path / "arm.urdf"
    urdf.write_text(arm_urdf(nominal))
    pts = write_points(tmp_path / "p.csv", [["m1", "ring", *[10] * 7, 1.0, 0.0, 0.0]])
    out = tmp_path / "o.csv"
    assert main(["tip", str(pts), "--arm", str(urdf), "-o", str(out)]) == 2      # no --tip-frame: said
    assert main(["tip", str(pts), "--arm", str(urdf), "--tip-frame", "tip", "-o", str(out)]) == 0
    row = next(csv.DictReader(out.open()))
    ref = ball_centres(nominal.with_probe(p_last=(0.001, -0.002, 0.085)), np.deg2rad([10] * 7))
    assert_close([float(row[k]) for k in ("x_rigid_mm", "y_rigid_mm", "z_rigid_mm")], ref * 1e3, atol=1e-6)


def test_help_imports_no_subcommand_module():
    """`aacmm --help` lists every subcommand without importing their modules, numpy or
    importlib.metadata (start-up stays short); `aacmm CMD --help` builds CMD in full."""
    import subprocess
    import sys
    code = ("import sys, contextlib, io\n"
            "from arm_model.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()) as out:\n"
            "    try: main(['--help'])\n"
            "    except SystemExit: pass\n"
            "heavy = [m for m in ('casadi', 'pinocchio', 'matplotlib', 'scipy', 'calibration', 'correction', 'viz',\n"
            "                     'arm_model.commands', 'numpy', 'importlib.metadata') if m in sys.modules]\n"
            "print(heavy); print('close-loop' in out.getvalue() and 'tip' in out.getvalue())\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert res.stdout.split("\n")[:2] == ["[]", "True"], res.stdout + res.stderr


def _subcommands(parser, path=()):
    """(command words, parser) of every subcommand below ``parser`` (``study montecarlo`` included)."""
    import argparse
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from [((*path, name), sub), *_subcommands(sub, (*path, name))]


def test_every_output_option_is_the_one_helper():
    """Every ``-o/--output`` of every subcommand comes from ``add_output_option``: one type (an empty path is
    refused), one help of the same promises; the commands that write are the ones we know."""
    from arm_model.cli import build_parser
    from arm_model.cli_options import file_output_path, output_path
    outputs = {}
    for words, sub in _subcommands(build_parser()):
        for action in sub._actions:
            if "-o" in action.option_strings or "--output" in action.option_strings:
                outputs[" ".join(words)] = action
    assert set(outputs) == {"tip", "urdf", "simulate", "ring", "paper", "calibrate", "study montecarlo",
                            "study poses", "close-loop", "live"}
    for words, action in outputs.items():
        assert action.option_strings == ["-o", "--output"] and action.required, words
        assert action.type is (file_output_path if action.metavar == "FILE" else output_path), words
        assert "never" in action.help and "nothing is written outside it" in action.help, words
        assert ("whole or not at all" in action.help) != (words == "live"), words


def test_an_empty_output_path_is_refused(capsys):
    from arm_model.cli import main
    with pytest.raises(SystemExit) as e:
        main(["paper", "-o", ""])
    assert e.value.code == 2 and "empty" in capsys.readouterr().err


@pytest.mark.parametrize("cmd, new, old, value, dest, expected", [
    (["view", "p.csv", "--arm", "aacmm7"], "--points-per-s", "--fps", "4", "fps", 4.0),
    (["view", "p.csv", "--arm", "aacmm7"], "--open-s", "--open-seconds", "60", "open_seconds", 60.0),
    (["calibrate", "p.csv", "a.toml", "--arm", "aacmm7", "-o", "o"], "--covariance-scale", "--covariance", "stated",
     "covariance", "stated")])
def test_renamed_options_keep_their_older_spelling(cmd, new, old, value, dest, expected):
    """Options renamed so that one name means one thing across commands still take their older spelling."""
    from arm_model.cli import build_parser
    for spelling in (new, old):
        args = build_parser().parse_args([*cmd, spelling, value])
        assert getattr(args, dest) == expected, spelling
