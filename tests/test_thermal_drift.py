"""A drift of the links in time (no thermometer): the three evaluators agree, it scales the lengths as a
temperature would, the loop offers it only where it can be told (time, no temperature) and keeps it only when the
held-out folds do."""
from __future__ import annotations

import numpy as np
import pytest

from arm_model import PinocchioArm
from arm_model.effects import EFFECTS, JointCompliance, ThermalDrift, ThermalGrowth
from arm_model.model import ArmModel, AuxData
from conftest import assert_close, assert_evaluators_agree


def test_three_evaluators_agree(nominal):
    model = ArmModel(nominal, (JointCompliance(), ThermalGrowth(), ThermalDrift(power=1, reference_time_s=900.0),
                               ThermalDrift(power=2, reference_time_s=900.0)))
    rng = np.random.default_rng(5)
    n = 8
    q = rng.uniform(-2.5, 2.5, (n, 7))
    w = np.zeros((n, 6))
    w[:, :3] = rng.normal(0, 2, (n, 3))
    tg, tc = PinocchioArm(nominal).torques(q, w)
    aux = AuxData(rng.uniform(15, 30, n), tg, tc, rng.uniform(0, 3600, n))
    p = rng.normal(0, 1e-5, model.spec.size)
    p[-2:] = [5e-8, 3e-11]                                   # 180 ppm an hour; a turn of the same order
    assert_evaluators_agree(model, q, w, p, aux)


def test_drift_scales_lengths_by_hand(nominal):
    model = ArmModel(nominal, (ThermalDrift(reference_time_s=100.0), ThermalDrift(power=2, reference_time_s=100.0)))
    assert model.spec.names[-2:] == ("links.drift_rate", "links.drift_rate2")
    assert model.spec.units[-2:] == ("1/s", "1/s^2")
    r1, r2, t = 5e-8, 2e-11, 1900.0
    p = model.spec.vector({"links.drift_rate": r1, "links.drift_rate2": r2})
    got = model.ball_centres(np.zeros((1, 7)), None, p, AuxData(time=np.array([t])))
    # at q = 0: x = a2 + a4 = 90 mm grows; z = d1 + d3 + d5 + d7 grows; the probe (85 mm) does not
    s = (1 + r1 * 1800.0) * (1 + r2 * 1800.0**2)
    assert_close(got[0], [0.090 * s, 0.0, 1.095 * s + 0.085], atol=1e-15)
    with pytest.raises(ValueError, match="time"):
        model.ball_centres(np.zeros((1, 7)), None, p)
    assert EFFECTS["thermal_drift"] is ThermalDrift
    for bad in ({"power": 3}, {"power": True}, {"reference_time_s": float("nan")}):
        with pytest.raises(ValueError, match="thermal_drift"):
            ThermalDrift(**bad)


#: a small campaign (58 points, 8 measurements, 5-min gaps: 36 min) in a room drifting 8 K/h
SMALL = [{"kind": "ballbar", "positions": 4, "length_mm": 600.0, "points_per_sphere": 4},
         {"kind": "seat", "articulations": 6, "measurements": 2},
         {"kind": "sphere", "points": 7, "measurements": 2}]


def _no_thermometer(alpha_per_k: float):
    """(points without their temperature column, artefacts, nominal) of the small campaign, its links growing by
    ``alpha_per_k`` (0: not at all)."""
    import dataclasses

    from arm_model.sim import campaign_from_dict, simulate
    d = {"seed": 3, "sensor": "xyz", "signals": {"enabled": False}, "noise": {"probing_repeatability_um": 2.0},
         "task": SMALL, "environment": {"drift_C_per_h": 8.0}, "operator": {"measurement_gap_s": 300.0}}
    if alpha_per_k:
        d["truth"] = {"thermal": {"alpha_per_K": [alpha_per_k]}}
    camp = campaign_from_dict(d)
    sim = simulate(camp)
    return dataclasses.replace(sim.points, temperature=None), sim.artefacts, camp.arm


@pytest.mark.slow
def test_loop_recovers_the_drift_and_writes_no_drift(tmp_path):
    """(slow: the simulator's poses of a growing arm, about 10 s unloaded) Links growing 23 ppm/K in a room
    drifting 8 K/h (5.1e-8 /s), no thermometer: the loop adds the drift (its
    rate within 3 u of the truth); the model file holds the geometry at the reference time and no drift (it reads
    back, needs no time column), the summary reports the drift."""
    from arm_model.io import read_back
    from calibration.data import Weights
    from calibration.loop import close_loop
    from calibration.loop_report import write_loop_model
    from calibration.model_output import session_drift
    points, artefacts, nominal = _no_thermometer(2.3e-5)
    loop = close_loop(points, artefacts, nominal, weights=Weights(probe=2e-6), seed=0, progress=lambda s: None)
    assert [c.name for c in loop.added] == ["thermal drift (time)"]
    res = loop.model_fit or loop.final.result
    rate, u = res.value("links.drift_rate"), res.uncertainty("links.drift_rate")
    assert 0 < u < 2.5e-8 and abs(rate - 2.3e-5 * 8.0 / 3600.0) < 3 * u
    write_loop_model(loop, tmp_path)
    assert "t_ref" in next(tmp_path.glob("*.toml")).read_text()          # said in its comment
    back = read_back(next(tmp_path.glob("*.toml")))
    assert not any(e.session for e in back.effects) and "time" not in back.model.needs()
    drift = session_drift(res)                          # summary.json's model.session_drift
    t_ref = loop.added[0].effect.reference_time_s
    assert drift[0]["reference_time_s"] == t_ref and drift[0]["parameters"][0]["value"] == pytest.approx(rate)
    # the geometry written is the fit's at t_ref: the fit's own ball centres with the time at t_ref
    t = np.full(len(res.data), t_ref)
    aux = AuxData(None if res.data.aux is None else res.data.aux.temperature,
                  None if res.data.aux is None else res.data.aux.tau_gravity,
                  None if res.data.aux is None else res.data.aux.tau_contact, t)
    own = res.model.ball_centres(res.data.points.q, res.data.wrench, res.p, aux)
    assert_close(back.ball_centres(res.data.points, wrench=res.data.wrench), own, atol=1e-9)


@pytest.mark.slow
def test_loop_adds_nothing_without_a_drift():
    """(slow: about 5 s unloaded) The same campaign, its links not growing: the drift is offered (time spans 36
    min, no temperature) and not added."""
    from calibration.data import Weights
    from calibration.loop import close_loop
    points, artefacts, nominal = _no_thermometer(0.0)
    loop = close_loop(points, artefacts, nominal, weights=Weights(probe=2e-6), seed=0, progress=lambda s: None)
    assert "thermal drift (time)" in {c.name for c in loop.candidates}
    assert not loop.added


def test_drift_offered_only_with_time_and_no_temperature():
    """Offered for time_s spanning >= 10 min without a temperature column; not with a temperature (thermal growth
    instead), without time, or over a short span."""
    from types import SimpleNamespace

    from calibration.candidates import MIN_DRIFT_SPAN_S, Candidate, Skipped, drift_offer
    t = np.linspace(0.0, 2 * MIN_DRIFT_SPAN_S, 10)
    free = SimpleNamespace(coupled=False)
    got = drift_offer(free, SimpleNamespace(temperature=None, time=t))
    assert isinstance(got, list) and [c.name for c in got] == ["thermal drift (time)"]
    assert got[0].effect.reference_time_s == MIN_DRIFT_SPAN_S
    assert [c.name for c in got[0].then] == ["thermal drift (time^2)"] and isinstance(got[0].then[0], Candidate)
    for temp, time in ((np.full(10, 20.0), t), (None, None), (None, t * 0.4), (None, np.r_[t[:-1], np.nan])):
        assert isinstance(drift_offer(free, SimpleNamespace(temperature=temp, time=time)), Skipped)


def test_model_file_refuses_a_session_drift(nominal):
    """A model file never holds a drift in time: the reader refuses the kind at its key."""
    from arm_model.errors import InputError
    from arm_model.model_file import format_model, parse_model
    text = format_model(nominal) + '\n[[effect]]\nkind = "thermal_drift"\n'
    with pytest.raises(InputError, match="thermal_drift.*not of the arm"):
        parse_model(text)


def test_an_arm_with_a_drift_in_python_reads_the_time_column(nominal):
    """An Arm holding a drift (built in Python, e.g. ``--effect thermal_drift``; never read from a file) takes the
    points' time_s, and names the column when the points lack it."""
    from dataclasses import replace

    from arm_model.errors import InputError
    from arm_model.io import PointSet
    from arm_model.model_file import Arm
    eff = ThermalDrift(reference_time_s=60.0)
    q = np.random.default_rng(2).uniform(-2, 2, (4, 7))
    t = np.array([0.0, 600.0, 1200.0, 1800.0])
    pts = PointSet(path="p.csv", measurement=np.array(["m"] * 4, dtype=object),
                   feature=np.array([""] * 4, dtype=object), q=q, time=t)
    arm = Arm(nominal, (eff,), {"links.drift_rate": 5e-8})
    want = arm.model.ball_centres(q, None, arm.p, AuxData(time=t))
    assert_close(arm.ball_centres(pts), want, atol=1e-15)
    with pytest.raises(InputError, match="time_s"):
        arm.ball_centres(replace(pts, time=None))


def test_no_link_growth_is_offered_on_a_chain_with_a_mimic_joint(tmp_path):
    """A chain whose joint mimics another (rows and encoder columns differ) is offered no thermal growth or drift
    (link growth acts on the chain's rows; the drift was an internal error of close-loop there), saying why."""
    from types import SimpleNamespace

    from test_sim_mocap import COUPLED_URDF, TIP

    from arm_model.urdf_import import description_from_urdf
    from calibration.candidates import MIN_DRIFT_SPAN_S, drift_offer, library_candidates
    (tmp_path / "a.urdf").write_text(COUPLED_URDF)
    desc = description_from_urdf(tmp_path / "a.urdf", TIP)
    assert desc.coupled
    n = 8
    pts = SimpleNamespace(temperature=None, time=np.linspace(0.0, 2 * MIN_DRIFT_SPAN_S, n), force=np.zeros((n, 3)),
                          q=np.zeros((n, desc.n_joints)))
    out, skipped = library_candidates(desc, SimpleNamespace(points=pts), families=("thermal",))
    assert out == [] and any(s.name == "thermal growth" and "mimicking" in s.reason for s in skipped)
    assert any(s.name == "thermal drift (time)" and "mimicking" in s.reason for s in skipped)
    assert "mimicking" in drift_offer(desc, pts).reason      # the loop's inputs ask the same decision: no time


def test_a_drift_asked_on_the_command_line_is_taken_about_the_session(nominal):
    """``--effect thermal_drift`` (time origin 0) is taken about the middle of the points' time span, as the loop's
    candidate is; a drift with its own origin and the other effects are left as they are; points without time
    leave the model as it is."""
    from types import SimpleNamespace

    from arm_model.effects import JointGain
    from calibration.cli import _drift_about_the_session
    model = ArmModel(nominal, (JointGain(), ThermalDrift(), ThermalDrift(power=2, reference_time_s=7.0)))
    got = _drift_about_the_session(model, SimpleNamespace(time=np.array([1900.0, 100.0, 1000.0004])))
    assert [getattr(e, "reference_time_s", None) for e in got.effects] == [None, 1000.0, 7.0]
    assert got.effects[0] == model.effects[0] and got.spec.names == model.spec.names
    assert _drift_about_the_session(model, SimpleNamespace(time=None)) is model
