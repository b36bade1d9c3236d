"""Round 14 of the hostile-input audit (fuzzing every command with hostile files and arguments): what it found,
each refused with one message naming the file, line and column, exit 2, nothing written. The path findings are in
tests/test_path_arguments.py."""
from __future__ import annotations

from conftest import exit_status

HEADER = "measurement,initial_mm,point_force_mm,mean_force_mm,max_force_mm,max10_force_mm\n"


def test_a_table2_row_with_no_initial_error_is_refused_at_its_cell(tmp_path, capsys):
    """`paper --table2`: an initial diameter error of 0.000 mm made every improvement of that row -inf %, written
    into table2_implied.csv and summary.json ("mean_pct": "-inf") with numpy's divide-by-zero warning, exit 0."""
    table = tmp_path / "t.csv"
    table.write_text(HEADER + "1,0.1,0.05,0.05,0.01,0.02\n2,0.000,0.1,0.1,0.02,0.03\n3,0.3,0.1,0.2,0.05,0.01\n")
    out = tmp_path / "out"
    assert exit_status(["paper", "--table2", str(table), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{table}, line 3, column 'initial_mm': an initial diameter error of 0" in err, err
    assert "RuntimeWarning" not in err and not out.exists()
