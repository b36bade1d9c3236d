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
