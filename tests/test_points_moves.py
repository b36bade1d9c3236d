"""Each joint's last move as a points file gives it: the optional columns ``q1_move_sign`` ... ``qJ_move_sign``
(docs/formats.md §3), read by the one points reader into ``PointSet.motion`` and taken by
:func:`arm_model.model.points_motion` before the points' own rule (the move from the point before)."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from arm_model import InputError
from arm_model.io import PointSet, move_columns, parse_points
from arm_model.model import points_motion, reading_motion

#: what a cell of a move column may read: the numbers -1, 0 and 1 as a file may spell them (decimals, no exponent)
SPELLINGS = {-1.0: ("-1", "-1.0", "-1."), 0.0: ("0", "0.0", "-0", "+0", " 0 "), 1.0: ("1", "1.0", "+1", "1.000")}


@st.composite
def moves_files(draw):
    """(text, J, (N, J) moves, (N, J) readings [rad], the columns' order): a points file with move columns in
    any order among the others, each cell in one of its spellings."""
    n_joints = draw(st.integers(1, 8))
    n = draw(st.integers(1, 6))
    moves = np.array(draw(st.lists(st.lists(st.sampled_from([-1.0, 0.0, 1.0]), min_size=n_joints,
                                            max_size=n_joints), min_size=n, max_size=n)))
    q = np.array(draw(st.lists(st.lists(st.floats(-3.0, 3.0), min_size=n_joints, max_size=n_joints),
                               min_size=n, max_size=n)))
    header = ["measurement", "feature"] + [f"q{j + 1}_rad" for j in range(n_joints)] + move_columns(n_joints)
    order = draw(st.permutations(range(len(header))))
    rows = []
    for i in range(n):
        cells = [f"m{i % 2}", "f"] + [repr(float(x)) for x in q[i]]
        cells += [draw(st.sampled_from(SPELLINGS[float(m)])) for m in moves[i]]
        rows.append(",".join(cells[k] for k in order))
    return "\n".join([",".join(header[k] for k in order)] + rows) + "\n", n_joints, moves, q


@settings(max_examples=60, deadline=None)
@given(moves_files())
def test_the_moves_read_back_exactly_whatever_the_columns_order(case):
    text, n_joints, moves, q = case
    ps = parse_points(text, "moves.csv", n_joints)
    assert ps.motion is not None and ps.motion.tobytes() == moves.tobytes()     # -0 read as 0: the same bits
    assert ps.q.tobytes() == q.tobytes()
    assert points_motion(ps) is ps.motion                       # the data's own, not the rule
    assert points_motion(ps.select([len(ps) - 1])).tolist() == [moves[-1].tolist()]


def _file(n_joints: int, header_moves: list[str], cells: list[str]) -> str:
    header = ["measurement", "feature"] + [f"q{j + 1}_deg" for j in range(n_joints)] + header_moves
    row = ["m", "f"] + ["10.5"] * n_joints + cells
    return ",".join(header) + "\n" + ",".join(["m", "f"] + ["1.0"] * n_joints + ["0"] * len(cells)) + "\n" + \
        ",".join(row) + "\n"


@settings(max_examples=80, deadline=None)
@given(st.integers(1, 8), st.data(),
       st.one_of(st.floats(allow_nan=False, allow_infinity=False).filter(lambda v: v not in (-1.0, 0.0, 1.0))
                 .map(repr), st.sampled_from(["nan", "inf", "-inf", "", "x", "1_0", "0x1", "true", "1e0", "1e-400",
                                              "0.99999999999999999", "1.00000000000000001", "--1", "01"])))
def test_a_move_other_than_minus_one_zero_one_is_refused_at_its_cell(n_joints, data, bad):
    k = data.draw(st.integers(0, n_joints - 1))
    cells = ["1"] * n_joints
    cells[k] = bad
    with pytest.raises(InputError) as e:
        parse_points(_file(n_joints, move_columns(n_joints), cells), "bad.csv", n_joints)
    assert (e.value.path, e.value.line, e.value.column) == ("bad.csv", 3, f"q{k + 1}_move_sign"), str(e.value)


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 8), st.data())
def test_a_partial_set_or_a_move_for_a_joint_not_there_is_refused_at_the_header(n_joints, data):
    """All or none: a proper subset of the joints' moves, or one beyond the joint columns, is one error naming the
    file, the header line and a move column; the message names the columns missing (or the joint not there)."""
    have = data.draw(st.sets(st.integers(1, n_joints + 2), min_size=1).filter(
        lambda s: s != set(range(1, n_joints + 1))))
    names = [f"q{i}_move_sign" for i in sorted(have)]
    with pytest.raises(InputError) as e:
        parse_points(_file(n_joints, names, ["1"] * len(names)), "part.csv", n_joints)
    assert e.value.path == "part.csv" and e.value.line == 1 and e.value.column in names, str(e.value)
    beyond = [i for i in have if i > n_joints]
    if beyond:
        assert e.value.column == f"q{min(beyond)}_move_sign"
        assert f"joint {min(beyond)}, but the points have {n_joints} joint columns" in e.value.reason
    else:
        missing = sorted(set(range(1, n_joints + 1)) - have)
        assert e.value.reason.startswith(f"columns {', '.join(f'q{i}_move_sign' for i in missing)} missing")


def test_a_point_set_built_in_python_is_held_to_the_same_values():
    q = np.zeros((2, 3))
    with pytest.raises(ValueError, match=r"last move of joint 2 of row 2, line 7 is 0\.5: it is -1, 0 or 1"):
        PointSet("p", np.array(["m", "m"]), np.array(["", ""]), q, lines=np.array([3, 7]),
                 motion=np.array([[1, 0, -1], [0, 0.5, 0]]))
    with pytest.raises(ValueError, match="last move of joint 1 of row 1 is nan"):
        PointSet("p", np.array(["m", "m"]), np.array(["", ""]), q, motion=np.array([[np.nan, 0, 0], [0, 0, 0]]))
    with pytest.raises(ValueError, match=r"motion must be \(N, joints\)"):
        PointSet("p", np.array(["m", "m"]), np.array(["", ""]), q, motion=np.zeros((2, 2)))


def test_without_the_columns_the_rule_and_a_merged_file_keeps_each_files_own():
    """No columns: the points' rule, as before. A file with the columns joined to one without (a reference-points
    file): each row keeps its own file's: the measured moves, or that file's rule on its own rows."""
    from calibration.data import merge_points

    q = np.array([[0.0, 0.0], [0.1, -0.1], [0.05, 0.2]])
    text = "measurement,feature,q1_rad,q2_rad\n" + "".join(f"m,,{float(a)!r},{float(b)!r}\n" for a, b in q)
    plain = parse_points(text, "plain.csv")
    assert plain.motion is None
    assert points_motion(plain).tolist() == reading_motion(q).tolist() == [[0, 0], [1, -1], [-1, 1]]
    measured = parse_points("measurement,feature,q1_rad,q2_rad,q1_move_sign,q2_move_sign\n"
                            "n,,0.3,0.3,-1,-1\nn,,0.4,0.4,0,1\n", "live.csv")
    merged, files = merge_points(measured, plain)
    assert merged.motion is not None
    assert merged.motion.tolist() == [[-1, -1], [0, 1], [0, 0], [1, -1], [-1, 1]]
    assert files.tolist() == ["live.csv"] * 2 + ["plain.csv"] * 3
    assert merge_points(plain, plain)[0].motion is None          # neither has them: the rule on the whole, as before


def test_tip_refuses_a_bad_move_with_file_line_column_and_writes_nothing(tmp_path, capsys):
    from arm_model.cli import main

    good = "measurement,feature," + ",".join(f"q{j}_deg" for j in range(1, 8)) + "," + ",".join(move_columns(7))
    bad = tmp_path / "points.csv"
    bad.write_text(good + "\nm,," + ",".join(["10"] * 7) + ",1,0,-1,0,0,2,0\n")
    assert main(["tip", str(bad), "--arm", "aacmm7", "-o", str(tmp_path / "tips.csv")]) == 2
    err = capsys.readouterr().err
    assert f"{bad}, line 2, column 'q6_move_sign': a joint's last move is -1, 0 or 1" in err, err
    assert "Traceback" not in err and not (tmp_path / "tips.csv").exists()


def test_calibrate_takes_the_measured_moves_and_recovers_a_known_hysteresis():
    """A simulated campaign (ball bars, seats, spheres: 64 points) on an arm whose joints 2 and 4 sit 50 and -40 urad
    beyond their encoders by the direction each last turned; on a third of the points (drawn) the operator overshot
    and came back, so the last move is against the move from the point before. The file with ``q1_move_sign`` ...
    gives the fit the true moves; the same file without them, the points' rule. Fitted with the hysteresis of both
    joints free (no prior), from the file through the reader: with the columns 0.5 and 0.4 urad off the truth (s0
    0.75), without 55 and 16 urad off (s0 14.5) (seeds 1 and 2: 0.8, 0.7 against 40, 16 urad; 0.4, 0.2 against
    7, 4 urad)."""
    from arm_model import load_description
    from arm_model.effects import JointHysteresis
    from arm_model.model import ArmModel
    from arm_model.sim.quick import SynthSpec, make_campaign
    from calibration.calibrate import FitOptions, calibrate
    from calibration.data import Weights, make_data
    from conftest import NOMINAL

    nominal = load_description(NOMINAL)
    truth_h = {1: 5e-5, 3: -4e-5}                                     # [rad]
    camp = make_campaign(ArmModel(nominal), SynthSpec(ballbars=4, ballbar_points=4, seats=2, articulations=8,
                                                      spheres=2, sphere_points=8, noise=1e-6), seed=0,
                         p_true=np.zeros(ArmModel(nominal).spec.size))
    pts = camp.points
    rng = np.random.default_rng(0)
    moves = reading_motion(pts.q, pts.session, pts.time)
    over = rng.random(len(pts)) < 1 / 3
    q = pts.q.copy()
    for j, h in truth_h.items():
        moves[over, j] = -moves[over, j]
        q[:, j] -= h * moves[:, j]                      # the encoder reads h m short of where the joint sits
    model = ArmModel(nominal, (JointHysteresis(joints=tuple(truth_h)),))
    errors = {}
    for columns in (True, False):
        header = ["measurement", "feature"] + [f"q{j + 1}_rad" for j in range(7)] + (move_columns(7) if columns else [])
        lines = [",".join([pts.measurement[i], pts.feature[i]] + [repr(float(x)) for x in q[i]]
                          + ([str(int(m)) for m in moves[i]] if columns else [])) for i in range(len(q))]
        path = f"<campaign {'with' if columns else 'without'} moves>"
        ps = parse_points("\n".join([",".join(header)] + lines) + "\n", path, nominal.joint_quantities)
        res = calibrate(model, make_data(ps, camp.artefacts, model),
                        FitOptions(weights=Weights(probe=1e-6), prior_scale=None))
        errors[columns] = [abs(res.value(f"j{j + 1}.hysteresis") - h) for j, h in truth_h.items()]
    assert max(errors[True]) < 2e-6, errors                  # the truth within 2 urad
    assert min(errors[False]) > 1e-5, errors                 # the rule: 10 urad and more off
