"""Correction models: the paper's four (Eq. 3-9) and the full-wrench one, on exact synthetic rings."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from test_correction_synth import RING_D, ring_measurement

from arm_model import InputError, ball_centres
from arm_model.geometry import fit_cylinder
from arm_model.io import parse_artefacts, parse_points
from conftest import assert_close
from correction.models import MODELS, analyse_ring_campaign, campaign_summary, correct_ring, paper_correction, table2
from correction.signals import PointForces

ARTEFACTS = f"""
[[feature]]
id = "ring"
kind = "ring"
diameter_mm = {RING_D * 1e3}
u_diameter_mm = 0.00105
form_error_mm = 0.005
"""


def points_csv(measurements, two_channel=False) -> str:
    """A points CSV (docs/formats.md §3) from [(id, q (N, 7) [rad], force (N, 3) [N])]."""
    cols = ["measurement", "feature"] + [f"q{i}_deg" for i in range(1, 8)]
    cols += ["f_bend_N", "f_axial_N"] if two_channel else ["fx_N", "fy_N", "fz_N"]
    lines = [",".join(cols)]
    for mid, q, f in measurements:
        for qi, fi in zip(np.degrees(q), f, strict=True):
            force = [fi[0], fi[2]] if two_channel else list(fi)
            lines.append(",".join([mid, "ring"] + [repr(float(v)) for v in qi] + [repr(float(v)) for v in force]))
    return "\n".join(lines) + "\n"


@pytest.fixture(scope="module")
def campaign_data(nominal):
    rng = np.random.default_rng(11)
    return [(f"ring-{k:02d}",) + ring_measurement(nominal, rng, per_row=10, force_mean=0.6 + 0.5 * k)[:2]
            for k in range(4)]


def test_uniform_shift_shrinks_the_diameter_by_2d_and_keeps_the_form():
    t = np.linspace(0, 2 * np.pi, 20, endpoint=False)
    local = np.vstack([np.column_stack([0.085 * np.cos(t), 0.085 * np.sin(t), np.full(20, h)]) for h in (0, 0.01)])
    local[::3, :2] *= 1 + 2e-5                       # some form error
    p = local @ Rotation.from_rotvec([0.4, 0.2, 1.0]).as_matrix().T + [0.3, 0.1, -0.2]
    cyl = fit_cylinder(p)
    moved = paper_correction(p, cyl, 2.0, 0.0142e-3)
    after = fit_cylinder(moved)
    assert_close(after.diameter, cyl.diameter - 2 * 2.0 * 0.0142e-3, atol=1e-12)
    assert_close(after.form_error, cyl.form_error, atol=1e-12)
    # each point moved by exactly |f c| perpendicular to the axis, towards it
    step = moved - p
    assert_close(np.linalg.norm(step, axis=1), np.full(len(p), 2.0 * 0.0142e-3), atol=1e-15)
    assert_close(step @ cyl.axis, np.zeros(len(p)), atol=1e-15)
    assert np.all(np.einsum("ij,ij->i", step, p - cyl.point) < 0)
    # per-point forces: the radius shrinks by the mean shift to first order
    f = np.random.default_rng(0).uniform(0.5, 3, len(p))
    per = fit_cylinder(paper_correction(p, cyl, f, 0.0142e-3))
    assert_close(per.radius, cyl.radius - 0.0142e-3 * f.mean(), atol=2e-9)


def test_full_wrench_recovers_the_true_ring_the_paper_models_do_what_they_say(nominal, campaign_data):
    c = nominal.probe.bending_compliance_x
    for _mid, q, f in campaign_data:
        forces = PointForces(f, "xyz", "synthetic")
        fits = correct_ring(ball_centres(nominal, q), nominal.probe.ball_diameter, RING_D, c, forces,
                            ball_centres(nominal, q, f))
        assert set(fits) == set(MODELS)
        init = fits["initial"].diameter_error
        assert init > 2 * c * forces.bending.mean() * 0.9          # the rigid centres read the ring too large
        assert abs(fits["wrench"].diameter_error) < 1e-9            # exact: the truth's physics
        assert fits["wrench"].form_error < 1e-9
        # force towards the axis with an isotropic bending compliance: the point model is right too (the
        # axial compliance moves the ball along the ring's axis, which does not change the diameter)
        assert abs(fits["point"].diameter_error) < 5e-9
        # the one-value models move every point alike: the form does not change, the diameter by 2 f c
        for m, value in (("mean", forces.bending.mean()), ("max", forces.bending.max()),
                         ("max10", np.sort(forces.bending)[-10:].mean())):
            assert_close(fits[m].form_error, fits["initial"].form_error, atol=1e-12)
            assert_close(init - fits[m].diameter_error, 2 * c * value, atol=1e-11)


def test_zero_compliance_changes_nothing(nominal, campaign_data):
    _, q, f = campaign_data[0]
    rigid = ball_centres(nominal, q)
    fits = correct_ring(rigid, nominal.probe.ball_diameter, RING_D, 0.0, PointForces(f, "xyz", "s"), rigid)
    for m in MODELS:
        assert_close(fits[m].diameter, fits["initial"].diameter, atol=1e-13)


def test_campaign_from_a_points_file(nominal, campaign_data):
    pts = parse_points(points_csv(campaign_data), "points.csv", 7)
    art = parse_artefacts(ARTEFACTS, "artefacts.toml")
    camp = analyse_ring_campaign(nominal, pts, art)
    assert [r.id for r in camp.measurements] == [m[0] for m in campaign_data]
    assert camp.models == MODELS and camp.force_kind == "xyz" and not camp.notes
    t = table2(camp)
    assert np.all(t["diameter_error_initial_mm"] > 0.005)
    assert np.all(np.abs(t["diameter_error_wrench_mm"]) < 1e-5)          # 10 nm: the CSV carries 17 digits
    assert_close(t["improvement_wrench_pct"], np.full(4, 100.0), atol=0.1)
    s = campaign_summary(camp)
    assert s["wrench"]["diameter_error_reduction_pct"] > 99.9
    assert np.all(t["diameter_error_max_mm"] < 0)                        # the max model overcorrects
    assert s["max"]["diameter_error_reduction_pct"] < s["mean"]["diameter_error_reduction_pct"]
    assert s["wrench"]["max_form_error_increase_mm"] <= 1e-6
    # the forces grow with k: so do the initial errors
    assert np.all(np.diff(camp.force_values("mean")) > 0)
    assert np.all(np.diff(camp.column("initial")) > 0)


def test_two_channel_sensor_is_stated(nominal, campaign_data):
    pts = parse_points(points_csv(campaign_data[:1], two_channel=True), "points.csv", 7)
    camp = analyse_ring_campaign(nominal, pts, parse_artefacts(ARTEFACTS, "a.toml"))
    assert camp.force_kind == "two-channel"
    assert any("probe y is not measured" in n for n in camp.notes)


def test_campaign_input_errors(nominal, campaign_data, tmp_path):
    pts = parse_points(points_csv(campaign_data[:1]), "points.csv", 7)
    two = parse_artefacts(ARTEFACTS + ARTEFACTS.replace('"ring"\nkind', '"ring-b"\nkind'), "two.toml")
    with pytest.raises(InputError, match="2 ring features"):
        analyse_ring_campaign(nominal, pts, two)
    with pytest.raises(InputError, match="no point of the points file touches the ring 'ring-b'"):
        analyse_ring_campaign(nominal, pts, two, feature="ring-b")
    with pytest.raises(InputError, match="no ring feature 'nope'"):
        analyse_ring_campaign(nominal, pts, two, feature="nope")
    with pytest.raises(InputError, match="no force signal for measurement 'ring-00'") as exc:
        analyse_ring_campaign(nominal, pts, parse_artefacts(ARTEFACTS, "a.toml"), signals=tmp_path)
    assert "ring-00.csv" in str(exc.value)
    no_force = parse_points("measurement,feature," + ",".join(f"q{i}_deg" for i in range(1, 8)) + "\n"
                            + "m,ring," + ",".join("0" for _ in range(7)) + "\n", "nf.csv", 7)
    with pytest.raises(InputError, match="no force columns"):
        analyse_ring_campaign(nominal, no_force, parse_artefacts(ARTEFACTS, "a.toml"))


def test_improvement_uses_the_size_of_the_error():
    """An over-correction from +0.015 mm to -0.152 mm is a worse result (-913 %), never "+1113 %"."""
    from types import SimpleNamespace
    cols = {"initial": np.array([0.015e-3, -0.020e-3]), "point": np.array([-0.152e-3, 0.010e-3])}
    camp = SimpleNamespace(measurements=[SimpleNamespace(id="a"), SimpleNamespace(id="b")], models=("initial", "point"),
                           column=lambda m, what="diameter_error": cols[m] if what == "diameter_error" else cols[m] * 0,
                           force_values=lambda w: np.zeros(2))
    t = table2(camp)
    np.testing.assert_allclose(t["improvement_point_pct"], [(0.015 - 0.152) / 0.015 * 100, 50.0], rtol=1e-12)
