"""Reliability, round 6: a hostile-input audit of what is new since round 5 (--hold-joint, --base-frame,
--holdout-points, the gross-error options, the option aliases) and of combinations: -o named with another
format's suffix, numbers in other scripts' digits, model files whose covariance contradicts them, artefacts
with a distance given twice. Each test is named after what it checks; all are fast (no fit, or one of a few
points)."""
from __future__ import annotations

import pytest

from arm_model.cli import main
from conftest import NOMINAL

QCOLS = ",".join(f"q{k}_deg" for k in range(1, 8))


def _exit(argv) -> int:
    """The exit status of ``aacmm argv`` (argparse's refusals raise SystemExit, the commands' return it)."""
    try:
        return main(argv)
    except SystemExit as exc:
        return exc.code


def _points(tmp_path, rows=("m,f,10,20,30,40,50,60,70",)):
    path = tmp_path / "p.csv"
    path.write_text(f"measurement,feature,{QCOLS}\n" + "".join(r + "\n" for r in rows))
    return path


# ---------------------------------------------------------------------------------------------
# -o named with the suffix of a format the toolkit reads, but not the one the command writes

@pytest.mark.parametrize("command, name, writes", [
    ("tip", "out.json", ".csv"), ("tip", "out.toml", ".csv"), ("tip", "out.urdf", ".csv"),
    ("urdf", "arm.toml", ".urdf"), ("urdf", "arm.JSON", ".urdf"), ("urdf", "arm.csv", ".urdf"),
])
def test_an_output_file_named_as_another_format_is_refused_before_any_work(tmp_path, capsys, command, name, writes):
    """`aacmm urdf aacmm7 -o arm.toml` wrote a URDF, then its own read-back (by the suffix: a .toml file is read as
    TOML by every --arm) refused it: exit 3, "internal error, please report it". The name is the user's input: exit
    2 naming the option and the suffix the command writes, nothing written."""
    out = tmp_path / "o" / name
    argv = (["tip", str(_points(tmp_path)), "--arm", "aacmm7"] if command == "tip" else ["urdf", "aacmm7"])
    rc = main(argv + ["-o", str(out)])
    err = capsys.readouterr().err
    assert rc == 2, err
    assert f"{out}:" in err and f"'{writes}'" in err and "internal error" not in err, err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("name", ["arm.urdf", "arm.URDF", "arm.xml", "arm.txt", "arm"])
def test_an_output_file_with_its_own_suffix_or_one_no_reader_takes_is_written(tmp_path, capsys, name):
    assert main(["urdf", "aacmm7", "-o", str(tmp_path / name)]) == 0
    assert (tmp_path / name).read_text().startswith("<?xml")


# ---------------------------------------------------------------------------------------------
# numbers on the command line follow the files' number rule

@pytest.mark.parametrize("option, value", [
    ("--sigma-probe-um", "١٠"), ("--sigma-probe-um", "１０"), ("--prior-scale", "٣"),
    ("--hold-joint", "j7=1_0"), ("--hold-joint", "j7=٣"), ("--hold-joint", "j7="), ("--hold-joint", "j7=nan"),
])
def test_a_number_in_another_script_or_with_underscores_is_refused_on_the_command_line(tmp_path, capsys, option,
                                                                                       value):
    """`--prior-scale ٣` (Arabic-Indic three) and `--hold-joint j7=1_0` were read as 3 and 10 (Python's float takes
    both), `--hold-joint j7=` as 0; a points file refuses the same cells. One rule: ASCII digits, exit 2."""
    arm = ["--arm", "aacmm7"] if option != "--hold-joint" else ["--arm", str(NOMINAL.with_suffix("").with_suffix(
        ".urdf")), "--tip-frame", "ball"]
    rc = _exit(["calibrate", str(_points(tmp_path)), *arm, option, value, "-o", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 2 and option in err and value in err, err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("value, expected", [("j7", ("j7", 0.0)), ("j7=-12.5", ("j7", -12.5)), (" j7 = 3 ", ("j7", 3.0)),
                                             ("j7=1e2", ("j7", 100.0))])
def test_a_hold_joint_value_in_ascii_digits_is_read(value, expected):
    from arm_model.cli_options import _hold_joint
    assert _hold_joint(value) == expected


def test_whole_number_options_keep_refusing_fractions_and_take_signs():
    import argparse

    from arm_model.cli_options import number_in
    assert number_in(kind=int)(" +7 ") == 7 and number_in(kind=int)("-3") == -3
    for bad in ("7.0", "1e3", "٧", "7_0"):
        with pytest.raises(argparse.ArgumentTypeError):
            number_in(kind=int)(bad)


def test_a_holdout_in_another_scripts_digits_is_an_id_not_a_fraction():
    from calibration.cli import parse_holdout
    assert parse_holdout("0.2") == 0.2 and parse_holdout("٠.٢") == ["٠.٢"] and parse_holdout("0_2") == ["0_2"]


# ---------------------------------------------------------------------------------------------
# artefacts: a distance given twice, a distance to a plane

_ART = '''[[feature]]
id = "A"
kind = "sphere"
diameter_mm = 25.0

[[feature]]
id = "B"
kind = "sphere"
diameter_mm = 25.0

[[feature]]
id = "table"
kind = "plane"

[[distance]]
between = ["A", "B"]
length_mm = 600.0
'''


@pytest.mark.parametrize("extra, line, words", [
    ('\n[[distance]]\nbetween = ["A", "B"]\nlength_mm = 600.0\n', 20, ("given twice", "line 16")),
    ('\n[[distance]]\nbetween = ["B", "A"]\nlength_mm = 500.0\n', 20, ("given twice", "line 16")),
    ('\n[[distance]]\nbetween = ["A", "table"]\nlength_mm = 500.0\n', 20, ("'table' is a plane", "has none")),
])
def test_a_distance_given_twice_or_to_a_plane_is_refused_with_its_line(tmp_path, capsys, extra, line, words):
    """The same pair twice made the fit's normal matrix singular ("unidentifiable", no file, no line) and with
    two lengths (600 and 500 mm) the fit went on with both; a distance to a plane (which has no centre) was
    silently unused when no measurement held both. Each is one error at the second table's line."""
    (tmp_path / "a.toml").write_text(_ART + extra)
    rc = main(["calibrate", str(_points(tmp_path, ("m,A,10,20,30,40,50,60,70",))), str(tmp_path / "a.toml"),
               "--arm", "aacmm7", "-o", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 2 and f"a.toml, line {line}, key 'distance[2].between'" in err, err
    for w in words:
        assert w in err, err
    assert not (tmp_path / "o").exists()
