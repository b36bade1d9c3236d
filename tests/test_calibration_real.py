"""calibrate's default estimation on real robots measured by others (docs/studies/calibration.md, "Real data").

* Panda seats (examples/data/real-panda-seats, the same as ../shared/data/real-panda-seats): trained on one
  plate placement, the other two predicted. The published tool's figures are MUKCa's method (its
  ``ParameterOptimizer.optimize()`` defaults) re-run on these data outside the project: mean held-out seat
  spread 2.073 mm, mean |distance error| 0.666 mm (docs/studies/calibration.md says how).
* TALOS motion capture (../shared/data/real-talos-mocap; its URDF may not be copied into the project, so the
  test reads it there and skips when it is absent): fit on the odd postures, predict the even ones with the
  training fit's frame and marker offset. The README of the data states the nominal (frames and marker
  fitted) at 5.84 mm and FIGAROH at 1.26 mm.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from arm_model.io import read_artefacts, read_points
from arm_model.model import ArmModel
from arm_model.urdf_import import load_arm
from calibration import FitOptions, calibrate, make_data
from calibration.calibrate import nominal_baseline
from calibration.data import split_holdout
from calibration.placements import seat_figures

ROOT = Path(__file__).resolve().parents[1]
PANDA = ROOT / "examples" / "data" / "real-panda-seats"
TALOS = ROOT.parent / "shared" / "data" / "real-talos-mocap"
PLACES = ("front", "right", "back-high")
#: MUKCa (platonics-delft/kinematics_calibration) on these data: mean held-out spread, mean |distance error| [mm]
MUKCA_SPREAD, MUKCA_DISTANCE = 2.073, 0.666


def _panda(effects=()):
    desc = load_arm(PANDA / "panda-with-inertials.urdf", "ball_link")
    model = ArmModel(desc, tuple(effects))
    art = read_artefacts(PANDA / "artefacts.toml")
    return model, {p: make_data(read_points(PANDA / p / "points.csv", 7), art, model) for p in PLACES}


def _placements(model, data):
    """Every placement trained on, the other two predicted: (fits, [(spread [mm], distance error [mm])])."""
    fits, out = {}, []
    for tr in PLACES:
        fits[tr] = res = calibrate(model, data[tr], FitOptions(weights_from_data=True))
        for te in PLACES:
            if te != tr:
                d = data[te]
                f = seat_figures(model.ball_centres(d.points.q, d.wrench, res.p, d.aux), d.points.feature,
                                 ("hole-0", "hole-1"), 0.05)
                out.append((f["spread_mean_mm"], f["distance_error_mm"]))
    return fits, np.array(out)


def test_panda_geometry_ties_the_published_tool_and_nothing_is_held_for_being_weak():
    """Default calibrate (geometry only), each placement predicting the other two: mean held-out spread at
    most MUKCa's (measured 2.04 mm, 0.99x), distance error within 0.1 mm of it (measured 0.71 mm); no
    parameter held for being weak, the held ones exact rank deficiencies with their combination; the noise
    estimated with the scales (0.13-0.2 mm per axis)."""
    model, data = _panda()
    fits, fig = _placements(model, data)
    assert fig[:, 0].mean() <= MUKCA_SPREAD, fig
    assert np.abs(fig[:, 1]).mean() <= MUKCA_DISTANCE + 0.1, fig
    for res in fits.values():
        assert res.evidence[-1]["settled"] and len(res.free) == 23
        assert all("weakly" not in f.reason for f in res.fixed)
        assert all(f.combination is not None for f in res.fixed)
        sigma = [v["sigma_um"] for v in res.variance if v["group"] == "seat"][0]
        assert 100 < sigma < 250, sigma


def test_panda_joint_compliance_is_non_negative_and_its_prior_comes_from_the_masses(tmp_path):
    """With the joint compliance effect (the URDF's link masses): every compliance is non-negative (held at
    its bound 0 when the data pull it below, and said so), its prior size is 10 mrad over the RMS gravity torque
    the data give the joint, none strays beyond three prior sizes; the held-out spread falls to at most 0.9x
    MUKCa's (measured 1.77 mm, 0.85x; the scale physical, 1); the model file written reads back in tip."""
    from arm_model.effects import JointCompliance
    from calibration.prior import DEFLECTION
    model, data = _panda((JointCompliance(),))
    fits, fig = _placements(model, data)
    assert fig[:, 0].mean() <= 0.9 * MUKCA_SPREAD, fig
    for tr, res in fits.items():
        tau = data[tr].aux.tau_gravity
        for k, n in enumerate(res.free):
            if n.endswith(".compliance"):
                j = [jr.name for jr in model.desc.joints].index(n.split(".")[0])
                rms = np.sqrt(np.mean(tau[:, j] ** 2))
                assert res.prior_sd[k] == pytest.approx(res.prior_scales["effect joint_compliance"] * DEFLECTION / rms,
                                                        rel=1e-9)
                assert res.value(n) >= 0.0
                assert abs(res.value(n)) <= 3 * res.prior_sd[k]
        for f in res.fixed:
            if f.name.endswith(".compliance"):
                assert f.value == 0.0 and ("bound" in f.reason or f.combination is not None), f
    from arm_model.cli import main
    out = tmp_path / "cal"
    assert main(["calibrate", str(PANDA / "front" / "points.csv"), str(PANDA / "artefacts.toml"), "--arm",
                 str(PANDA / "panda-with-inertials.urdf"), "--tip-frame", "ball_link", "--effect",
                 "joint_compliance", "--no-plots", "-q", "-o", str(out)]) == 0
    assert main(["tip", str(PANDA / "right" / "points.csv"), "--arm", str(out / "panda-calibrated.toml"),
                 "-o", str(tmp_path / "tip.csv"), "-q"]) == 0


@pytest.fixture(scope="module")
def talos():
    """The TALOS chain (torso, left arm, gripper) from ../shared's URDF as it ships, its points without an
    artefacts file (the marker's offset on the gripper an unknown of every fit), and the README's split."""
    urdf = TALOS / "talos_full_v2.urdf"
    if not urdf.exists():
        pytest.skip(f"the TALOS motion-capture data are not here ({TALOS}): they are read from ../shared, "
                    "never copied into the project (the URDF's licence)")
    desc = load_arm(urdf, "gripper_left_base_link")
    model = ArmModel(desc)
    data = make_data(read_points(TALOS / "points.csv", desc.n_joints), None, model)
    train, test = split_holdout(data, [f"pose-{i:02d}" for i in range(2, 62, 2)])
    return model, train, test


def _predicted_rms(res, test) -> float:
    """RMS [mm] over the held-out postures of the marker's 3D error, frame and marker offset of the fit."""
    from arm_model.tracker import marker_positions
    x = marker_positions(res.model, res.p, test.points.q, res.tracker, test.sessions, test.aux)[:, 0]
    return float(np.sqrt(np.mean(np.sum((x - test.reference) ** 2, axis=1)))) * 1e3


def test_talos_nominal_baseline_is_the_readmes_and_calibrate_beats_it(talos):
    """The like-for-like nominal (frame and marker offset fitted, nothing else) gives the README's 5.84 mm;
    calibrate of the geometry alone (the command's ``--effect none``; its default adds the joint compliance,
    below) predicts the held-out postures to 1.37 mm (measured; FIGAROH 1.26 mm), never holding
    the unknown marker offset for being weak, with the noise estimated at the capture's 0.2 mm per axis."""
    model, train, test = talos
    base = nominal_baseline(model, train, FitOptions(weights_from_data=True))
    assert base.free == () and base.tracker.offsets.shape == (1, 3)      # the frame and the marker only
    assert _predicted_rms(base, test) == pytest.approx(5.84, abs=0.01)
    res = calibrate(model, train, FitOptions(weights_from_data=True))
    rms = _predicted_rms(res, test)
    assert rms <= 1.45, rms
    # the marker's offset is an unknown of the fit (a nuisance, like the frame): never held, never shrunk
    assert res.tracker.offsets.shape == (1, 3) and np.all(np.isfinite(res.tracker.u_offsets))
    assert not {"probe.x", "probe.y", "probe.z"} & set(res.free)
    sigma = [v["sigma_um"] for v in res.variance if v["group"] == "reference"][0]
    assert 150 < sigma < 300, sigma


def test_panda_heldout_uncertainty_coverage(tmp_path):
    """Each placement's model file applied by ``aacmm tip`` to the other two placements;
    each corrected centre's deviation from its seat's mean lies within 1.96 u (tip's u: the posterior
    covariance, prior-dominated parameters included, the probing scatter and the model discrepancy of the
    extrapolative cross-validation, growing with each joint's travel from the nearest training pose, its estimates'
    uncertainty carried) for 90-97 % of the axis values pooled (measured 96.8 %, 83.9-100 % per pair; with one
    growth for every joint at its estimate 94.7 %, 73.9-100 %; with a constant discrepancy 88.9 %, without one
    86.2 %; the hold rule of earlier versions: 73.6 %, 58-91 %)."""
    import csv

    from arm_model.cli import main
    inside = []
    for tr in PLACES:
        out = tmp_path / tr
        assert main(["calibrate", str(PANDA / tr / "points.csv"), str(PANDA / "artefacts.toml"), "--arm",
                     str(PANDA / "panda-with-inertials.urdf"), "--tip-frame", "ball_link", "--no-plots", "-q",
                     "-o", str(out)]) == 0
        for te in PLACES:
            if te == tr:
                continue
            tip = tmp_path / f"{tr}-{te}.csv"
            assert main(["tip", str(PANDA / te / "points.csv"), "--arm", str(out / "panda-calibrated.toml"), "-q",
                         "-o", str(tip)]) == 0
            rows = list(csv.DictReader(open(tip)))
            x = np.array([[float(r[f"{a}_mm"]) for a in "xyz"] for r in rows])
            u = np.array([[float(r[f"u_{a}_mm"]) for a in "xyz"] for r in rows])
            f = np.array([r["feature"] for r in rows])
            for h in set(f):
                inside.append((np.abs(x[f == h] - x[f == h].mean(axis=0)) <= 1.96 * u[f == h]).ravel())
    pooled = np.concatenate(inside).mean()
    assert 0.90 <= pooled <= 0.97, pooled


#: FIGAROH 1.0.2 (its TALOS example settings: Levenberg-Marquardt, a ridge of 1e-3 on the joint parameters, frame
#: and marker free) re-run outside the project on the same random splits (seeds as below): held-out RMS [mm]
FIGAROH_HALVES = {0: 0.851, 1: 0.768}


def _talos_split(talos_all, n, seed):
    """A random training set of ``n`` postures (numpy default_rng(seed)), the rest held out."""
    model, data = talos_all
    ids = list(dict.fromkeys(data.points.measurement.tolist()))
    train = set(np.random.default_rng(seed).choice(ids, n, replace=False))
    return split_holdout(data, [m for m in ids if m not in train])


@pytest.fixture(scope="module")
def talos_all(talos):
    from arm_model.effects import JointCompliance
    model = ArmModel(talos[0].desc, (JointCompliance(),))
    return model, make_data(read_points(TALOS / "points.csv", model.desc.n_joints), None, model)


def test_talos_joint_compliance_carries_over_to_random_halves(talos_all):
    """On random halves of the 61 postures (scripts/mocap_study.py's seeds 100, 101) joint compliance with
    its mass-based prior predicts the held-out postures at most 0.9x FIGAROH's error on the same split
    (measured 0.683 and 0.678 mm against 0.851 and 0.768: 0.84x), the compliance of arm_left_3 estimated
    non-negative and several standard uncertainties from 0 (measured about 1 mrad/(N m))."""
    model, _ = talos_all
    ratios = []
    for s, fig in FIGAROH_HALVES.items():
        train, test = _talos_split(talos_all, 31, 100 + s)
        res = calibrate(model, train, FitOptions(weights_from_data=True))
        ratios.append(_predicted_rms(res, test) / fig)
        k = res.free.index("arm_left_3_joint.compliance")
        assert res.p[model.spec.index("arm_left_3_joint.compliance")] > 3 * res.u[k] > 0
    assert np.mean(ratios) <= 0.9, ratios


def _scale_ratios(talos_all, seeds, groups=("lengths", "axis angles", "joint offsets")) -> dict:
    """(group, factor) -> the held-out RMS on the random halves of ``seeds`` with that group's scale halved or
    doubled (the others and the noise as the evidence chose them) over the RMS at the evidence's scales. The noise
    is held at the evidence's estimate: estimated again at each scale (the noise alone, to 3 %), the reference fit
    at the evidence's own scales stopped a round earlier or later as the angles' scale moved by 1 % (7.37 -> 7.41)
    and predicted 0.657 or 0.681 mm, against 0.683 mm for the evidence's fit itself."""
    model, _ = talos_all
    ratios: dict = {}
    for s in seeds:
        train, test = _talos_split(talos_all, 31, s)
        res = calibrate(model, train, FitOptions(weights_from_data=True))
        chosen, noise = res.prior_scales, res.weights
        at = _predicted_rms(calibrate(model, train, FitOptions(weights=noise, prior_scale=dict(chosen))), test)
        for group in groups:
            for factor in (0.5, 2.0):
                moved = calibrate(model, train, FitOptions(weights=noise,
                                                           prior_scale={**chosen, group: chosen[group] * factor}))
                ratios.setdefault((group, factor), []).append(_predicted_rms(moved, test) / at)
    return ratios


def test_talos_evidence_scale_of_the_lengths_sits_at_the_held_out_optimum_on_one_half(talos_all):
    """The study below on one half (seed 100) and the group nearest its bound, the lengths (about 3 s of CPU):
    halved or doubled, the held-out error is not 3 % lower (measured 1.076 and 0.984). (Starting from a lengths
    scale 4 times too small, doubling it predicts 15 % better: 0.848.)"""
    for key, r in _scale_ratios(talos_all, (100,), ("lengths",)).items():
        assert r[0] >= 0.97, (key, r)


@pytest.mark.slow
def test_talos_evidence_scales_sit_at_the_held_out_optimum(talos_all):
    """On random halves (seeds 100, 101) the geometry's group scales the evidence chooses are where the
    held-out error is flat: halving or doubling any one group's scale (the others and the noise as chosen)
    does not predict the held-out postures better by more than 3 % on average (measured: the best of the six
    is 0.99x; over 25 halves the medians are 0.996-1.029x, docs/studies/calibration.md, "Where the remaining held-out
    error comes from"), so the shrinkage is not what keeps the default above the noise floor."""
    for key, r in _scale_ratios(talos_all, (100, 101)).items():
        assert np.mean(r) >= 0.97, (key, r)


def test_talos_joint_compliance_extrapolates_on_the_readmes_split(talos, talos_all):
    """On the README's split (the odd postures: the capture's heights of about 0.2 and 0.53 m; the even ones
    held out, among them every posture of the lowest level, beyond the training range) joint compliance with
    its physical prior (10 mrad under each joint's RMS gravity torque, its scale not shrunk by the evidence)
    predicts the held-out postures to at most 0.82x FIGAROH's 1.26 mm (measured 0.998 mm; with the scale
    chosen by the evidence, as before, 1.35 mm: the evidence shrank the compliances the training poses see
    weakly to zero and left their signature to the geometry); the group's scale stays 1 while the geometry's
    groups are estimated."""
    model = talos_all[0]
    _, train, test = talos
    train, test = (make_data(d.points, None, model) for d in (train, test))
    res = calibrate(model, train, FitOptions(weights_from_data=True))
    assert _predicted_rms(res, test) <= 0.82 * 1.26
    assert res.prior_scales["effect joint_compliance"] == 1.0
    assert res.prior_scales["joint offsets"] > 2.0           # the geometry's scales are the evidence's
    for n in res.free:
        if n.endswith(".compliance"):
            assert res.value(n) >= 0.0


def test_talos_17_postures_never_worse_than_the_nominal(talos, talos_all):
    """Trained on 17 random postures (seeds 17000-17002), the other 44 predicted: default calibrate and
    calibrate with joint compliance both beat the like-for-like nominal by at least 4x (measured 5.76 mm
    nominal, 1.12 and 0.99 mm)."""
    plain = talos[0]
    for seed in (17000, 17001, 17002):
        train, test = _talos_split(talos_all, 17, seed)
        base = _predicted_rms(nominal_baseline(plain, train, FitOptions(weights_from_data=True)), test)
        for model in (plain, talos_all[0]):
            rms = _predicted_rms(calibrate(model, train, FitOptions(weights_from_data=True)), test)
            assert rms <= base / 4, (seed, rms, base)
