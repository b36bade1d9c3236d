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


def test_a_fit_whose_scatter_no_model_file_can_carry_is_a_numerical_failure(tmp_path, monkeypatch, nominal):
    """The Panda's two placements under one measurement id (`front`: its seats moved between them) made calibrate
    fit a probing scatter of 106 mm, then stop at the model file's writer ("must be a number in [0, 100000] um"),
    exit 3 (internal error) after the fit; now a numerical failure (exit 4) saying what to check, nothing written.
    Here the fit's scatter is set beyond the model file's range on a small simulated fit."""
    import numpy as np
    import pytest

    from arm_model.errors import NumericalError
    from arm_model.model import ArmModel
    from arm_model.output import output_folder
    from arm_model.sim.quick import SynthSpec, make_campaign, random_truth
    from calibration import calibrate, make_data
    from calibration.model_output import write_model
    model = ArmModel(nominal)
    truth = random_truth(model, np.random.default_rng(1), length=2e-4, angle=1e-4)
    c = make_campaign(model, SynthSpec(ballbars=2, seats=1, spheres=1), seed=1, p_true=truth)
    fit = calibrate(model, make_data(c.points, c.artefacts, model))
    monkeypatch.setattr(type(fit), "probing_scatter", lambda self: 0.1064)
    with pytest.raises(NumericalError, match=r"'probing_scatter_um' must be a number in \[0, 100000\] um, got 106400"
                                             r".*several placements under one measurement id"):
        with output_folder(tmp_path / "out", (), "calibrate") as out:
            write_model(fit, out.dir, "arm")
    assert list(tmp_path.iterdir()) == []
