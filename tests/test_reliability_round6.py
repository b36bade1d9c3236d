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
