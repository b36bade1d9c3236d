"""Tracker campaigns: points with markers and sessions, frames and marker offsets estimated, written to the
model file and read back, and predicted by ``aacmm tip --reference-frame``.

Independent references: a campaign simulated here from known frames, offsets and arm errors (the truth);
Pinocchio's own frame placement for where a marker on the tip frame is; central differences of a numpy
implementation of the residuals for the Jacobians."""
from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from arm_model import InputError, PinocchioArm
from arm_model.cli import main
from arm_model.geometry import rotation_xyz
from arm_model.io import parse_points, write_csv
from arm_model.model import ArmModel
from arm_model.model_file import format_model, load_model, parse_model
from arm_model.sim.ik import random_q
from arm_model.tracker import Tracker, marker_positions, offset_matrix
from calibration import calibrate
from calibration.data import make_data
from calibration.kinds import tracker_start
from calibration.options import FitOptions
from calibration.problem import Problem
from conftest import assert_close

#: the truth of the simulated campaigns: two markers on the tip frame [m], two sessions' frames
OFFSETS = np.array([[0.012, -0.031, 0.046], [-0.028, 0.017, 0.071]])
FRAMES = {"mon": (np.array([0.4, -0.2, 1.1]), np.array([0.3, -0.5, 2.0])),
          "tue": (np.array([-0.7, 0.1, 0.4]), np.array([-1.2, 0.8, 1.5]))}


def _frame(t, rpy) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = rotation_xyz(rpy), t
    return out


def _truth_tracker(sessions=("mon", "tue"), offsets=OFFSETS) -> Tracker:
    return Tracker(sessions, [_frame(*FRAMES[s]) for s in sessions], offsets)


def _campaign(model, p_true, n=24, seed=1, noise=20e-6, sessions=("mon", "tue"), offsets=OFFSETS):
    """Points text of ``n`` poses a session, each marker of ``offsets`` seen by the instrument (noise
    ``noise`` per axis [m]) in the session's frame; and the noise-free coordinates."""
    rng = np.random.default_rng(seed)
    truth = _truth_tracker(sessions, offsets)
    q = random_q(model.desc, n * len(sessions), rng)
    sess = np.repeat(np.array(sessions, dtype=object), n)
    exact = marker_positions(model, p_true, q, truth, sess)
    seen = exact + rng.normal(0.0, noise, exact.shape)
    cols = {"measurement": np.array([f"pose-{i + 1:03d}" for i in range(len(q))], dtype=object),
            "feature": np.full(len(q), "", dtype=object), "session": sess}
    for j in range(q.shape[1]):
        cols[f"q{j + 1}_rad"] = q[:, j]
    for k in range(len(offsets)):
        for a, axis in enumerate("xyz"):
            cols[f"{axis}{k + 1}_ref_mm"] = seen[:, k, a] * 1e3
    return cols, q, sess, exact


# -- the points format ---------------------------------------------------------------------------

def test_markers_and_sessions_are_read_with_units():
    pts = parse_points("measurement,feature,session,q1_deg,x1_ref_mm,y1_ref_mm,z1_ref_mm,x2_ref_m,y2_ref_m,z2_ref_m\n"
                       "a,,s1,10,1,2,3,0.5,0.25,0.125\nb,,s2,20,4,5,6,1,2,3\n")
    assert pts.n_markers == 2 and pts.ref.shape == (2, 2, 3)
    assert_close(pts.ref[0], [[1e-3, 2e-3, 3e-3], [0.5, 0.25, 0.125]], atol=0)
    assert list(pts.session) == ["s1", "s2"]
    one = parse_points("measurement,feature,q1_deg,x_ref_mm,y_ref_mm,z_ref_mm\na,,1,1,2,3\n")
    assert one.ref.shape == (1, 1, 3) and one.session is None


@pytest.mark.parametrize("text, column, words", [
    ("q1_deg,x1_ref_mm,y1_ref_mm,z1_ref_mm,x3_ref_mm,y3_ref_mm,z3_ref_mm\na,,1,1,2,3,4,5,6", "x3_ref_mm",
     "marker 2 is missing"),
    ("q1_deg,x_ref_mm,y_ref_mm,z_ref_mm,x1_ref_mm,y1_ref_mm,z1_ref_mm\na,,1,1,2,3,4,5,6", "x_ref_mm", "both"),
    ("q1_deg,x2_ref_mm,y2_ref_mm\na,,1,1,2", "x2_ref_mm", "marker 1 is missing"),
    ("q1_deg,x1_ref_mm,y1_ref_mm\na,,1,1,2", "x1_ref_mm", "z1_ref missing"),
    ("q1_deg,x1_ref_deg,y1_ref_mm,z1_ref_mm\na,,1,1,2,3", "x1_ref_deg", "must be a length"),
    ("q1_deg,x0_ref_mm\na,,1,1", "x0_ref_mm", "unknown column"),
])
def test_bad_marker_columns_are_refused_with_their_column(text, column, words):
    with pytest.raises(InputError) as e:
        parse_points("measurement,feature," + text + "\n", "p.csv")
    assert e.value.column == column and words in str(e.value)


def test_an_empty_session_is_refused_with_its_line():
    with pytest.raises(InputError) as e:
        parse_points("measurement,feature,session,q1_deg\na,,s,1\nb,,,2\n", "p.csv")
    assert e.value.line == 3 and e.value.column == "session"


# -- where a marker is ---------------------------------------------------------------------------

@settings(max_examples=20, deadline=None)
@given(rpy=st.lists(st.floats(-3.1, 3.1), min_size=3, max_size=3),
       o=st.lists(st.floats(-0.2, 0.2), min_size=3, max_size=3))
def test_a_marker_is_the_tip_frame_point_pinocchio_places(nominal, rpy, o):
    """``offset_matrix``: the marker at ``o`` in a tip frame of any orientation is ``T_base_tip @ o``, with
    ``T_base_tip`` from Pinocchio's frame placement."""
    desc = nominal.with_probe(rpy=tuple(rpy))
    model = ArmModel(desc)
    q = random_q(desc, 3, np.random.default_rng(4))
    x = model.ball_centres(q, None, offset_matrix(model) @ np.array(o))
    pin = PinocchioArm(desc)
    for qi, xi in zip(q, x, strict=True):
        t = pin.T_base_ball(qi)
        assert_close(xi, t[:3, :3] @ o + t[:3, 3], atol=1e-12)


def test_the_first_fit_finds_exact_frames_and_offsets(nominal):
    """Noise-free data: the alternating Kabsch / least-squares start recovers the truth without any
    Levenberg-Marquardt step (to its stopping rule: 10 nm)."""
    model = ArmModel(nominal)
    cols, q, sess, exact = _campaign(model, np.zeros(model.spec.size), noise=0.0)
    data = make_data(parse_points(_text(cols), "t.csv", 7), None, model)
    prob = Problem(model, data, free=[])
    states = prob.initial_states(np.zeros(model.spec.size))
    got = prob.tracker(states)
    assert got.sessions == ("mon", "tue")
    for s in got.sessions:
        assert_close(got.frame(s), _truth_tracker().frame(s), atol=1e-8)
    assert_close(got.offsets, OFFSETS, atol=1e-8)


def test_tracker_start_holds_what_is_given():
    rng = np.random.default_rng(2)
    base = rng.normal(size=(12, 3))
    turn = np.stack([rotation_xyz(rng.uniform(-3, 3, 3)) for _ in range(12)])
    t = _frame(*FRAMES["mon"])
    o = np.array([0.1, 0.0, -0.05])
    x_ref = (base + turn @ o) @ t[:3, :3].T + t[:3, 3]
    fs, os = tracker_start(base, turn, x_ref, np.zeros(12, int), np.full(12, 1), [0], [1], [None], [o])
    assert_close(os[0], o, atol=0)
    assert_close(fs[0][9:12], t[:3, 3], atol=1e-12)


def _text(cols) -> str:
    from arm_model.csv_io import format_csv
    return format_csv(cols, "%.12g").decode()


# -- residuals and Jacobians with markers ----------------------------------------------------------

def _numpy_marker_residuals(prob, model, data, p, states):
    """A second implementation of the reference residuals of markers at offsets (numpy model, frames
    applied by hand), weighted."""
    m = offset_matrix(model)
    out = []
    for g in prob.groups:
        for pi, ii, mk in zip(g["points"], g["inst"], g["marker"], strict=True):
            o = states[mk][:3] if mk >= 0 else np.zeros(3)
            x = model.ball_centres(data.points.q[pi:pi + 1], None, p + m @ o)[0]
            s = states[ii]
            out.append(s[0:9].reshape(3, 3, order="F") @ x + s[9:12] - data.reference[pi])
    return np.concatenate(out) / prob.sigma


def test_marker_jacobians_match_finite_differences(nominal):
    model = ArmModel(nominal)
    cols, *_ = _campaign(model, np.zeros(model.spec.size), n=6, noise=1e-5)
    data = make_data(parse_points(_text(cols), "t.csv", 7), None, model)
    prob = Problem(model, data, free=np.arange(model.spec.size))
    p0 = np.full(model.spec.size, 1e-5)
    states = prob.initial_states(p0)
    assert sum(it.kind == "marker" and it.n_theta == 3 for it in prob.instances) == 2
    ev = prob.evaluate(p0, states)
    assert_close(ev.r, _numpy_marker_residuals(prob, model, data, p0, states), atol=1e-9)
    jt = ev.jt.toarray()
    for k in range(prob.n_nuisance):
        e = np.zeros(prob.n_nuisance)
        e[k] = 1e-7
        fd = (_numpy_marker_residuals(prob, model, data, p0, prob.retract(states, e))
              - _numpy_marker_residuals(prob, model, data, p0, prob.retract(states, -e))) / 2e-7
        assert np.abs(fd - jt[:, k]).max() <= 2e-5 * max(np.abs(fd).max(), 1.0), k
    for k in range(0, model.spec.size, 2):
        e = np.zeros(model.spec.size)
        e[k] = 1e-7
        fd = (_numpy_marker_residuals(prob, model, data, p0 + e, states)
              - _numpy_marker_residuals(prob, model, data, p0 - e, states)) / 2e-7
        assert np.abs(fd - ev.jp[:, k]).max() <= 2e-5 * max(np.abs(fd).max(), 1.0), model.spec.names[k]


# -- the estimates --------------------------------------------------------------------------------

def test_frames_and_offsets_are_estimated_within_their_uncertainty(nominal):
    """The nominal arm exact, only the frames and offsets unknown: each estimate within 4 standard
    uncertainties of the truth, and the uncertainties of the right size (not 10x too large)."""
    model = ArmModel(nominal)
    cols, *_ = _campaign(model, np.zeros(model.spec.size), n=30, noise=30e-6)
    data = make_data(parse_points(_text(cols), "t.csv", 7), None, model)
    res = calibrate(model, data, FitOptions(free=(), weights=replace(FitOptions().weights, probe=1e-9,
                                                                     reference=30e-6)))
    tr, truth = res.tracker, _truth_tracker()
    z = (tr.offsets - OFFSETS) / tr.u_offsets
    assert np.abs(z).max() < 4 and 1e-6 < tr.u_offsets.max() < 1e-4, z
    for i, s in enumerate(tr.sessions):
        zt = (tr.frames[i][:3, 3] - truth.frame(s)[:3, 3]) / tr.u_frames[i, :3]
        assert np.abs(zt).max() < 4, zt


# -- the command line -----------------------------------------------------------------------------

@pytest.fixture(scope="module")
def tracker_files(tmp_path_factory, nominal):
    """A campaign of two markers and two sessions on aacmm7 with joint-row errors (the truth), written as
    a points file without any artefacts file."""
    from arm_model.sim.quick import random_truth
    model = ArmModel(nominal)
    p_true = random_truth(model, np.random.default_rng(7), length=300e-6, angle=5e-4)
    cols, q, sess, exact = _campaign(model, p_true, n=30, noise=20e-6)
    out = tmp_path_factory.mktemp("tracker")
    write_csv(out / "points.csv", cols, fmt="%.12g")
    return out, cols, exact, p_true


def test_calibrate_without_artefacts_then_tip_predicts_the_instrument(tracker_files, tmp_path, capsys):
    src, cols, exact, _ = tracker_files
    held = [f"pose-{i:03d}" for i in range(5, 61, 5)]
    out = tmp_path / "cal"
    assert main(["calibrate", str(src / "points.csv"), "--arm", "aacmm7", "--holdout", ",".join(held),
                 "--no-plots", "-o", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["inputs"]["artefacts"] is None
    ref = summary["reference_frame"]
    assert [f["session"] for f in ref["frames"]] == ["mon", "tue"] and len(ref["markers"]) == 2
    assert ref["marker_offsets"] == "fit" and not {"probe.x", "probe.y", "probe.z"} & set(summary["free"])
    hold = {r["key"]: r for r in summary["validation_holdout"]}
    # the held-out prediction: the training fit's frames and offsets; the calibrated arm near the noise
    # (20 um per axis: 35 um in 3D), the nominal with its own frames and offsets far off
    assert hold["reference_rms_predicted"]["after"] < 60
    assert hold["reference_rms_predicted"]["before"] > 3 * hold["reference_rms_predicted"]["after"]
    arm = load_model(out / "aacmm7-calibrated.toml")
    assert arm.tracker.sessions == ("mon", "tue") and arm.tracker.offsets.shape == (2, 3)
    tips = tmp_path / "tips.csv"
    capsys.readouterr()
    assert main(["tip", str(src / "points.csv"), "--arm", str(out / "aacmm7-calibrated.toml"), "--reference-frame",
                 "-o", str(tips)]) == 0
    # its u_x_mm ... are of the tip in the base frame, with the frames' and offsets' share: it says so
    assert "cancels in x_ref_mm ... (no u there: docs/uncertainty.md" in capsys.readouterr().out
    t = np.genfromtxt(tips, delimiter=",", names=True, dtype=None, encoding="utf-8")
    rows = np.isin(cols["measurement"], held)
    for k in range(2):
        pred = np.column_stack([t[f"{a}{k + 1}_ref_mm"] for a in "xyz"]) * 1e-3
        err = np.linalg.norm(pred[rows] - exact[rows, k], axis=1)
        assert np.sqrt(np.mean(err ** 2)) < 40e-6, k            # against the noise-free truth
        measured = np.column_stack([cols[f"{a}{k + 1}_ref_mm"] for a in "xyz"]) * 1e-3
        assert_close(t[f"error{k + 1}_ref_um"], np.linalg.norm(measured - pred, axis=1) * 1e6, atol=2e-3)
    # a session the model has no frame for, or rows without a session column: one message, nothing written
    for name, columns in (("wed.csv", {**cols, "session": np.full(len(cols["session"]), "wed", dtype=object)}),
                          ("none.csv", {k: v for k, v in cols.items() if k != "session"})):
        write_csv(tmp_path / name, columns, fmt="%.12g")
        out_csv = tmp_path / f"{name}.tips.csv"
        assert main(["tip", str(tmp_path / name), "--arm", str(out / "aacmm7-calibrated.toml"), "--reference-frame",
                     "-o", str(out_csv)]) == 2 and not out_csv.exists()


def test_the_tracker_tables_read_back(nominal):
    rng = np.random.default_rng(3)
    tr = Tracker(("", "b"), [_frame(rng.normal(size=3), rng.uniform(-3, 3, 3)) for _ in range(2)],
                 rng.normal(0, 0.1, (3, 3)), np.abs(rng.normal(0, 1e-4, (2, 6))), np.abs(rng.normal(0, 1e-4, (3, 3))))
    back = parse_model(format_model(nominal, tracker=tr), "m.toml").tracker
    assert back.sessions == tr.sessions
    assert_close(back.frames, tr.frames, atol=1e-14)
    assert_close(back.offsets, tr.offsets, atol=0)
    assert_close(back.u_frames, tr.u_frames, atol=1e-20)
    assert_close(back.u_offsets, tr.u_offsets, atol=0)


@pytest.mark.parametrize("extra, key, words", [
    ('[[marker]]\nx_mm = 1\ny_mm = 2\nz_mm = 3\n', "marker", "need the [[reference_frame]]"),
    ('[[reference_frame]]\nx_mm = 1\ny_mm = 2\nz_mm = 3\nroll_deg = 0\npitch_deg = 0\nyaw_deg = 0\nscale = 2\n',
     "reference_frame", "no known unit suffix"),
    ('[[reference_frame]]\nx_mm = 1\ny_mm = 2\nz_mm = 3\nroll_deg = 0\npitch_deg = 0\n', "reference_frame",
     "missing key 'yaw_<unit>'"),
    ('[[reference_frame]]\nx_mm = 1\ny_mm = 2\nz_mm = 3\nroll_deg = 0\npitch_deg = 0\nyaw_deg = 0\n'
     '[[reference_frame]]\nx_mm = 1\ny_mm = 2\nz_mm = 3\nroll_deg = 0\npitch_deg = 0\nyaw_deg = 0\n',
     "reference_frame", "two reference frames"),
    ('[[reference_frame]]\nx_mm = 2e9\ny_mm = 2\nz_mm = 3\nroll_deg = 0\npitch_deg = 0\nyaw_deg = 0\n',
     "reference_frame", "x_mm"),
])
def test_bad_tracker_tables_are_refused_with_their_key(nominal, extra, key, words):
    text = format_model(nominal) + "\n" + extra
    with pytest.raises(InputError) as e:
        parse_model(text, "m.toml")
    assert key in e.value.column and words in str(e.value), str(e.value)


def _run(capsys, *argv) -> tuple[int, str]:
    code = main(list(argv))
    return code, capsys.readouterr().err


def test_tracker_input_errors_stop_with_one_message(tracker_files, tmp_path, capsys):
    src, cols, *_ = tracker_files
    bare = tmp_path / "bare.csv"
    write_csv(bare, {k: v for k, v in cols.items() if "_ref_" not in k}, fmt="%.12g")
    code, err = _run(capsys, "calibrate", str(bare), "--arm", "aacmm7", "-o", str(tmp_path / "a"))
    assert code == 2 and "no artefacts file and no reference columns" in err and not (tmp_path / "a").exists()
    feat = tmp_path / "feat.csv"
    write_csv(feat, {**cols, "feature": np.full(len(cols["feature"]), "seat-1", dtype=object)}, fmt="%.12g")
    code, err = _run(capsys, "calibrate", str(feat), "--arm", "aacmm7", "-o", str(tmp_path / "b"))
    assert code == 2 and "no artefacts file was given" in err and "line 2" in err
    code, err = _run(capsys, "calibrate", str(src / "points.csv"), "--arm", "aacmm7", "--marker-offset", "zero",
                     "-o", str(tmp_path / "c"))
    assert code == 2 and "2 markers" in err
    code, err = _run(capsys, "tip", str(src / "points.csv"), "--arm", "aacmm7", "--reference-frame",
                     "-o", str(tmp_path / "t.csv"))
    assert code == 2 and "[[reference_frame]]" in err and not (tmp_path / "t.csv").exists()


def test_the_tip_frame_only_moves_the_offsets(tracker_files, tmp_path):
    """The marker's link named at the flange (the last joint's origin, no stylus) or at the probe's ball:
    the same predictions, offsets apart by the fixed 180 mm between the two frames. The held-out set
    holds a single pose of session 'tue' (2 reference points): its frame is the training fit's."""
    from conftest import ROOT
    src = tracker_files[0]
    got = {}
    for tip in ("link_7", "ball"):
        out = tmp_path / tip
        assert main(["calibrate", str(src / "points.csv"), "--arm", str(ROOT / "urdf" / "aacmm7.urdf"), "--tip-frame",
                     tip, "--holdout", "pose-005,pose-010,pose-035", "--no-plots", "-o", str(out)]) == 0
        summary = json.loads((out / "summary.json").read_text())
        got[tip] = ({r["key"]: r["after"] for r in summary["validation_holdout"]},
                    load_model(out / "aacmm7-calibrated.toml").tracker)
    assert got["link_7"][0]["reference_rms_predicted"] == pytest.approx(got["ball"][0]["reference_rms_predicted"],
                                                                        rel=1e-6)
    assert_close(got["link_7"][1].offsets - got["ball"][1].offsets, [[0, 0, 0.18]] * 2, atol=1e-9)


def test_close_loop_without_artefacts(nominal, tmp_path):
    model = ArmModel(nominal)
    cols, *_ = _campaign(model, np.zeros(model.spec.size), n=10, noise=20e-6, sessions=("mon",))
    write_csv(tmp_path / "p.csv", cols, fmt="%.12g")
    out = tmp_path / "loop"
    assert main(["close-loop", str(tmp_path / "p.csv"), "--arm", "aacmm7", "--no-plots", "-o", str(out)]) == 0
    arm = load_model(out / "aacmm7-calibrated.toml")
    assert arm.tracker.sessions == ("mon",) and arm.tracker.offsets.shape == (2, 3)
    assert_close(arm.tracker.offsets, OFFSETS, atol=2e-4)


def test_poses_that_cannot_place_the_markers_are_a_numerical_failure(nominal, tmp_path, capsys):
    """Only the first joint moves: the tip frame turns about one axis, and a marker's offset along it
    moves the marker as the frame's translation does. The fit stops with that reason, nothing written."""
    model = ArmModel(nominal)
    cols, q, *_ = _campaign(model, np.zeros(model.spec.size), n=20, noise=0.0, sessions=("mon",))
    q[:, 1:] = q[0, 1:]
    exact = marker_positions(model, np.zeros(model.spec.size), q, _truth_tracker(("mon",)), cols["session"])
    noisy = exact + np.random.default_rng(5).normal(0, 20e-6, exact.shape)
    cols.update({f"q{j + 1}_rad": q[:, j] for j in range(7)})
    cols.update({f"{a}{k + 1}_ref_mm": noisy[:, k, i] * 1e3 for k in range(2) for i, a in enumerate("xyz")})
    write_csv(tmp_path / "p.csv", cols, fmt="%.12g")
    code, err = _run(capsys, "calibrate", str(tmp_path / "p.csv"), "--arm", "aacmm7", "-o", str(tmp_path / "cal"))
    assert code == 4 and "numerical failure:" in err
    assert "do not determine the instrument's frame and the markers' offsets" in err
    assert not (tmp_path / "cal").exists()


@settings(max_examples=25, deadline=None)
@given(k=st.integers(1, 4), n=st.integers(1, 6), unit=st.sampled_from(["mm", "m", "um"]),
       numbered=st.booleans(), data=st.data())
def test_marker_columns_read_back_whatever_their_count_and_unit(k, n, unit, numbered, data):
    """Points written with K markers (numbered, or one unnumbered), sessions and any length unit read back
    to the same metres."""
    numbered = numbered or k > 1
    values = np.array(data.draw(st.lists(st.floats(-1e3, 1e3, allow_nan=False), min_size=3 * k * n,
                                         max_size=3 * k * n))).reshape(n, k, 3)
    sessions = data.draw(st.lists(st.sampled_from(["a", "b c", "day-2"]), min_size=n, max_size=n))
    factor = {"mm": 1e-3, "m": 1.0, "um": 1e-6}[unit]
    cols = {"measurement": np.array([f"m{i}" for i in range(n)], dtype=object),
            "feature": np.full(n, "", dtype=object), "session": np.array(sessions, dtype=object),
            "q1_deg": np.arange(n, dtype=float)}
    for m in range(k):
        for a, axis in enumerate("xyz"):
            cols[f"{axis}{m + 1 if numbered else ''}_ref_{unit}"] = values[:, m, a]
    pts = parse_points(_text(cols), "p.csv")
    assert pts.n_markers == k and list(pts.session) == sessions
    assert_close(pts.ref, values * factor, atol=0, rtol=1e-11)


# -- close-loop's outer test set: a prediction, as calibrate's held-out figures ------------------------------------

def _loop_on_tracker(nominal, gross_mm: float = 0.0):
    """close-loop's first stage (:func:`calibration.loop.stages.prepare`: the split, the base fit on the design set,
    the test set's point test and its figures) on a tracker campaign of one session (16 poses, 2 markers, 20 um
    noise), the even poses held out; ``gross_mm``: marker 1 of pose-004 (held out) moved that far along x. Returns
    the loop's state and its test set."""
    from calibration.data import split_holdout
    from calibration.loop import LoopSettings
    from calibration.loop.stages import Campaign, prepare
    model = ArmModel(nominal)
    cols, *_ = _campaign(model, np.zeros(model.spec.size), n=16, noise=20e-6, sessions=("mon",))
    cols["x1_ref_mm"][3] += gross_mm
    text = ",".join(cols) + "\n" + "\n".join(",".join(str(cols[k][i]) for k in cols) for i in range(16))
    held = tuple(f"pose-{i:03d}" for i in range(2, 17, 2))
    state = prepare(Campaign(parse_points(text), None, nominal), LoopSettings(holdout=held, test_in_model=False),
                    lambda _: None)
    return state, split_holdout(state.data, list(held))[1]


def _predicted_rms(res, test) -> tuple[float, float]:
    """RMS of the markers' 3D errors and of their components [m], frames and offsets of the fit ``res``
    (arm_model.tracker, not the calibration code under test)."""
    x = marker_positions(res.model, res.p, test.points.q, res.tracker, test.sessions)
    e = x[np.arange(len(test)), test.markers] - test.reference
    return float(np.sqrt(np.mean(np.sum(e ** 2, axis=1)))), float(np.sqrt(np.mean(e ** 2)))


def test_close_loops_test_set_figure_is_calibrates_heldout_prediction(nominal):
    """The outer test set's figures are predictions with the design fit's frame and marker offsets, to 1e-9 m: of
    calibrate's held-out validation (validate with the fit's tracker) and of the markers placed by
    arm_model.tracker; refitting the frame and offsets on the test poses (the loop's old figure) gives less."""
    from calibration.validation import validate
    state, test = _loop_on_tracker(nominal)
    res, h = state.stages[0].result, state.stages[0].heldout
    rms3, rms = _predicted_rms(res, test)
    val = validate(res.model, res.p, test, res.weights, res.reference_mode, tracker=res.tracker)
    assert h["standard"]["reference_rms_predicted"] * 1e-6 == pytest.approx(rms3, abs=1e-9)
    assert val.reference_predicted["rms"] == pytest.approx(rms3, abs=1e-9)
    assert h["rms_um"] * 1e-6 == pytest.approx(rms, abs=1e-9) and h["nuisance"] == 0 and h["held"] == 6 + 2 * 3
    assert "reference_rms" not in h["standard"] and val.reference["rms"] < 0.9 * rms3      # refitted: smaller


def test_a_test_point_far_off_stays_in_the_figure_and_is_reported(nominal):
    """A held-out marker 3 mm off: the point test flags it (reported), the figure keeps it (equal to the
    prediction of every test point) and gives the figure without it beside (the prediction of the others)."""
    state, test = _loop_on_tracker(nominal, gross_mm=3.0)
    res, h = state.stages[0].result, state.stages[0].heldout
    rms3, rms = _predicted_rms(res, test)
    assert [f["measurement"] for f in state.flagged_entries] == ["pose-004"] and h["flagged_points"] == 1
    assert "pose-004" in state.test.measurements()
    assert h["standard"]["reference_rms_predicted"] * 1e-6 == pytest.approx(rms3, abs=1e-9)
    assert h["rms_um"] * 1e-6 == pytest.approx(rms, abs=1e-9) and rms > 2e-4
    clean = _predicted_rms(res, state.test.select(~state.flagged))[1]
    assert state.flagged.sum() == 1 and clean < 0.6 * rms
    assert h["rms_um_unflagged"] * 1e-6 == pytest.approx(clean, abs=1e-9)
