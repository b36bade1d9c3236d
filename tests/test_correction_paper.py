"""The paper's Table 2 (bundled), its Pearson coefficients and improvement figures, and the loop closed."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from arm_model import InputError
from conftest import assert_close
from correction.paper import (
    IMPLIED_FORCE_HALF_WIDTH,
    TABLE2_MODELS,
    close_loop,
    implied_forces,
    improvements,
    load_paper_table2,
    paper_correlations,
)

# the improvement percentages printed in brackets in the paper's Table 2 (an independent check of the data)
PRINTED_IMPROVEMENT = {
    "point_force": [23, 29, 31, 27, 22, 23, 52, 54, 40, 29, 78, 28, 31, 29, 27, 28, 38],
    "mean_force": [23, 29, 31, 23, 22, 23, 54, 54, 40, 29, 78, 29, 31, 29, 27, 28, 37],
    "max_force": [46, 61, 76, 57, 60, 58, 146, 104, 91, 66, 165, 75, 63, 59, 64, 68, 83],
    "max10_force": [41, 53, 62, 48, 47, 46, 108, 98, 80, 53, 143, 57, 56, 53, 47, 54, 73],
}


@pytest.fixture(scope="module")
def table():
    return load_paper_table2()


def test_bundled_table2(table):
    assert len(table.initial) == 17
    assert list(table.measurement) == [str(i) for i in range(1, 18)]
    assert_close(table.initial[[0, 14]] * 1e3, [0.130, 0.225], atol=1e-12)
    assert_close(table.columns["max_force"][6] * 1e3, -0.022, atol=1e-12)
    assert_close(table.columns["max10_force"][16] * 1e3, 0.033, atol=1e-12)
    # the text (§4.1): "a mean diameter [error] of 0.100 mm" (0.098 in the table) and "a maximum peak higher
    # than 0.200 mm"; its "minimum peak lower than 0.010 mm" is not in the table (smallest: 0.023 mm)
    assert_close(table.initial.mean() * 1e3, 0.100, atol=0.0025)
    assert table.initial.max() > 0.200e-3
    assert_close(table.initial.min() * 1e3, 0.023, atol=1e-12)
    # the printed improvements follow from the values to the rounding of the table's 3 decimals
    imp = improvements(table)
    for m, printed in PRINTED_IMPROVEMENT.items():
        diff = np.abs(imp[m]["paper_formula_pct"] - printed)
        assert np.all(diff < 1.6), (m, diff)
        assert np.mean(diff < 0.5) > 0.8


def test_implied_forces_match_the_text(table):
    f = implied_forces(table)
    # "Maximum force reaches 5 N, but common values for maximum force are around 2.5 N. As regards mean force,
    # it reaches up to 2 N and common values are around 1 N. 10Max force provides values between max and mean"
    assert 4.9 < f["max_force"].max() < 5.2
    assert 2.0 < np.median(f["max_force"]) < 2.6
    assert 2.0 < f["mean_force"].max() < 2.2
    assert 0.8 < np.median(f["mean_force"]) < 1.1
    assert np.all((f["max10_force"] > f["mean_force"]) & (f["max10_force"] < f["max_force"]))
    # the point model implies the mean force to first order: equal within the table's rounding, except
    # measurement 4 (point 0.110 mm, mean 0.115 mm: 0.18 N apart)
    apart = np.abs(f["point_force"] - f["mean_force"]) > 2 * IMPLIED_FORCE_HALF_WIDTH
    assert np.flatnonzero(apart).tolist() == [3]
    assert_close(IMPLIED_FORCE_HALF_WIDTH, 0.001 / 0.0284, atol=1e-12)


def test_pearson_coefficients_of_the_paper(table):
    corr = {(c.x_name, c.with_reference): c for c in paper_correlations(table)}
    # the paper: 0.89, 0.88, 0.90 with the (0 N, 0 mm) point; tolerance 0.005 (its two decimals)
    for key, printed in (("mean", 0.89), ("max10", 0.88), ("max", 0.90)):
        assert abs(corr[(f"{key}_force_N", True)].r - printed) < 0.005
        assert corr[(f"{key}_force_N", True)].n == 18
        # without the reference point the correlation is a little weaker
        assert corr[(f"{key}_force_N", False)].r < corr[(f"{key}_force_N", True)].r
    # "about 78 % of diameter error variation is explained"
    assert all(abs(c.r2 - 0.78) < 0.03 for (_, ref), c in corr.items() if ref)


def test_improvement_figures(table):
    imp = improvements(table)
    red = {m: imp[m]["mean_abs_reduction_pct"] for m in TABLE2_MODELS}
    # the conclusion: about 30 %, 30 % for the point and mean models (tolerance 1.5 points)
    assert abs(red["point_force"] - 30) < 1.5 and abs(red["mean_force"] - 30) < 1.5
    # its "60 % and 55 %" for 10Max and max: the table gives 55.8 % for 10Max and 65.2 % for max, i.e. the
    # max model is the better one (as the paper's §4.2 says); the two figures are swapped in the conclusion
    assert abs(red["max10_force"] - 55) < 1.5
    assert abs(red["max_force"] - 65) < 1.5
    assert red["max_force"] > red["max10_force"] + 5


def test_per_measurement_improvement_is_on_the_size_of_the_error(table):
    imp = improvements(table)
    # measurement 7, max model: 0.048 -> -0.022 mm, over-corrected: 22 of 48 um left, 54.2 % (the paper's
    # signed bracket formula prints 146 %); measurement 11: 0.023 -> -0.015 mm, 34.8 % (printed 165 %)
    assert abs(imp["max_force"]["per_measurement_pct"][6] - 100 * (48 - 22) / 48) < 1e-9
    assert abs(imp["max_force"]["per_measurement_pct"][10] - 100 * (23 - 15) / 23) < 1e-9
    assert abs(imp["max_force"]["paper_formula_pct"][6] - 100 * (48 + 22) / 48) < 1e-9
    assert all(np.all(d["per_measurement_pct"] <= 100) for d in imp.values())


def test_closing_the_loop(table):
    L = close_loop(table)
    # the residual after the FEM correction still depends on the force
    assert L.r > 0.75 and L.p_value < 1e-3
    # a compliance in series explains it: positive, well determined, several times... (through the origin)
    c, lo, hi = L.origin["extra_compliance"], *L.origin["extra_compliance_ci"]
    assert 0.030e-3 < c < 0.038e-3 and lo > 0.02e-3 and hi < 0.045e-3
    # the free offset is not distinguishable from zero (within 2 standard errors)
    assert abs(L.intercept) < 2 * L.intercept_se
    # leave-one-out: each measurement predicted by the other 16
    assert L.origin["rms_after"] < 0.4 * L.rms_before
    assert L.rms_after < 0.4 * L.rms_before
    # LOO prediction by hand for one measurement
    m = np.arange(17) != 4
    b = L.force[m] @ L.residual[m] / (L.force[m] @ L.force[m])
    assert_close(L.origin["after"][4], L.residual[4] - b * L.force[4], atol=1e-15)
    A = np.column_stack([np.ones(16), L.force[m]])
    coef = np.linalg.lstsq(A, L.residual[m], rcond=None)[0]
    assert_close(L.loo_prediction[4], coef[0] + coef[1] * L.force[4], atol=1e-15)
    # the other force statistics explain it about as well: 17 measurements cannot tell them apart
    for fm in ("max_force", "max10_force"):
        other = close_loop(table, force_model=fm)
        assert abs(other.origin["rms_after"] - L.origin["rms_after"]) < 0.25 * L.origin["rms_after"]


def test_table_reader_errors(tmp_path):
    good = (tmp_path / "t.csv")
    header = "measurement,initial_mm,point_force_mm,mean_force_mm,max_force_mm,max10_force_mm\n"
    good.write_text("# comment\n" + header + "1,0.1,0.05,0.05,0.01,0.02\n2,0.2,0.1,0.1,0.02,0.03\n"
                    "3,0.3,0.1,0.2,0.05,0.01\n")
    assert len(load_paper_table2(good).initial) == 3
    bad = tmp_path / "b.csv"
    bad.write_text("# c\n" + header + "1,0.1,0.05,x,0.01,0.02\n")
    with pytest.raises(InputError) as exc:
        load_paper_table2(bad)
    assert exc.value.line == 3 and exc.value.column == "mean_force_mm"
    bad.write_text(header.replace("max10_force_mm", "tenmax_mm") + "1,0.1,0.05,0.05,0.01,0.02\n")
    with pytest.raises(InputError, match="missing column 'max10_force_mm'"):
        load_paper_table2(bad)
    bad.write_text(header)
    with pytest.raises(InputError, match="0 measurement row"):
        load_paper_table2(bad)


@settings(max_examples=30, deadline=None)
@given(cells=st.lists(st.text(alphabet="0123456789.-eE xn", min_size=0, max_size=6), min_size=5, max_size=5))
def test_table_reader_never_crashes(tmp_path_factory, cells):
    p = tmp_path_factory.mktemp("t") / "t.csv"
    p.write_text("measurement,initial_mm,point_force_mm,mean_force_mm,max_force_mm,max10_force_mm\n"
                 "1," + ",".join(cells) + "\n2,0.2,0.1,0.1,0.02,0.03\n3,0.3,0.1,0.2,0.05,0.01\n")
    try:
        t = load_paper_table2(p)
    except InputError as exc:
        assert exc.line in (2, None) and exc.column.endswith("_mm")
    else:
        assert np.all(np.isfinite(t.initial))
