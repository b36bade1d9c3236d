"""Standard tests with a maximum permissible error: hand-made errors against the MPE give the expected
PASS / FAIL, the smallest enclosing sphere of L_Dia against hand geometry, the options range-checked
(exit 2, nothing written), and ``aacmm calibrate --mpe-*-um`` end to end."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from arm_model.cli import main
from arm_model.model import ArmModel
from arm_model.sim.quick import SynthSpec, make_campaign
from calibration.validation import MPE_TESTS, Validation, _articulation, conformance
from conftest import NOMINAL, assert_close

UM = 1e-6


def _length(m, e_um):
    return {"measurement": m, "between": ["A", "B"], "certified": 0.5, "measured": 0.5 + e_um * UM, "error": e_um * UM}


def _sphere(m, e_um, form_um):
    return {"measurement": m, "feature": "sph", "kind": "sphere", "n": 12, "certified": 0.025,
            "fitted": 0.025 + e_um * UM, "error": e_um * UM, "form": form_um * UM}


def _seat(m, pts_um):
    return {"measurement": m, "feature": "seat", "kind": "seat", "line": 2, **_articulation(np.array(pts_um) * UM)}


A = 10.0                                            # um: side of the equilateral triangle of seat s1
TRIANGLE = [[0, 0, 0], [A, 0, 0], [A / 2, A * math.sqrt(3) / 2, 0], [A / 2, A / (2 * math.sqrt(3)), 0]]
OBTUSE = [[0, 0, 0], [8, 0, 0], [4, 1, 0]]          # smallest enclosing sphere: the longest side's, d = 8


@pytest.fixture()
def val():
    v = Validation()
    v.lengths = [_length("b1", 3.0), _length("b2", -4.9), _length("b3", 2.0)]
    v.diameters = [_sphere("s1", -1.5, 6.0), _sphere("s2", 2.5, 9.0),
                   {**_sphere("r1", 50.0, 50.0), "kind": "ring"}]        # a ring is no sphere test
    v.articulation = [_seat("t1", TRIANGLE), _seat("t2", OBTUSE)]
    return v


def _by_key(rows):
    return {r["key"]: r for r in rows}


def test_hand_values_and_pass_fail(val):
    # hand: the triangle's centre point is the mean: delta_max = A / sqrt(3), enclosing diameter 2 A / sqrt(3);
    # the obtuse triangle: mean (4, 1/3), farthest corner sqrt(16 + 1/9); enclosing diameter 8
    rows = _by_key(conformance(val, {"e-uni": 5 * UM, "volumetric": 4.5 * UM, "p-size": 2.5 * UM,
                                     "p-form": 8 * UM, "l-dia": 11.6 * UM, "spat": 5.7 * UM}))
    assert set(rows) == {t.key for t in MPE_TESTS}
    assert_close([i["value_um"] for i in rows["e-uni"]["items"]], [3.0, -4.9, 2.0], atol=1e-9)
    assert rows["e-uni"]["result"] == "PASS" and rows["e-uni"]["n_fail"] == 0       # |-4.9| <= 5
    assert rows["volumetric"]["result"] == "FAIL" and rows["volumetric"]["n_fail"] == 1   # 4.9 > 4.5
    assert rows["p-size"]["n"] == 2 and rows["p-size"]["result"] == "PASS"           # 2.5 <= 2.5: on the MPE passes
    assert rows["p-form"]["result"] == "FAIL" and rows["p-form"]["n_fail"] == 1       # 9 > 8
    assert_close([i["value_um"] for i in rows["l-dia"]["items"]], [2 * A / math.sqrt(3), 8.0], atol=1e-9)
    assert rows["l-dia"]["result"] == "PASS"                                          # 11.547 <= 11.6
    assert_close([i["value_um"] for i in rows["spat"]["items"]], [A / math.sqrt(3), math.sqrt(16 + 1 / 9)],
                 atol=1e-9)
    assert rows["spat"]["result"] == "FAIL" and rows["spat"]["n_fail"] == 1           # 5.774 > 5.7
    assert rows["eff-diameter"]["result"] is None and rows["eff-diameter"]["mpe_um"] is None   # no MPE given
    assert_close(rows["eff-diameter"]["max_abs_um"], 2.5, atol=1e-9)
    # one item over a tighter L_Dia MPE
    assert _by_key(conformance(val, {"l-dia": 11.5 * UM}))["l-dia"]["result"] == "FAIL"


def test_without_mpe_no_verdict_and_untested_mpe_said(val):
    rows = conformance(val)
    assert rows and all(r["result"] is None and r["mpe_um"] is None for r in rows)
    empty = Validation()
    empty.lengths = [_length("b1", 1.0)]
    r = _by_key(conformance(empty, {"p-size": 3 * UM}))
    assert r["p-size"]["n"] == 0 and r["p-size"]["result"] is None and r["p-size"]["mpe_um"] == pytest.approx(3)
    assert r["e-uni"]["result"] is None


def test_the_conformance_figure_holds_everything_it_draws(val, monkeypatch):
    """The figure's fixed layout (no tight crop) keeps every title, label and legend on the canvas and no two
    panels' drawn extents overlap: the hand rows with an MPE (legends), plus a panel of long item labels and one
    of more items than it labels (41)."""
    from arm_model import reports
    from calibration.report import plot_conformance
    rows = conformance(val, {"e-uni": 5 * UM, "spat": 5.7 * UM})
    long = Validation()
    long.lengths = [_length(f"ballbar-position-{i:02d}-of-the-long-campaign", 1.0 + i) for i in range(3)]
    many = Validation()
    many.lengths = [_length(f"b{i}", -200.0 + 10 * i) for i in range(41)]
    rows = rows + [r for r in conformance(long) + conformance(many) if r["key"] == "e-uni"]
    seen = {}

    def keep(fig, **kw):
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        seen["canvas"] = fig.bbox
        seen["drawn"] = fig.get_tightbbox(renderer).transformed(fig.dpi_scale_trans)
        seen["panels"] = [ax.get_tightbbox(renderer) for ax in fig.axes]
        return b"\x89PNG"
    monkeypatch.setattr(reports, "png", keep)
    plot_conformance(rows, "hand rows")
    canvas, drawn = seen["canvas"], seen["drawn"]
    assert drawn.x0 >= -0.5 and drawn.y0 >= -0.5 and drawn.x1 <= canvas.x1 + 0.5 and drawn.y1 <= canvas.y1 + 0.5
    boxes = sorted(seen["panels"], key=lambda b: -b.y1)
    assert len(boxes) == sum(1 for r in rows if r["n"])
    assert all(a.y0 > b.y1 for a, b in zip(boxes[:-1], boxes[1:], strict=True))


@pytest.mark.parametrize("value", ["0", "-3", "nan", "inf", "abc"])
def test_mpe_option_out_of_range_exits_2(value, tmp_path, capsys):
    out = tmp_path / "o"
    with pytest.raises(SystemExit) as exc:
        main(["calibrate", "p.csv", "a.toml", "--arm", str(NOMINAL), "--mpe-e-uni-um", value, "-o", str(out)])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "--mpe-e-uni-um" in err and value in err
    assert not out.exists()


@pytest.fixture(scope="module")
def files(tmp_path_factory, nominal):
    c = make_campaign(ArmModel(nominal), SynthSpec(ballbars=6, ballbar_points=5, seats=3, articulations=8,
                                                   spheres=2, sphere_points=10, noise=2e-6), seed=33)
    return c.write(tmp_path_factory.mktemp("campaign"))


def test_calibrate_with_mpe_end_to_end(files, tmp_path, capsys):
    out = tmp_path / "out"
    code = main(["calibrate", str(files["points"]), str(files["artefacts"]), "--arm", str(NOMINAL),
                 "--sigma-probe-um", "2", "--mpe-e-uni-um", "1000", "--mpe-spat-um", "0.01", "-o", str(out)])
    text = capsys.readouterr().out
    assert code == 0
    s = json.loads((out / "summary.json").read_text())
    conf = s["conformance"]
    assert conf["mpe_given"] and conf["holdout"] is None
    rows = _by_key(conf["training"])
    # the verdicts follow from the items written next to them
    for r in rows.values():
        if r["mpe_um"] is not None:
            worst = max(abs(i["value_um"]) for i in r["items"])
            assert r["result"] == ("PASS" if worst <= r["mpe_um"] else "FAIL")
    assert rows["e-uni"]["result"] == "PASS" and rows["spat"]["result"] == "FAIL"
    assert rows["l-dia"]["result"] is None
    # the same figures as the validation table: max |length error| and max radial deviation
    val = {r["key"]: r for r in s["validation_training"]}
    assert_close(rows["e-uni"]["max_abs_um"], val["length_error_max"]["after"], atol=1e-9)
    assert_close(rows["spat"]["max_abs_um"], val["articulation_max"]["after"], atol=1e-9)
    assert "E_UNI on training data" in text and "PASS" in text and "FAIL" in text
    assert (out / "conformance_training.png").read_bytes()[:4] == b"\x89PNG"
    assert "conformance_training.png" in (out / "report.html").read_text()


def test_calibrate_without_mpe_says_so(files, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["calibrate", str(files["points"]), str(files["artefacts"]), "--arm", str(NOMINAL),
                 "--sigma-probe-um", "2", "--weights", "stated", "--no-plots", "-o", str(out)]) == 0
    text = capsys.readouterr().out
    s = json.loads((out / "summary.json").read_text())
    assert not s["conformance"]["mpe_given"]
    assert all(r["result"] is None for r in s["conformance"]["training"])
    assert "no --mpe-*-um option given" in text
    assert "no pass/fail" in (out / "report.html").read_text()
