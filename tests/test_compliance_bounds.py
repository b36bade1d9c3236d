"""A compliance is never negative: one rule (``ArmModel.lower_bounds``) that every fit holds its parameters to,
with a prior or without (the loop's fits without one wrote a joint compliance of -1.07 urad/(N m) on the
simulated lateral-compliance case of tests/test_loop_synthesis.py), and that the model-file reader checks."""
from __future__ import annotations

import math

import numpy as np
import pytest

from arm_model.effects import JointBacklash, JointCompliance, LateralCompliance, ProbeCompliance, ProbeComplianceMatrix
from arm_model.model import ArmModel
from arm_model.sim.quick import SynthSpec, make_campaign
from calibration import FitOptions, calibrate
from calibration.loop import resolved
from conftest import exit_status


def test_lower_bounds_are_the_physical_ones(nominal):
    """Joint and lateral compliances at least 0, a probe compliance increment at least minus the description's
    compliance it adds to (hand values: 0.0142 mm/N bending, 0.0000876 mm/N axial), an off-diagonal term of
    the probe's compliance matrix and every geometric error unbounded."""
    model = ArmModel(nominal, (JointCompliance(joints=(1,)), LateralCompliance(joints=(3,)),
                               ProbeCompliance(axial=True), ProbeComplianceMatrix(terms=("yy", "xy"))))
    low = dict(zip(model.spec.names, model.lower_bounds(), strict=True))
    assert low["j2.compliance"] == 0.0 and low["j4.lateral_compliance_x"] == low["j4.lateral_compliance_y"] == 0.0
    assert math.isclose(low["probe.dcompliance_bend"], -nominal.probe.bending_compliance_x)
    assert math.isclose(low["probe.compliance_z"], -nominal.probe.axial_compliance)
    assert math.isclose(low["probe.dcompliance_z"], -nominal.probe.axial_compliance)
    assert math.isclose(low["probe.dcompliance_yy"], -nominal.probe.bending_compliance_y)
    assert low["probe.dcompliance_xy"] == -math.inf and low["j2.a"] == -math.inf and low["probe.x"] == -math.inf


SMALL = SynthSpec(ballbars=6, ballbar_points=4, seats=2, articulations=8, spheres=2, noise=2e-6)


def _deflected(nominal, joint: int, c: float, spec: SynthSpec = SMALL):
    """A small campaign on the nominal arm whose encoder ``joint`` reads as if the joint turned by ``c`` [rad/(N m)]
    under its gravity torque (q_enc = q + c tau_gravity, no force), and the model with that joint's compliance."""
    import dataclasses

    from calibration.data import make_data
    model = ArmModel(nominal, (JointCompliance(joints=(joint,)),))
    camp = make_campaign(ArmModel(nominal), spec, seed=3, p_true=np.zeros(model.base_size))
    tau = make_data(camp.points, camp.artefacts, model).aux.tau_gravity[:, joint]
    q = camp.points.q.copy()
    q[:, joint] += c * tau
    return model, make_data(dataclasses.replace(camp.points, q=q), camp.artefacts, model)


@pytest.fixture(scope="module")
def pulled_negative(nominal):
    """A campaign whose truth turns joint 2 against its load (compliance -3 urad/(N m)), fitted without a prior
    (the loop's fits on an arm whose base model holds no compliance) with the compliance free."""
    from calibration.data import Weights
    model, data = _deflected(nominal, 1, -3e-6)
    return calibrate(model, data, FitOptions(prior_scale=None, weights=Weights(probe=2e-6)))


def test_a_fit_without_a_prior_holds_a_compliance_at_its_bound(pulled_negative):
    """Before the bound applied without a prior, this fit returned j2.compliance about -3 urad/(N m); now it is
    held at 0, said with the value the data wanted and that value's uncertainty, and ``resolved`` counts it as
    significantly negative (the loop's physics rule refuses a compliance family the data pull below zero)."""
    res = pulled_negative
    assert res.value("j2.compliance") == 0.0 and "j2.compliance" not in res.free
    f = next(f for f in res.fixed if f.name == "j2.compliance")
    assert f.reason.startswith("at its lower bound") and f.pulled is not None
    value, u = f.pulled
    assert -4.5e-6 < value < -1.5e-6 and 0 < u < 1e-6, f.pulled
    z, neg, pos = resolved(res, ["j2.compliance"], 0.01)
    assert neg == ["j2.compliance"] and pos == [] and math.isclose(z, 2.5758, rel_tol=1e-4)


def test_a_negative_compliance_in_a_model_file_is_refused_at_its_key(nominal, tmp_path, capsys):
    """A joint compliance of -5 urad/(N m) was read and applied (the joint turning against its load); a lateral one
    too; a probe's bending increment that makes its compliance negative in total; a joint's backlash below 0 (a play
    against the links' weight). Each is refused naming the
    file, the line and the key (exit 2), and a probe increment within the description's compliance is read."""
    from arm_model.model_file import format_model
    text = format_model(nominal, (JointCompliance(), LateralCompliance(joints=(3,)), ProbeCompliance(),
                                  JointBacklash(joints=(1,))))
    pts = tmp_path / "p.csv"
    pts.write_text("measurement,feature," + ",".join(f"q{i}_deg" for i in range(1, 8)) + "\nm1,,"
                   + ",".join(["10"] * 7) + "\n")
    cases = [('name = "j1.compliance", value_urad_per_Nm = 0.0', "-5.0", "a compliance cannot be negative"),
             ('name = "j4.lateral_compliance_y", value_urad_per_Nm = 0.0', "-0.5", "a compliance cannot be negative"),
             ('name = "probe.dcompliance_bend", value_um_per_N = 0.0', "-20.0", "negative in total"),
             ('name = "j2.backlash", value_urad = 0.0', "-30.0", "a joint's backlash cannot be negative")]
    for old, new, words in cases:
        assert old in text, old
        model = tmp_path / "m.toml"
        model.write_text(text.replace(old, old.replace("0.0", new), 1))
        line = next(k for k, s in enumerate(model.read_text().splitlines(), 1) if old.split(",")[0] in s)
        assert exit_status(["tip", str(pts), "--arm", str(model), "-o", str(tmp_path / "t.csv")]) == 2
        err = capsys.readouterr().err
        assert words in err and f"{model}, line {line}, key" in err and ".value_u" in err, err
        assert not (tmp_path / "t.csv").exists()
    model.write_text(text.replace(cases[2][0], cases[2][0].replace("0.0", "-10.0"), 1))
    assert exit_status(["tip", str(pts), "--arm", str(model), "-o", str(tmp_path / "t.csv")]) == 0


def test_bounds_reach_every_compliance_parameter_a_fit_can_free(nominal):
    """Every parameter in rad/(N m) of every registered effect has a finite lower bound (none is left to the
    unit), so no fit of the loop can write a negative one."""
    from arm_model.effects import EFFECTS
    for key, cls in EFFECTS.items():
        try:
            e = cls()
        except TypeError:
            continue
        for (name, unit), low in zip(e.param_defs(nominal), e.lower_bounds(nominal), strict=True):
            if unit == "rad/(N m)":
                assert low == 0.0, (key, name, low)
    assert np.all(np.isfinite(ArmModel(nominal, (JointCompliance(),)).lower_bounds()[-7:]))


def test_a_fit_that_ends_where_no_arm_is_is_a_numerical_failure(nominal):
    """``calibrate --prior-scale off`` on one placement of the real Panda seats ended at a joint 7 compliance of
    5.6-7 rad/(N m) (an angle at 1e15 deg once the compliances were bounded) and the model file's reader refused
    it on read-back: exit 3, "This is a bug". A value beyond the plausible range of its quantity (the readers' one
    table) is a numerical failure (exit 4) naming the parameter and what to do: here the data themselves say
    1.3 rad/(N m) for joint 6 (its gravity torque about 0.2 N m: a 0.26 rad turn)."""
    from arm_model import NumericalError
    from calibration.data import Weights
    model, data = _deflected(nominal, 5, 1.3, SynthSpec(ballbars=0, seats=3, articulations=8, spheres=0, noise=2e-6))
    with pytest.raises(NumericalError, match=r"values no arm has: j6\.compliance = 1\.\d+ rad/\(N m\).*--prior-scale "
                                             r"evidence.*--hold NAME.*--min-resolution"):
        calibrate(model, data, FitOptions(prior_scale=None, weights=Weights(probe=2e-6), free=["j6.compliance"]))


def test_the_loop_screens_at_the_current_models_torques(nominal):
    """The screening's torques are the current model's at its equilibrium, not the nominal description's at the
    readings the fits use: for a fit with joint 2's compliance c, joint 2's gravity torque at theta = q - c tau
    (Pinocchio's RNEA at those angles on the fitted description: the independent route), to 1e-6 relative."""
    from arm_model.pinocchio_model import PinocchioArm
    from calibration.data import Weights
    from calibration.loop.stages import at_current_torques
    model, data = _deflected(nominal, 1, 2e-4)           # 2e-4 rad/(N m) under ~13 N m: a 2.6 mrad sag
    res = calibrate(model, data, FitOptions(prior_scale=None, weights=Weights(probe=2e-6)))
    c = res.value("j2.compliance")
    assert 1.5e-4 < c < 2.5e-4
    got = at_current_torques(res).data.aux.tau_gravity
    arm = PinocchioArm(res.model.described(res.p))
    theta = data.points.q.copy()
    for _ in range(30):                                    # theta = q + c (0 - tau_gravity(theta)) on joint 2
        theta[:, 1] = data.points.q[:, 1] - c * arm.torques(theta)[0][:, 1]
    want = arm.torques(theta)[0]
    assert np.allclose(got, want, rtol=1e-6, atol=1e-9 * np.abs(want).max())
    assert np.abs(data.aux.tau_gravity - want).max() > 1e-3 * np.abs(want).max()     # the fits' own differ
