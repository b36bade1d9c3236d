"""URDF in and out: the tip frame's full pose, the project's own elastic joints, masses folded from
<inertial> or a masses file against Pinocchio's RNEA on the user's file, and the calibrated URDF that is
the user's own file with only the identified origins changed."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from lxml import etree

from arm_model import InputError, PinocchioArm, apply_params, ball_centres, casadi_ball_centre, param_spec
from arm_model.cli import main
from arm_model.description import format_description, parse_description
from arm_model.urdf_import import calibrated_urdf_text, description_from_urdf, load_arm, load_masses
from conftest import NOMINAL, ROOT, assert_close, assert_evaluators_agree

PANDA = ROOT / "examples" / "data" / "real-panda-seats" / "panda.urdf"
PANDA_INERTIAL = ROOT / "examples" / "data" / "real-panda-seats" / "panda-with-inertials.urdf"
G = np.array([0.0, 0.0, -9.81])


def _pin_model(path_or_text):
    import pinocchio as pin
    text = path_or_text if isinstance(path_or_text, str) else path_or_text.read_text()
    model = pin.buildModelFromXML(text)
    model.gravity.linear = G.copy()
    return model


def _q_full(model, desc, q):
    """Pinocchio configuration of the user's whole URDF: the chain's joints at q, the rest at zero."""
    x = np.zeros(model.nq)
    for name, v in zip(desc.joint_names, q, strict=True):
        x[model.joints[model.getJointId(name)].idx_q] = v
    return x


def _user_tip(model, desc, q, frame):
    """T_base_tip of the user's own URDF, evaluated by Pinocchio (independent of the toolkit's chain)."""
    import pinocchio as pin
    data = model.createData()
    pin.framesForwardKinematics(model, data, _q_full(model, desc, q))
    return data.oMf[model.getFrameId(frame)].homogeneous.copy()


# ---------------------------------------------------------------------------------------------
# tip frame orientation

def _tool_urdf(tmp_path, xyz, rpy) -> str:
    """The Panda with its ball replaced by a tool tip at (xyz, rpy) of panda_hand_tcp."""
    text = PANDA.read_text()
    start = text.index('<joint name="ball_joint"')
    end = text.index("</joint>", start) + len("</joint>")
    joint = (f'<joint name="ball_joint" type="fixed"><origin rpy="{" ".join(map(repr, rpy))}" '
             f'xyz="{" ".join(map(repr, xyz))}"/><parent link="panda_hand_tcp"/><child link="ball_link"/></joint>')
    path = tmp_path / "tool.urdf"
    path.write_text(text[:start] + joint + text[end:])
    return path


TOOLS = {   # a tool tip beyond the hand: (xyz [m], rpy [rad]) of the tip frame, z along the tool
    "tool along x": ((0.12, 0.0, -0.05), (0.0, math.pi / 2, 0.0)),
    "tool along -y": ((0.0, -0.09, -0.04), (math.pi / 2, 0.0, 0.0)),
    "arbitrary rpy": ((0.05, 0.03, 0.02), (0.3, -1.1, 2.4)),
}


@pytest.mark.parametrize("tool", TOOLS)
def test_tip_frame_full_pose_gives_probe_frame(tmp_path, tool):
    """Ball centre and probe axes of the description equal the tip frame that Pinocchio computes on the
    user's own URDF; a small probe-frame force moves the ball along the tip frame's axes."""
    path = _tool_urdf(tmp_path, *TOOLS[tool])
    d = description_from_urdf(path, "ball_link")
    model = _pin_model(path)
    rng = np.random.default_rng(3)
    q = rng.uniform(-2, 2, (10, 7))
    F = rng.normal(0, 1, (10, 3))
    F *= 2.0 / np.linalg.norm(F, axis=1)[:, None]
    rigid = ball_centres(d, q)
    moved = ball_centres(d, q, F) - rigid
    for i in range(10):
        T = _user_tip(model, d, q[i], "ball_link")
        assert_close(rigid[i], T[:3, 3], atol=1e-12)
        assert_close(moved[i], T[:3, :3] @ (d.probe.compliance * F[i]), atol=3e-8)


@pytest.mark.parametrize("tool", TOOLS)
def test_rotated_tool_three_evaluators_with_errors(tmp_path, tool):
    d = description_from_urdf(_tool_urdf(tmp_path, *TOOLS[tool]), "ball_link")
    rng = np.random.default_rng(4)
    spec = param_spec(d)
    p = np.array([rng.normal(0, {"m": 1e-4, "rad": 1e-3, "m/N": 1e-6}[u]) for u in spec.units])
    arm, f = PinocchioArm(apply_params(d, p)), casadi_ball_centre(d)
    q = rng.uniform(-2, 2, (8, 7))
    w = np.column_stack([rng.normal(0, 3, (8, 3)), rng.normal(0, 0.05, (8, 3))])
    batch = ball_centres(d, q, w, p)
    for i in range(8):
        assert_close(arm.ball_centre(q[i], w[i]), batch[i], atol=1e-12)
        assert_close(np.array(f(q[i], w[i], p)).ravel(), batch[i], atol=1e-12)
    back = parse_description(format_description(d))          # the probe frame survives the TOML
    assert_close(ball_centres(back, q, w), ball_centres(d, q, w), atol=1e-12)


@settings(max_examples=15, deadline=None)
@given(st.tuples(*[st.floats(-math.pi, math.pi)] * 3), st.tuples(*[st.floats(-0.1, 0.1)] * 2))
def test_any_tip_orientation_is_read(tmp_path_factory, rpy, xy):
    """Property: for any orientation of the tip frame (the ball 60 mm ahead along its z), the rigid ball
    and the tip axes equal Pinocchio's on the user's file."""
    from scipy.spatial.transform import Rotation
    z = Rotation.from_euler("xyz", rpy).as_matrix()[:, 2]
    xyz = tuple(float(v) for v in np.array([*xy, 0.0]) + 0.06 * z)
    d = description_from_urdf(_tool_urdf(tmp_path_factory.mktemp("t"), xyz, rpy), "ball_link")
    model = _pin_model(_tool_urdf(tmp_path_factory.mktemp("t"), xyz, rpy))
    q = np.random.default_rng(5).uniform(-2, 2, 7)
    T = _user_tip(model, d, q, "ball_link")
    assert_close(ball_centres(d, q), T[:3, 3], atol=1e-12)
    F = np.array([0.0, 0.0, 1.0])     # along the probe axis: the ball moves by c_z along the tip's z
    assert_close(ball_centres(d, q, F) - ball_centres(d, q), d.probe.axial_compliance * T[:3, 2], atol=1e-15)


def test_tip_frame_pointing_back_and_at_the_joint(tmp_path):
    """A tip frame whose z points back to the robot is still read (the hinge then |p| behind the ball) and
    the model file written of it reads back; a tip frame at the last joint's origin (a flange) is a tip
    without a stylus: rigid, compliances 0, equal to Pinocchio's frame, and a compliant probe there is
    refused with the line of its joint."""
    path = _tool_urdf(tmp_path, (0.0, 0.0, 0.05), (math.pi, 0.0, 0.0))    # z points back to the robot
    d = description_from_urdf(path, "ball_link")
    assert abs(d.probe.stylus_length - np.linalg.norm(d.probe.p_last)) < 1e-15
    model = _pin_model(path)
    q = np.random.default_rng(2).uniform(-2, 2, 7)
    T = _user_tip(model, d, q, "ball_link")
    assert_close(ball_centres(d, q), T[:3, 3], atol=1e-12)
    assert_close(ball_centres(d, q, [0, 0, 1.0]) - ball_centres(d, q), d.probe.axial_compliance * T[:3, 2], atol=1e-15)
    back = parse_description(format_description(d))       # the model file written of it reads back
    assert back.probe == d.probe
    assert_close(ball_centres(back, q, [0, 0, 1.0]), ball_centres(d, q, [0, 0, 1.0]), atol=1e-15)
    flipped = d.with_probe(rpy=(0.0, 0.0, 0.0), p_last=(0.0, 0.0, -0.07839), lever=0.07839)   # the file
    assert parse_description(format_description(flipped)).probe == flipped.probe
    text = PANDA.read_text()
    start = text.index('<joint name="ball_joint"')
    end = text.index("</joint>", start) + len("</joint>")
    text = (text[:start] + '<joint name="ball_joint" type="fixed"><origin xyz="0 0 0"/><parent link="panda_link7"/>'
            '<child link="ball_link"/></joint>' + text[end:])
    path.write_text(text)
    d = description_from_urdf(path, "ball_link")
    assert d.probe.lever == 0.0 and not d.probe.compliance.any()
    assert parse_description(format_description(d)).probe == d.probe
    assert_close(ball_centres(d, q), _user_tip(_pin_model(path), d, q, "ball_link")[:3, 3], atol=1e-12)
    with pytest.raises(InputError, match="at the origin of the last joint") as exc:
        description_from_urdf(path, "ball_link", probe=dict(axial_compliance=1e-7))
    assert exc.value.line is not None


def test_probe_orientation_keys_in_the_toml(nominal):
    text = NOMINAL.read_text().replace("z_mm = 85.0", "z_mm = 20.0\nroll_deg = 0.0\npitch_deg = 90.0\nyaw_deg = 0.0")
    text = text.replace("x_mm = 0.0 ", "x_mm = 100.0 ")
    d = parse_description(text)
    assert_close(d.probe.rpy, [0, math.pi / 2, 0], atol=1e-15)
    assert abs(d.probe.stylus_length - 0.100) < 1e-15          # along x of the last joint frame
    assert parse_description(format_description(d)) == d
    # the probe z turned back up the arm: one rule with the URDF route, the hinge |p| behind the ball
    back = parse_description(NOMINAL.read_text().replace("z_mm = 85.0", "z_mm = 85.0\npitch_deg = 180.0"))
    assert back.probe.lever == pytest.approx(0.085, abs=1e-15)
    assert parse_description(format_description(back)).probe == back.probe
    # at the joint origin: a tip without a stylus, which a compliant probe cannot be
    with pytest.raises(InputError, match="from the last joint origin, a tip without a stylus") as exc:
        parse_description(NOMINAL.read_text().replace("z_mm = 85.0", "z_mm = 0.0"))
    assert exc.value.column == "key 'probe.z_mm'"


# ---------------------------------------------------------------------------------------------
# the project's own URDF

def test_own_urdf_with_tip_frame_ball_equals_the_dh_arm(nominal):
    """urdf/aacmm7.urdf (generated by make urdf): the elastic joints are recognised, not encoder joints,
    and the ball centres equal those of the DH TOML, rigid and under load."""
    d = load_arm(ROOT / "urdf" / "aacmm7.urdf", "ball")
    assert d.joint_names == nominal.joint_names
    assert d.probe.ball_diameter == nominal.probe.ball_diameter        # from the ball's <sphere>
    assert abs(d.probe.stylus_length - nominal.probe.stylus_length) < 1e-15
    rng = np.random.default_rng(6)
    q = rng.uniform(-3, 3, (200, 7))
    w = np.column_stack([rng.normal(0, 3, (200, 3)), rng.normal(0, 0.05, (200, 3))])
    assert_close(ball_centres(d, q), ball_centres(nominal, q), atol=1e-12)
    assert_close(ball_centres(d, q, w), ball_centres(nominal, q, w), atol=1e-12)
    # the masses of the DH rows come back from the generated <inertial> tags
    assert [j.mass for j in d.joints] == [j.mass for j in nominal.joints]
    tg_d, _ = PinocchioArm(d).torques(q[:5])
    tg_n, _ = PinocchioArm(nominal).torques(q[:5])
    assert_close(tg_d, tg_n, atol=1e-9)


def test_own_urdf_with_rotated_probe(nominal, tmp_path):
    from arm_model.urdf import urdf_text
    rot = nominal.with_probe(p_last=(0.03, 0.04, 0.07), rpy=(0.4, -0.7, 2.1))
    path = tmp_path / "rot.urdf"
    path.write_text(urdf_text(rot))
    d = load_arm(path, "ball")
    q = np.random.default_rng(7).uniform(-3, 3, (50, 7))
    w = np.random.default_rng(8).normal(0, 3, (50, 3))
    assert_close(ball_centres(d, q, w), ball_centres(rot, q, w), atol=1e-12)


@pytest.mark.parametrize("tip, kept", [("ball_link", "ball_link"), ("stylus", "ball")])
def test_aacmm_urdf_of_a_urdf_arm_keeps_its_tip_link_name(nominal, tmp_path, tip, kept):
    """`aacmm urdf` of an arm read from a URDF names its ball link as the input did, so the same --tip-frame reads
    the generated file (before: the link was always 'ball', and `--tip-frame ball_link` failed with "did you mean
    'base_link'"); the ball centres agree. A name the generated file gives a link of its own ('stylus', the
    probe's shaft) falls back to 'ball', and the command says which name to give."""
    from arm_model.urdf import urdf_text
    src, out = tmp_path / "in.urdf", tmp_path / "out.urdf"
    src.write_text(urdf_text(nominal, tip_link="tip").replace('"stylus"', '"shaft"').replace('"tip"', f'"{tip}"'))
    assert main(["urdf", str(src), "--tip-frame", tip, "-o", str(out)]) == 0
    again = load_arm(out, kept)
    q = np.random.default_rng(9).uniform(-3, 3, (50, 7))
    assert_close(ball_centres(again, q), ball_centres(nominal, q), atol=1e-12)


# ---------------------------------------------------------------------------------------------
# masses

def test_panda_gravity_torques_match_rnea_on_the_users_urdf():
    d = load_arm(PANDA_INERTIAL, "ball_link")
    model, arm = _pin_model(PANDA_INERTIAL), PinocchioArm(d)
    import pinocchio as pin
    data = model.createData()
    for q in np.random.default_rng(9).uniform(-2, 2, (10, 7)):
        x = _q_full(model, d, q)
        ref = pin.computeGeneralizedGravity(model, data, x)
        idx = [model.joints[model.getJointId(n)].idx_q for n in d.joint_names]
        assert_close(arm.gravity_torques(q), ref[idx], atol=1e-9)
    assert abs(sum(j.mass for j in d.joints) - 16.792136) < 1e-9     # the seven <inertial> masses


MASSES = """# Gaz et al. style link masses, plus a hand and two fingers hanging from link 7
[[link]]
name = "panda_link1"
mass_kg = 4.97
com_x_mm = 3.9
com_y_mm = 2.1
com_z_mm = -175.0
[[link]]
name = "panda_link2"
mass_kg = 0.65
com_y_mm = -28.7
[[link]]
name = "panda_link3"
mass_kg = 3.23
com_x_mm = 27.5
com_y_mm = 39.3
com_z_mm = -66.5
[[link]]
name = "panda_link4"
mass_kg = 3.59
com_x_mm = -53.2
com_y_mm = 104.4
[[link]]
name = "panda_link5"
mass_kg = 1.23
com_z_mm = -38.4
[[link]]
name = "panda_link6"
mass_kg = 1.67
com_x_mm = 60.1
[[link]]
name = "panda_link7"
mass_kg = 0.74
com_z_mm = 79.0
[[link]]
name = "panda_hand"
mass_kg = 0.73
com_z_mm = 17.0
com_x_mm = -10.0
[[link]]
name = "panda_leftfinger"
mass_kg = 0.015
com_y_mm = 10.0
com_z_mm = 20.0
[[link]]
name = "panda_rightfinger"
mass_kg = 0.015
com_y_mm = -10.0
com_z_mm = 20.0
"""


def _with_inertials(path, masses) -> str:
    """The URDF text with <inertial> tags written from a masses dict (the independent reference)."""
    tree = etree.parse(str(path))
    for link in tree.getroot().findall("link"):
        m = masses.get(link.get("name"))
        if m is not None:
            link.append(etree.fromstring(
                f'<inertial><origin xyz="{" ".join(map(repr, m.com))}" rpy="0 0 0"/><mass value="{m.mass!r}"/>'
                '<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>'))
    return etree.tostring(tree, encoding="unicode")


def test_masses_file_folds_fixed_children_and_branches(tmp_path):
    """Hand (fixed child of link 8, itself fixed to link 7) and fingers (prismatic branch, held at zero)
    are folded into link 7: the torques equal Pinocchio's RNEA on the URDF with those inertials."""
    import pinocchio as pin
    mpath = tmp_path / "masses.toml"
    mpath.write_text(MASSES)
    masses = load_masses(mpath)
    d = load_arm(PANDA, "ball_link", masses=mpath)
    assert abs(d.joints[6].mass - (0.74 + 0.73 + 0.03)) < 1e-12
    model = _pin_model(_with_inertials(PANDA, masses))
    data = model.createData()
    arm = PinocchioArm(d)
    for q in np.random.default_rng(10).uniform(-2, 2, (10, 7)):
        ref = pin.computeGeneralizedGravity(model, data, _q_full(model, d, q))
        idx = [model.joints[model.getJointId(n)].idx_q for n in d.joint_names]
        assert_close(arm.gravity_torques(q), ref[idx], atol=1e-9)
    # hand derived: at q = 0 joint 2 holds the moment of every mass beyond it about its axis
    tau = arm.gravity_torques(np.zeros(7))
    assert np.abs(tau).max() > 1.0


@pytest.mark.parametrize("text, words, line", [
    ('[[link]]\nname = "panda_link1"\nmass_kg = -1.0\n', "mass must not be negative", 3),
    ('[[link]]\nname = "panda_link1"\nmass_kg = 1.0\ncom_q_mm = 3.0\n', "unknown key 'com_q_mm'", 4),
    ('[[link]]\nname = "panda_link1"\nmass_g = 1.0\n', "'mass_g' has no known unit", 3),
    ('[[link]]\nname = "panda_link1"\ncom_x_mm = 1.0\n', "missing key 'mass_<unit>'", 1),
    ('[[link]]\nname = "panda_link1"\nmass_kg = 1.0\n[[link]]\nname = "panda_link1"\nmass_kg = 2.0\n',
     "listed twice", 5),
    ('[link]\nname = "x"\n', "no [[link]]", 1),
])
def test_bad_masses_file_is_located(tmp_path, text, words, line):
    p = tmp_path / "m.toml"
    p.write_text(text)
    with pytest.raises(InputError, match=words.replace("[", r"\[")) as exc:
        load_arm(PANDA, "ball_link", masses=p)
    assert exc.value.line == line and str(p) in str(exc.value)


def test_masses_naming_an_unknown_link_or_for_a_toml_arm(tmp_path):
    p = tmp_path / "m.toml"
    p.write_text('[[link]]\nname = "nowhere"\nmass_kg = 1.0\n')
    with pytest.raises(InputError, match="does not have"):
        load_arm(PANDA, "ball_link", masses=p)
    with pytest.raises(InputError, match=r"\[\[joint\]\] rows"):
        load_arm(NOMINAL, masses=p)


def test_joint_compliance_skip_says_why():
    from arm_model.io import read_artefacts, read_points
    from calibration.candidates import library_candidates
    from calibration.data import make_data
    data_dir = PANDA.parent
    pts = read_points(data_dir / "front" / "points.csv", 7)
    arts = read_artefacts(data_dir / "artefacts.toml")
    for path, offered in ((PANDA, False), (PANDA_INERTIAL, True)):
        d = load_arm(path, "ball_link")
        cands, skipped = library_candidates(d, make_data(pts, arts), ("joint_compliance",))
        if offered:      # joint 1 turns about the vertical: gravity never loads it
            assert len([c for c in cands if c.joint]) == 6                 # one a loaded joint, and all at once
            assert [c.name for c in cands if not c.joint] == ["joint compliance (every loaded joint)"]
            assert [s.name for s in skipped] == ["joint compliance panda_joint1"]
        else:
            assert not cands and len(skipped) == 1
            assert "no masses" in skipped[0].reason and "--masses" in skipped[0].reason


# ---------------------------------------------------------------------------------------------
# the calibrated URDF

def _canonical(text: str) -> bytes:
    return etree.tostring(etree.fromstring(text.encode()), method="c14n")


def test_calibrated_urdf_roundtrip_is_the_users_file():
    d = load_arm(PANDA_INERTIAL, "ball_link")
    out = calibrated_urdf_text(d, d)
    assert _canonical(out) == _canonical(PANDA_INERTIAL.read_text())


def _elements(text):
    return [(el.tag, dict(el.attrib), el.getparent().get("name") if el.getparent() is not None else None)
            for el in etree.fromstring(text.encode()).iter() if isinstance(el.tag, str)]


@pytest.mark.parametrize("path, tip", [(PANDA_INERTIAL, "ball_link"), (ROOT / "urdf" / "aacmm7.urdf", "ball")])
def test_calibrated_urdf_keeps_everything_but_the_origins(tmp_path, path, tip):
    """Random errors in every origin and the tool offset: the written file has the same elements and
    attributes except the <origin> of the chain's joints and the tip joint's xyz, and Pinocchio on it
    gives the calibrated rigid ball centres to 1 nm."""
    d = load_arm(path, tip)
    spec = param_spec(d)
    rng = np.random.default_rng(11)
    p = np.array([rng.normal(0, {"m": 2e-4, "rad": 2e-3, "m/N": 0.0}[u]) for u in spec.units])
    p[[spec.index(f"{d.joint_names[2]}.{f}") for f in d.row_fields]] = 0.0      # this joint stays
    cal = apply_params(d, p)
    text = calibrated_urdf_text(d, cal)
    before, after = _elements(path.read_text()), _elements(text)
    assert len(before) == len(after)
    changed = {j.name for j in d.joints if j.name != d.joint_names[2]} | {ch for ch in _tip_joint(path, tip)}
    for (tag0, a0, parent0), (tag1, a1, parent1) in zip(before, after, strict=True):
        assert (tag0, parent0) == (tag1, parent1)
        if tag0 == "origin" and parent0 in changed:
            assert set(a0) <= set(a1)
            continue
        assert a0 == a1, (tag0, parent0)
    out = tmp_path / "cal.urdf"
    out.write_text(text)
    model = _pin_model(out)
    orig = _pin_model(path)
    assert list(model.names) == list(orig.names)
    assert [f.name for f in model.frames] == [f.name for f in orig.frames]
    assert_close(model.lowerPositionLimit, orig.lowerPositionLimit, atol=0)
    assert_close([i.mass for i in model.inertias], [i.mass for i in orig.inertias], atol=0)
    q = rng.uniform(-2, 2, (20, 7))
    want = ball_centres(cal, q)
    for i in range(20):
        assert_close(_user_tip(model, d, q[i], tip)[:3, 3], want[i], atol=1e-9)
    assert_close(ball_centres(load_arm(out, tip), q), want, atol=1e-12)   # and it reads back


def _tip_joint(path, tip):
    root = etree.parse(str(path)).getroot()
    return [j.get("name") for j in root.findall("joint") if j.find("child").get("link") == tip]


def test_calibrate_writes_the_users_urdf(tmp_path):
    """aacmm calibrate on the real Panda data: the written URDF is the user's file, loadable in Pinocchio
    with the same joint and frame names, and gives the calibrated description's ball centres (its geometry:
    the joint compliance a robot with masses gets by default has no place in a URDF)."""
    from arm_model.model_file import load_model
    data_dir = PANDA.parent
    out = tmp_path / "cal"
    rc = main(["calibrate", str(data_dir / "front" / "points.csv"), str(data_dir / "artefacts.toml"),
               "--arm", str(PANDA_INERTIAL), "--tip-frame", "ball_link", "-o", str(out), "--no-plots"])
    assert rc == 0
    urdf = next(out.glob("*.urdf"))
    model, orig = _pin_model(urdf), _pin_model(PANDA_INERTIAL)
    assert list(model.names) == list(orig.names)
    assert [f.name for f in model.frames] == [f.name for f in orig.frames]
    arm = load_model(next(out.glob("*.toml")))
    assert [e.key for e in arm.effects] == ["joint_compliance"]
    cal = arm.desc
    q = np.random.default_rng(12).uniform(-2, 2, (10, 7))
    for qi in q:
        assert_close(_user_tip(model, cal, qi, "ball_link")[:3, 3], ball_centres(cal, qi), atol=1e-9)
    assert "mesh" in urdf.read_text() and "panda_finger_joint1" in urdf.read_text()


def test_calibrate_a_robot_with_a_prismatic_joint_at_its_flange(nominal, tmp_path, capsys):
    """A robot's URDF with a prismatic joint, its tip the last joint's own link (a flange: no stylus), a
    tracker: calibrate runs to the end; the model file reads back (a prismatic joint, a rigid tip with the
    fitted tool offset), and the calibrated URDF carries that offset on a new link on the flange, giving the
    model file's centres; tip with force columns says that nothing bends."""
    from dataclasses import replace as dc_replace

    from arm_model.model import ArmModel
    from arm_model.model_file import load_model
    from arm_model.sim.quick import SynthSpec, make_campaign
    from arm_model.urdf import urdf_text
    joints = list(nominal.joints)
    joints[2] = dc_replace(joints[2], kind="prismatic", lower=-0.05, upper=0.25)
    text = urdf_text(dc_replace(nominal, joints=tuple(joints), name="lift"))
    urdf = tmp_path / "lift.urdf"
    urdf.write_text(text[: text.index('  <joint name="stylus_root_joint"')] + "</robot>\n")
    arm = load_arm(urdf, "link_7")
    assert arm.probe.lever == 0.0 and arm.joint_quantities[2] == "length"
    c = make_campaign(ArmModel(arm), SynthSpec(ballbars=6, ballbar_points=4, seats=2, articulations=6, spheres=0,
                                               reference_points=30, force=0.0, noise=2e-6, reference_noise=3e-6),
                      seed=5)
    f = c.write(tmp_path)
    assert "q3_mm" in f["points"].read_text().splitlines()[0]
    out = tmp_path / "cal"
    assert main(["calibrate", str(f["points"]), str(f["artefacts"]), "--arm", str(urdf), "--tip-frame", "link_7",
                 "--reference-points", str(f["reference"]), "--sigma-probe-um", "2", "--sigma-ref-um", "3",
                 "--no-plots", "-q", "-o", str(out)]) == 0
    cal = load_model(out / "lift-calibrated.toml").desc
    assert cal.joints[2].prismatic and cal.probe.lever == 0.0 and cal.probe.p_last != (0.0, 0.0, 0.0)
    tool = load_arm(out / "lift-calibrated.urdf", "link_7_calibrated")
    q = c.points.q[:10]
    assert_close(ball_centres(tool, q), ball_centres(cal, q), atol=1e-12)
    pts = tmp_path / "forces.csv"
    lines = f["points"].read_text().splitlines()
    pts.write_text("\n".join([lines[0] + ",fx_N,fy_N,fz_N"] + [ln + ",1,2,3" for ln in lines[1:6]]) + "\n")
    capsys.readouterr()
    assert main(["tip", str(pts), "--arm", str(urdf), "--tip-frame", "link_7", "-o", str(tmp_path / "t.csv")]) == 0
    assert "the tip has no stylus" in capsys.readouterr().err


def test_user_meshes_are_kept_for_the_viewer(tmp_path):
    """The Panda's meshes, found beside the URDF (relative, package:// and a mirrored scale), are drawn by the
    viewer's model where Pinocchio places them in the user's own file (hand and finger meshes folded onto
    the last row's link); a missing mesh is left out, the kinematics untouched."""
    import pinocchio as pin
    import trimesh

    from arm_model import PinocchioArm
    text = PANDA.read_text()
    (tmp_path / "meshes" / "panda").mkdir(parents=True)
    (tmp_path / "robot").mkdir()
    for k, name in enumerate(["link0", "link1", "link2", "link3", "link4", "link5", "link6", "link7", "hand",
                              "finger"]):
        trimesh.creation.box((0.02 + 0.01 * k, 0.03, 0.04)).export(tmp_path / "meshes" / "panda" / f"{name}.stl")
        text = text.replace(f"../meshes/panda/{name}.dae", f"../meshes/panda/{name}.stl")
    text = text.replace('"../meshes/panda/link3.stl"', '"package://meshes/panda/link3.stl"')
    text = text.replace('"../meshes/panda/link5.stl"/>', '"../meshes/panda/link5.stl" scale="1 -1 1"/>')
    user = tmp_path / "robot" / "panda.urdf"
    user.write_text(text)
    d = load_arm(user, "ball_link")
    meshes = [v for v in d.visuals if "<mesh" in v.geometry]
    assert len(meshes) == 11 and {v.row for v in meshes} == set(range(-1, 7))
    arm = PinocchioArm(d)
    ours = pin.buildGeomFromUrdfString(arm.model, arm.urdf, pin.GeometryType.VISUAL)
    ref_model = pin.buildModelFromUrdf(str(user))
    ref = pin.buildGeomFromUrdf(ref_model, str(user), pin.GeometryType.VISUAL,
                                package_dirs=[str(user.parent), str(tmp_path)])
    q = np.random.default_rng(4).uniform(-2, 2, 7)
    placed = {}
    for model, geom, x in ((arm.model, ours, arm.full_q(q)), (ref_model, ref, _q_full(ref_model, d, q))):
        data, gdata = model.createData(), pin.GeometryData(geom)
        pin.updateGeometryPlacements(model, data, geom, gdata, x)
        placed[id(geom)] = sorted((Path(o.meshPath).name, tuple(np.round(o.meshScale, 9)),
                                   tuple(np.round(gdata.oMg[k].homogeneous.ravel(), 9)))
                                  for k, o in enumerate(geom.geometryObjects) if o.meshPath.endswith(".stl"))
    assert placed[id(ours)] == placed[id(ref)] and len(placed[id(ours)]) == 11
    assert any(s == (1.0, -1.0, 1.0) for _, s, _ in placed[id(ours)])
    (tmp_path / "meshes" / "panda" / "link4.stl").unlink()
    d2 = load_arm(user, "ball_link")
    assert len([v for v in d2.visuals if "<mesh" in v.geometry]) == 10
    assert_close(ball_centres(d2, q), ball_centres(d, q), atol=0)


# ---------------------------------------------------------------------------------------------
# bad URDF: located, exit 2, no traceback

@pytest.mark.parametrize("edit, words, line", [
    (('xyz="0 0 0.333"', 'xyz="0 0 zero"'), "must be 3 finite numbers", 20),
    (('<parent link="panda_link0" />', '<parent link="panda_link_zero" />'), "is not defined", 21),
    (('<link name="panda_link2">', '<link name="panda_link1">'), "defined twice", 28),
    (('type="revolute">\n    <origin rpy="0 0 0" xyz="0 0 0.333" />', 'type="hinge">\n    <origin rpy="0 0 0" xyz="0 0 '
                                                                      '0.333" />'),
     "type must be one of", 19),
    (('</robot>', '</robt>'), "not valid XML", None),
    (('<mass value="4.97068" />', '<mass value="nan" />'), "finite", 16),
])
def test_bad_urdf_is_located(tmp_path, capsys, edit, words, line):
    text = PANDA_INERTIAL.read_text()
    assert edit[0] in text
    path = tmp_path / "bad.urdf"
    path.write_text(text.replace(edit[0], edit[1], 1))
    with pytest.raises(InputError, match=words) as exc:
        load_arm(path, "ball_link")
    if line is not None:
        assert exc.value.line == line
    else:
        assert exc.value.line is not None
    pts = PANDA.parent / "front" / "points.csv"
    out = tmp_path / "tips.csv"
    assert main(["tip", str(pts), "--arm", str(path), "--tip-frame", "ball_link", "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert words.split()[0] in err and "Traceback" not in err and not out.exists()


def test_prismatic_finger_and_its_mimic_equal_pinocchio():
    """The Panda's fingers: panda_finger_joint1 (prismatic) on the chain to the left finger; the right
    finger's joint mimics it (off its chain), so its column holds the master's value. Both tips equal
    Pinocchio's frames on the user's file, positions in metres."""
    import pinocchio as pin
    model = _pin_model(PANDA)
    data = model.createData()
    rng = np.random.default_rng(8)
    for tip, joint in (("panda_leftfinger", "panda_finger_joint1"), ("panda_rightfinger", "panda_finger_joint2")):
        d = load_arm(PANDA, tip)
        assert d.n_joints == 8 and d.joints[-1].prismatic and d.joint_quantities[-1] == "length"
        assert d.joint_names[-1] == "panda_finger_joint1"       # the mimic reads its master's column
        assert d.joints[-1].name == joint
        q = np.column_stack([rng.uniform(-2, 2, (6, 7)), rng.uniform(0.0, 0.04, 6)])
        for i in range(len(q)):
            x = np.zeros(model.nq)
            for name, v in zip([j.name for j in d.joints], q[i], strict=True):
                x[model.joints[model.getJointId(name)].idx_q] = v
            pin.framesForwardKinematics(model, data, x)
            assert_close(ball_centres(d, q[i]), data.oMf[model.getFrameId(tip)].translation, atol=1e-12)


def test_every_effect_with_a_rotated_tool_three_evaluators(tmp_path):
    """Every effect of the library on a URDF arm whose tool points along x: the effects that read the probe
    frame (contact moments, approach direction, compliance matrix) agree with Pinocchio, whose ball
    frame carries the tip frame's orientation (its moments come from RNEA)."""
    from arm_model.effects import EFFECTS
    from arm_model.model import ArmModel, AuxData, reading_motion
    mpath = tmp_path / "masses.toml"
    mpath.write_text(MASSES)
    d = load_arm(_tool_urdf(tmp_path, *TOOLS["tool along x"]), "ball_link", masses=mpath)
    model = ArmModel(d, tuple(cls() for cls in EFFECTS.values()))
    rng = np.random.default_rng(13)
    n = 5
    q = rng.uniform(-2, 2, (n, 7))
    w = np.column_stack([rng.normal(0, 2, (n, 3)), rng.normal(0, 0.02, (n, 3))])
    tg, tc = PinocchioArm(d).torques(q, w)
    aux = AuxData(rng.uniform(15, 30, n), tg, tc, rng.uniform(0, 3600, n), reading_motion(q))
    p = rng.normal(0, 1e-5, model.spec.size)
    assert_evaluators_agree(model, q, w, p, aux)


def test_simulator_truth_uses_the_probe_frame(tmp_path):
    """The simulator's true pose of a rotated tool: the ball of the model under the same wrench, and the
    probe axes of Pinocchio's ball frame (the simulator turns contact forces into the probe frame)."""
    from arm_model.model import ArmModel
    from arm_model.sim.truth import Truth
    d = load_arm(_tool_urdf(tmp_path, *TOOLS["arbitrary rpy"]), "ball_link")
    truth = Truth(ArmModel(d), np.zeros(ArmModel(d).spec.size), np.zeros((3, 3)), np.zeros(3), np.zeros(3))
    rng = np.random.default_rng(14)
    q = rng.uniform(-2, 2, (6, 7))
    w = np.column_stack([rng.normal(0, 2, (6, 3)), np.zeros((6, 3))])
    ball, z, x = truth.pose(q, truth.geometry(np.full(6, 20.0)), w)
    assert_close(ball, ball_centres(d, q, w), atol=1e-12)
    arm = PinocchioArm(d)
    for i in range(6):
        R = arm.T_base_ball(q[i])[:3, :3]
        assert_close(z[i], R[:, 2], atol=1e-12)
        assert_close(x[i], R[:, 0], atol=1e-12)
