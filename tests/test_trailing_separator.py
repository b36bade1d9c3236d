"""A path to a file given with a trailing separator (`samples.csv/`) names a folder: the system refuses it (not a
directory), and so does every command (pathlib drops the separator, so the file was read) and every reader."""
from __future__ import annotations

import pytest

from arm_model.errors import InputError
from arm_model.io import read_points
from conftest import ROOT, exit_status

RING = ROOT / "examples" / "data" / "paper-ring-xyz" / "points.csv"


@pytest.mark.parametrize("where", ["points", "--arm", "--arm="])
def test_a_file_with_a_trailing_slash_is_refused_naming_it(tmp_path, capsys, where):
    arm = str(ROOT / "urdf" / "aacmm7.dh.toml")
    points, bad = (f"{RING}/", f"{RING}/") if where == "points" else (str(RING), f"{arm}/")
    arm_args = [f"--arm={bad}"] if where == "--arm=" else ["--arm", bad if where == "--arm" else arm]
    rc = exit_status(["tip", points, *arm_args, "-o", str(tmp_path / "t.csv")])
    err = capsys.readouterr().err
    assert rc == 2 and f"aacmm tip: error: {bad}: Not a directory" in err and "nothing written" in err, err
    assert list(tmp_path.iterdir()) == []


def test_a_reader_given_a_file_with_a_trailing_slash_refuses_it():
    with pytest.raises(InputError, match="Not a directory") as exc:
        read_points(f"{RING}/")
    assert exc.value.path == f"{RING}/"
    assert len(read_points(str(RING)).q) > 0
