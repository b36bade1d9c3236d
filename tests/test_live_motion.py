"""A live session reads each joint's last move before a contact from its samples (:mod:`arm_model.live.motion`), so
a model with a :class:`~arm_model.effects.JointHysteresis` effect corrects its points as ``aacmm tip`` does given
the same motion (docs/live.md, "The last move of each joint")."""
from __future__ import annotations

import math

import numpy as np
import pytest

from arm_model.commands import tip_centres
from arm_model.effects import JointHysteresis
from arm_model.io import PointSet
from arm_model.live import Session
from arm_model.live.motion import BAND_STEPS, LastMove
from arm_model.model import reading_motion
from arm_model.model_file import Arm, load_model

STEP = math.radians(1e-4)                 # aacmm7's encoder step
HYSTERESIS = {"j2.hysteresis": 6e-5, "j3.hysteresis": -4e-5, "j5.hysteresis": 5e-5}     # [rad]
#: live's corrected points against tip's on the same readings and forces, the motion given [m]
TOL = 1e-10


def _session_stream(seed: int = 3, n_points: int = 12, rate: float = 1000.0):
    """Samples of an operator going from pose to pose (a smooth move of 0.3 s), holding still for a touch of
    1 N peaking 30 ms into it (60 ms), free for 0.1 s: readings quantised to the encoder's step, with one step of
    flicker on a tenth of the samples out of contact (a reading between two steps), the force with 0.01 N of
    noise. On every third move two joints overshoot their target by 30 steps and come back, so their last move is
    against the move from the point before; one joint stays put from point 7 to 8 (its last move is the one
    before). Returns the samples (t, q, wrench) and each point's true last move (n_points, 7)."""
    rng = np.random.default_rng(seed)
    desc = load_model("aacmm7").desc
    centre = np.radians([10.0, 40.0, 20.0, 60.0, -30.0, 40.0, 0.0])
    poses = centre + rng.uniform(-0.3, 0.3, (n_points, 7))
    poses[7, 2] = poses[6, 2]
    truth = np.zeros((n_points, 7))
    dt = 1.0 / rate
    samples, t, q_now = [], 0.0, poses[0].copy()

    def emit(q, force, free):
        nonlocal t
        r = np.round(q / STEP) * STEP
        if free:
            r = r + STEP * (rng.random(7) < 0.1) * rng.choice([-1.0, 1.0], 7)
        samples.append((t, tuple(r), tuple(force + rng.normal(0.0, 0.01, 3))))
        t += dt

    for _ in range(100):
        emit(q_now, np.zeros(3), True)
    for k in range(n_points):
        target = poses[k]
        via = target.copy()
        over = [1, 4] if k % 3 == 2 else []
        for j in over:                                     # beyond the target, then back
            via[j] += 30 * STEP * np.sign(target[j] - q_now[j])
        legs = [(q_now, via), (via, target)] if over else [(q_now, target)]
        if k > 0:
            moved = np.sign(target - q_now)
            truth[k] = np.where(moved == 0, truth[k - 1], moved)
            truth[k, over] = -moved[over]
            for a, b in legs:
                for x in np.linspace(0.0, 1.0, 300 // len(legs)):
                    emit(a + x * x * (3 - 2 * x) * (b - a), np.zeros(3), True)
        q_now = target
        for i in range(60):                                # held: the touch
            emit(q_now, np.array([0.0, 0.0, -math.sin(math.pi * i / 59)]), False)
        for _ in range(100):
            emit(q_now, np.zeros(3), True)
    return desc, samples, truth


@pytest.fixture(scope="module")
def hysteresis_session():
    desc, samples, truth = _session_stream()
    arm = Arm(desc, (JointHysteresis(joints=(1, 2, 4)),), dict(HYSTERESIS))
    session = Session(arm, rate=1000.0)
    for t, q, w in samples:
        session.push(t, q, w)
    session.close()
    return arm, session, truth


def test_live_points_are_tips_given_the_true_motion(hysteresis_session):
    arm, session, truth = hysteresis_session
    assert len(session.points) == len(truth)
    peaks = [p.contact.peak for p in session.points]
    ps = PointSet("<live>", np.array(["m"] * len(peaks)), np.array([""] * len(peaks)), np.array([s.q for s in peaks]),
                  force=np.array([s.wrench[:3] for s in peaks]), force_kind="xyz")
    live = np.array([p.corrected for p in session.points])
    given = tip_centres(arm, ps, truth)[1]
    assert np.max(np.abs(live - given)) <= TOL
    # the old behaviour (each point alone: a move of 0) is off by the hysteresis, tens of um
    alone = np.array([tip_centres(arm, ps.select([i]))[1][0] for i in range(len(ps))])
    assert np.max(np.linalg.norm(alone - given, axis=1)) > 2e-5
    # tip's own rule (the move from the point before) is wrong exactly where the operator overshot, or stayed put
    by_points = tip_centres(arm, ps)[1]
    off = np.linalg.norm(by_points - given, axis=1) > 1e-6
    assert off.tolist() == [k % 3 == 2 or k == 7 for k in range(len(truth))]


def test_the_band_holds_flicker_and_noise_and_a_real_move_turns_it():
    moves = LastMove([STEP] * 2)
    assert moves.band == [BAND_STEPS * STEP] * 2
    rng = np.random.default_rng(1)
    moves.free([0.0, 0.0])
    for x in np.arange(1, 50) * STEP:                       # joint 1 up 49 steps, joint 2 flickering
        moves.free([x, STEP * rng.integers(-1, 2)])
    assert moves.sign == [1.0, 0.0]
    moves.free([46.5 * STEP, 0.0])                          # 2.5 steps back: within the band
    assert moves.sign == [1.0, 0.0]
    moves.free([45.5 * STEP, 0.0])                          # 3.5 steps back: turned
    assert moves.sign == [-1.0, 0.0]
    for _ in range(200):                                    # held, white noise of 2 steps
        moves.held(list(rng.normal(0.0, 2 * STEP, 2)))
    moves.settle()
    assert np.allclose(moves.band, 10 * 2 * STEP, rtol=0.25)


def test_the_bundled_session_with_a_hysteresis_model_is_tips_byte_for_byte(tmp_path, capsys):
    """The bundled stream (the simulator's operator goes straight from point to point) with a model file of 100 and
    -50 urad of hysteresis on joints 2 and 4: ``aacmm tip`` on the session's ``points.csv`` writes its ``tips.csv``
    byte for byte (docs/live.md); the last moves read from the samples (its ``q1_move_sign`` ...) are the points' own
    rule's here; each point taken with a move of 0 (the session before it read any) was 38-91 um off, every point but
    the first."""
    import csv

    from arm_model.cli import main
    from arm_model.io import read_points
    from arm_model.model_file import format_model
    from conftest import ROOT

    desc = load_model("aacmm7").desc
    values = {"j2.hysteresis": 1e-4, "j4.hysteresis": -5e-5}
    model = tmp_path / "hysteresis.toml"
    model.write_text(format_model(desc, (JointHysteresis(joints=(1, 3)),), values))
    out = tmp_path / "live"
    assert main(["live", str(ROOT / "examples/live/samples.csv"), "--arm", str(model), "--speed", "0",
                 "-o", str(out)]) == 0
    assert main(["tip", str(out / "points.csv"), "--arm", str(model), "--uncertainty", "-o",
                 str(tmp_path / "again.csv")]) == 0
    capsys.readouterr()
    assert (tmp_path / "again.csv").read_bytes() == (out / "tips.csv").read_bytes()
    ps = read_points(out / "points.csv", desc.joint_quantities)
    assert ps.motion is not None and np.array_equal(ps.motion, reading_motion(ps.q, None, ps.time))
    arm = Arm(desc, (JointHysteresis(joints=(1, 3)),), values)
    alone = tip_centres(arm, ps, np.zeros(ps.q.shape))[1]
    with open(out / "tips.csv") as fh:
        live = np.array([[float(r[f"{a}_mm"]) * 1e-3 for a in "xyz"] for r in csv.DictReader(fh)])
    off = np.linalg.norm(alone - live, axis=1)
    assert len(off) == 19 and off[0] < 1e-9 and np.all(off[1:] > 3e-5), off


def test_a_record_where_the_operator_overshoots_gives_tips_again_byte_for_byte(tmp_path, capsys):
    """The simulated session above as a stream file, through ``aacmm live`` with a model file of its hysteresis:
    ``points.csv`` holds each point's true last move (``q1_move_sign`` ..., exactly the test's truth) and the band it
    was read with is in ``session.json``, so ``aacmm tip points.csv`` writes ``tips.csv`` byte for byte. The same
    file without the move columns (what the session wrote before) gives tip the move from the point before: 19-100 um
    off on the five points where the operator overshot or held a joint still, 0 elsewhere."""
    import csv
    import json

    from arm_model.cli import main
    from arm_model.io import read_points
    from arm_model.model_file import format_model

    desc, samples, truth = _session_stream()
    stream = tmp_path / "samples.csv"
    with open(stream, "w") as fh:
        fh.write(",".join(["time_s"] + [f"q{j + 1}_rad" for j in range(7)] + ["fx_N", "fy_N", "fz_N"]) + "\n")
        fh.writelines(",".join(map(repr, (t, *map(float, q), *map(float, w)))) + "\n" for t, q, w in samples)
    model = tmp_path / "hysteresis.toml"
    model.write_text(format_model(desc, (JointHysteresis(joints=(1, 2, 4)),), dict(HYSTERESIS)))
    out = tmp_path / "live"
    assert main(["live", str(stream), "--arm", str(model), "--speed", "0", "-o", str(out)]) == 0
    points = out / "points.csv"
    assert np.array_equal(read_points(points, desc.joint_quantities).motion, truth)
    band = json.loads((out / "session.json").read_text())["last_move"]
    assert band["band_steps"] == BAND_STEPS and [j["dead_band_rad"] for j in band["joints"]] == [BAND_STEPS * STEP] * 7
    assert main(["tip", str(points), "--arm", str(model), "--uncertainty", "-o", str(tmp_path / "again.csv")]) == 0
    assert (tmp_path / "again.csv").read_bytes() == (out / "tips.csv").read_bytes()
    rows = list(csv.reader(open(points)))                     # before: no column for the moves
    keep = [k for k, h in enumerate(rows[0]) if not h.endswith("_move_sign")]
    (tmp_path / "old.csv").write_text("".join(",".join(r[k] for k in keep) + "\n" for r in rows))
    assert main(["tip", str(tmp_path / "old.csv"), "--arm", str(model), "-o", str(tmp_path / "old-tips.csv")]) == 0
    capsys.readouterr()

    def centres(path):
        with open(path) as fh:
            return np.array([[float(r[f"{a}_mm"]) for a in "xyz"] for r in csv.DictReader(fh)])
    off = np.linalg.norm(centres(tmp_path / "old-tips.csv") - centres(out / "tips.csv"), axis=1) * 1e3    # [um]
    wrong = [k % 3 == 2 or k == 7 for k in range(len(truth))]
    assert np.all(off[wrong] > 15) and np.all(off[wrong] < 110) and np.all(off[~np.array(wrong)] < 1e-3), off
