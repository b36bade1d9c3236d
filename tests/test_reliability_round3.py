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
