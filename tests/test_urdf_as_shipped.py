"""Robot descriptions as they ship (docs/robots.md, "Loading a robot's URDF as it ships"): what urdfdom reads past
and the toolkit now reads too, what stays refused and how the refusal reads, each with a small synthetic URDF that
reproduces the feature found in a shipped description."""
from __future__ import annotations

import logging
import math
import os

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from arm_model.cli import main
from arm_model.errors import InputError
from arm_model.kinematics import ball_centres
from arm_model.model_file import load_model
from arm_model.urdf_import import description_from_urdf, is_urdf, load_arm

LIMIT = '<limit lower="-3" upper="3" effort="1" velocity="1"/>'


def joint(name, parent, child, axis="0 0 1", rpy="0 0 0", limit=LIMIT, jtype="revolute", extra=""):
    return (f'<joint name="{name}" type="{jtype}"><parent link="{parent}"/><child link="{child}"/>'
            f'<origin xyz="0 0.02 0.1" rpy="{rpy}"/><axis xyz="{axis}"/>{limit}{extra}</joint>')


def robot(j2=None, links_extra="", decl='<?xml version="1.0"?>\n', tip_link='<link name="tip"/>', root_attrs=""):
    """A three-joint arm base -> l1 -> l2 -> l3 -> tip (fixed, 50 mm along z), j2 replaceable."""
    return (f'{decl}<robot name="r"{root_attrs}>\n<link name="base"/>\n<link name="l1"/>\n<link name="l2"/>\n'
            f'<link name="l3"/>\n{tip_link}\n{links_extra}'
            f'{joint("j1", "base", "l1")}\n{j2 or joint("j2", "l1", "l2", axis="0 1 0")}\n'
            f'{joint("j3", "l2", "l3", axis="1 0 0")}\n'
            '<joint name="tj" type="fixed"><parent link="l3"/><child link="tip"/><origin xyz="0 0 0.05"/></joint>\n'
            '</robot>\n')


def write(tmp_path, text, name="r.urdf"):
    path = tmp_path / name
    path.write_bytes(text.encode() if isinstance(text, str) else text)
    return path


def origins(desc):
    return [j.origin for j in desc.joints], desc.probe.p_last


# -- what urdfdom reads past -----------------------------------------------------------------------------------

#: name: (the file's bytes, the line the warning names, what it says), as shipped descriptions have them
TOLERATED = {
    "xml version 0.0 (pybullet's minitaur)": (robot(decl='<?xml version="0.0" ?>\n'), 1, "unknown version"),
    "declaration after a blank line (pybullet's diff_ring)": (robot(decl='\n<?xml version="1.0" ?>\n'), 2,
                                                               "after blank lines"),
    "a UTF-8 declaration after blank lines": (
        robot(decl='\n  \n<?xml version="1.0" encoding="UTF-8"?>\n'), 3, "after blank lines"),
    "a NUL byte after </robot> (pybullet's humanoid)": (robot() + "\x00", 13, "NUL bytes"),
    "drake: attributes never declared (Drake's UR5e)": (
        robot(j2=joint("j2", "l1", "l2", axis="0 1 0", limit=LIMIT.replace("<limit ", '<limit drake:acceleration="2" '))
              ).replace("</robot>", '<drake:collision_filter_group name="g"/></robot>'), 9,
        "a namespace prefix never declared"),
}


@pytest.mark.parametrize("name", TOLERATED)
def test_what_urdfdom_reads_past_is_read_with_a_warning(tmp_path, caplog, name):
    """Files lxml refuses as XML but urdfdom (Pinocchio, ROS) reads, as shipped robots have them: read as the clean
    file is, one warning naming the line; the calibrated URDF written back is strict XML Pinocchio builds."""
    import pinocchio as pin
    text, line, words = TOLERATED[name]
    path = write(tmp_path, text)
    with caplog.at_level(logging.WARNING, logger="arm_model"):
        desc = description_from_urdf(path, "tip")
    assert origins(desc) == origins(description_from_urdf(write(tmp_path, robot(), "clean.urdf"), "tip"))
    said = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(said) == 1 and "r.urdf is not strict XML" in said[0] and f"line {line}: " in said[0] \
        and words in said[0], said
    assert pin.buildModelFromUrdf(str(path)).nq == 3              # the claim: urdfdom reads the file as it is
    out = tmp_path / "out.urdf"
    assert main(["urdf", str(path), "--tip-frame", "tip", "-o", str(out), "-q"]) == 0
    from lxml import etree
    etree.parse(str(out))                                          # strict XML


@pytest.mark.parametrize("text, line", [
    (robot() + "<robot name='again'/>\n", 13),                     # a second document: not a NUL byte
    (robot().replace("<robot ", "<robot  ", 1).replace('<link name="l1"/>', '<link name="l1">'), None),
    (robot(decl='<?xml version="1.0" encoding="latin-1"?>\n'.rjust(44)), None),
    (robot(decl='<!-- made by hand -->\n<?xml version="1.0"?>\n'), 2),     # urdfdom refuses it there too
])
def test_other_xml_faults_stay_refused_at_their_line(tmp_path, text, line):
    with pytest.raises(InputError, match="not valid XML") as exc:
        description_from_urdf(write(tmp_path, text), "tip")
    assert exc.value.line is not None and (line is None or exc.value.line == line), exc.value


# -- what file is a URDF ---------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["arm.xml", "arm.URDF", "model", "arm.description"])
def test_a_urdf_by_any_name_is_read_as_a_urdf(tmp_path, name):
    """A URDF named otherwise than .urdf (pybullet's kuka_iiwa/model.urdf's relatives, `robot.xml`) was read as a
    TOML file: "--tip-frame is for an arm given as a URDF; this arm is a TOML file"."""
    path = write(tmp_path, robot(), name)
    assert is_urdf(path)
    assert load_model(str(path), tip_frame="tip").desc.joint_names == ("j1", "j2", "j3")


def test_a_toml_without_suffix_is_still_a_toml(tmp_path):
    path = tmp_path / "arm"
    assert main(["urdf", "aacmm7", "-o", str(tmp_path / "a.urdf"), "-q"]) == 0
    from arm_model.shipped import arm_path
    path.write_text(arm_path("aacmm7").read_text())
    assert not is_urdf(path) and len(load_model(str(path)).desc.joints) == 7


@pytest.mark.parametrize("robot_tag", ['<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro">',
                                       '<robot xmlns:xacro="http://www.ros.org/wiki/xacro">',      # a file of macros
                                       '<robot name="r">'])                  # the prefix never declared
def test_a_xacro_file_is_told_to_be_expanded_with_or_without_a_tip_frame(tmp_path, capsys, robot_tag):
    """rtb-data's 60 xacro files: 19 files of macros (a <robot> without a name) were refused as "<robot> has no
    name"; every one now says to expand it."""
    path = write(tmp_path, f'<?xml version="1.0"?>\n{robot_tag}\n<xacro:include filename="arm.xacro"/>\n</robot>\n',
                 "r.urdf.xacro")
    for extra in ([], ["--tip-frame", "tip"]):
        assert main(["urdf", str(path), *extra, "-o", str(tmp_path / "o.urdf")]) == 2
        err = capsys.readouterr().err
        assert "r.urdf.xacro, line 3" in err and "expand it first (xacro" in err and "Traceback" not in err, err
    assert not (tmp_path / "o.urdf").exists()


# -- limits ----------------------------------------------------------------------------------------------------

def test_infinite_limits_are_no_limits_and_nan_stays_refused(tmp_path):
    for lim in ('<limit lower="-inf" upper="inf" effort="1" velocity="1"/>',
                '<limit lower="-1" upper="INF" effort="1" velocity="1"/>'):
        d = description_from_urdf(write(tmp_path, robot(j2=joint("j2", "l1", "l2", limit=lim))), "tip")
        assert (d.joints[1].lower, d.joints[1].upper) == (None, None)
    with pytest.raises(InputError, match="must be 1 finite number, got 'nan'") as exc:
        description_from_urdf(write(tmp_path, robot(j2=joint("j2", "l1", "l2", limit=LIMIT.replace('"-3"', '"nan"')))),
                              "tip")
    assert exc.value.line == 9


def test_a_revolute_joint_without_limit_is_refused_saying_why(tmp_path):
    with pytest.raises(InputError) as exc:
        description_from_urdf(write(tmp_path, robot(j2=joint("j2", "l1", "l2", limit=""))), "tip")
    assert exc.value.line == 9 and "urdfdom" in str(exc.value) and 'type="continuous"' in str(exc.value)
    d = description_from_urdf(write(tmp_path, robot(j2=joint("j2", "l1", "l2", limit="", jtype="continuous"))), "tip")
    assert d.joints[1].lower is None


# -- the tip frame ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("tip, line, words", [
    ("j3", 10, "'j3' is a joint, not a link: --tip-frame names a link (this joint's child link is 'l3')"),
    ("base", 3, "link 'base' hangs from no joint: it is a root of the URDF"),
    ("tpi", None, "no link named 'tpi'; did you mean 'tip'?; the chains end at tip (3 moving joints) (5 links in all)"),
])
def test_a_tip_frame_on_no_chain_says_which_links_are(tmp_path, capsys, tip, line, words):
    """(A link no joint leads to, an island, is a second root: refused since round 11 whatever the tip frame,
    tests/test_reliability_round11.py.)"""
    path = write(tmp_path, robot())
    assert main(["tip", str(path), "--arm", str(path), "--tip-frame", tip, "-o", str(tmp_path / "t.csv")]) == 2
    err = capsys.readouterr().err
    assert words in err and "key '--tip-frame'" in err and (line is None or f"line {line}," in err), err
    assert "Traceback" not in err and not (tmp_path / "t.csv").exists()
    if line is not None and tip != "j3":
        assert "a link a chain reaches: the chains end at tip (3 moving joints)" in err


# -- geometry that is not the probe's ---------------------------------------------------------------------------

def test_a_zero_radius_sphere_on_the_tip_is_no_ball(tmp_path):
    """pybullet's laikago toes carry a collision sphere of radius 0: the toe was refused as "the probe ball must
    be > 0"; it is a point, so the ball is the default. A negative radius stays an error."""
    sphere = '<link name="tip"><collision><geometry><sphere radius="{}"/></geometry></collision></link>'
    d = description_from_urdf(write(tmp_path, robot(tip_link=sphere.format("0.0"))), "tip")
    assert d.probe.ball_diameter == description_from_urdf(write(tmp_path, robot(), "c.urdf"), "tip").probe.ball_diameter
    with pytest.raises(InputError, match="must not be negative"):
        description_from_urdf(write(tmp_path, robot(tip_link=sphere.format("-0.01"))), "tip")


def test_missing_meshes_are_listed_for_the_viewer_and_do_not_matter(tmp_path):
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "l2.stl").write_text("solid x\nendsolid x\n")
    vis = '<visual><geometry><mesh filename="{}"/></geometry></visual>'
    text = (robot().replace('<link name="l1"/>', f'<link name="l1">{vis.format("package://gone/meshes/l1.dae")}</link>')
            .replace('<link name="l2"/>', f'<link name="l2">{vis.format("meshes/l2.stl")}</link>')
            .replace('<link name="l3"/>', f'<link name="l3">{vis.format("file:///nowhere/l3.stl")}</link>'))
    d = description_from_urdf(write(tmp_path, text), "tip")
    assert sorted(d.missing_meshes) == ["file:///nowhere/l3.stl", "package://gone/meshes/l1.dae"]
    clean = description_from_urdf(write(tmp_path, robot(), "c.urdf"), "tip")
    assert len(d.visuals) == 1 and origins(d) == origins(clean)



@pytest.mark.parametrize("var, layout", [("ROS_PACKAGE_PATH", "{root}"), ("ROS_PACKAGE_PATH", "{root}/desc"),
                                         ("AMENT_PREFIX_PATH", "{root}/install")])
def test_package_meshes_are_found_through_a_sourced_ros_workspace(tmp_path, monkeypatch, var, layout):
    """package://desc/... is found in ROS 1's ROS_PACKAGE_PATH (a folder holding the package, or the package
    itself) and under ROS 2's AMENT_PREFIX_PATH/share, not only beside or above the URDF."""
    root = tmp_path / "ws"
    mesh_dir = (root / "install" / "share" / "desc" if var == "AMENT_PREFIX_PATH" else root / "desc") / "meshes"
    mesh_dir.mkdir(parents=True)
    (mesh_dir / "l1.stl").write_text("solid x\nendsolid x\n")
    vis = '<visual><geometry><mesh filename="package://desc/meshes/l1.stl"/></geometry></visual>'
    text = robot().replace('<link name="l1"/>', f'<link name="l1">{vis}</link>')
    (tmp_path / "robot").mkdir()
    urdf = write(tmp_path / "robot", text)
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    assert description_from_urdf(urdf, "tip").missing_meshes == ("package://desc/meshes/l1.stl",)
    monkeypatch.setenv(var, os.pathsep.join(["/nowhere", layout.format(root=root)]))
    d = description_from_urdf(urdf, "tip")
    assert d.missing_meshes == () and len(d.visuals) == 1

# -- axes and origins against Pinocchio --------------------------------------------------------------------------

def _axis():
    comp = st.one_of(st.just(0.0), st.floats(-1, 1), st.sampled_from([1e-17, -2e-16, 1e-12]))
    return st.tuples(comp, comp, comp).filter(lambda v: max(map(abs, v)) > 0.1)


@settings(max_examples=15, deadline=None)
@given(axis=_axis(), scale=st.floats(1e-6, 1e3), roll=st.floats(-math.pi, math.pi), yaw=st.floats(-math.pi, math.pi),
       near=st.sampled_from([0.0, 1e-12, 1e-8, 1e-4, 0.3]), sign=st.sampled_from([-1, 1]),
       q=st.lists(st.floats(-3, 3), min_size=3, max_size=3))
def test_non_unit_axes_and_near_singular_rpy_equal_pinocchio(tmp_path_factory, axis, scale, roll, yaw, near, sign, q):
    """An axis of any length and tiny components, an origin at pitch within 1e-12 rad of +-90 deg: the tip equals
    Pinocchio's placement of the same file to 1e-12 m."""
    import pinocchio as pin
    pitch = sign * (math.pi / 2 - near)
    text = robot(j2=joint("j2", "l1", "l2", axis=" ".join(repr(scale * a) for a in axis),
                          rpy=f"{roll!r} {pitch!r} {yaw!r}"))
    path = write(tmp_path_factory.mktemp("ax"), text)
    model = pin.buildModelFromUrdf(str(path))
    data = model.createData()
    pin.framesForwardKinematics(model, data, np.array(q))
    expected = data.oMf[model.getFrameId("tip")].translation
    got = ball_centres(load_arm(path, "tip"), np.array([q]))[0]
    assert np.abs(got - expected).max() < 1e-12


def test_unicode_names_through_the_commands(tmp_path, capsys):
    """Joint and link names outside ASCII (a Japanese vendor's file) are read, and the calibrated URDF keeps them."""
    text = robot().replace('"j1"', '"関節1"').replace('"tip"', '"ツール先端"')
    path = write(tmp_path, text)
    out = tmp_path / "o.urdf"
    assert main(["urdf", str(path), "--tip-frame", "ツール先端", "-o", str(out), "-q"]) == 0
    assert "関節1" in out.read_text(encoding="utf-8")
    assert load_arm(path, "ツール先端").joint_names[0] == "関節1"


def test_repeated_elements_use_the_first_as_urdfdom_does_and_say_so(tmp_path, caplog):
    """Two <origin> (or <axis>) in one joint, as a bad xacro macro leaves them: the first is used, as urdfdom uses
    it (the tip equals Pinocchio's), with a warning naming both lines."""
    import pinocchio as pin
    j2 = joint("j2", "l1", "l2", axis="0 1 0", extra='\n<origin xyz="0 0 5"/>\n<axis xyz="1 0 0"/>')
    path = write(tmp_path, robot(j2=j2))
    with caplog.at_level(logging.WARNING, logger="arm_model"):
        desc = load_arm(path, "tip")
    said = " ".join(r.getMessage() for r in caplog.records)
    assert "has 2 <origin> elements (lines 9, 10)" in said and "has 2 <axis> elements (lines 9, 11)" in said, said
    model = pin.buildModelFromUrdf(str(path))
    data, q = model.createData(), np.array([0.4, -0.6, 1.2])
    pin.framesForwardKinematics(model, data, q)
    assert np.abs(ball_centres(desc, q[None])[0] - data.oMf[model.getFrameId("tip")].translation).max() < 1e-12


@pytest.mark.parametrize("tj, words", [
    ('<joint name="tj" type="floating"><parent link="l3"/><child link="tip"/></joint>',
     "the tip frame 'tip' hangs from the floating joint 'tj', which moves it freely"),
    ('<joint name="tj" type="fixed"><parent link="l3"/><child link="tip"/><mimic/></joint>',
     "its <mimic> names no joint"),
])
def test_a_tip_no_chain_places_and_a_mimic_of_nothing_are_said_plainly(tmp_path, tj, words):
    fixed = '<joint name="tj" type="fixed"><parent link="l3"/><child link="tip"/><origin xyz="0 0 0.05"/></joint>'
    text = robot().replace(fixed, tj)
    with pytest.raises(InputError, match=words) as exc:
        load_arm(write(tmp_path, text), "tip")
    assert exc.value.line == 11


def test_a_campaign_takes_a_urdf_without_suffix(tmp_path):
    write(tmp_path, robot(), "robotmodel")
    (tmp_path / "c.toml").write_text('name = "x"\nseed = 1\narm = "robotmodel"\ntip_frame = "tip"\nsensor = "none"\n\n'
                                     '[[task]]\nkind = "mocap"\npostures = 6\nnoise_mm = 0.15\n')
    assert main(["simulate", str(tmp_path / "c.toml"), "-o", str(tmp_path / "out"), "-q"]) == 0
    assert (tmp_path / "out" / "points.csv").read_text().splitlines()[0].count("_deg") == 3


def test_joints_the_points_do_not_give_are_counted_first_and_said_how_to_leave_out(tmp_path, capsys):
    """An arm on a mobile base whose URDF moves the base by two prismatic joints and a yaw (as a whole-body
    controller's description has it), points of the arm's three joints only: the refusal counts the columns
    first (before, q1 was said to need a length, the base's x being joint 1) and names --base-frame and
    --hold-joint; with --base-frame after the base, the same points are read."""
    base = ('<link name="world"/><link name="bx"/><link name="by"/><link name="mobile"/>'
            + joint("base_x", "world", "bx", axis="1 0 0", jtype="prismatic")
            + joint("base_y", "bx", "by", axis="0 1 0", jtype="prismatic")
            + joint("base_yaw", "by", "mobile", limit="", jtype="continuous")
            + '<joint name="mount" type="fixed"><parent link="mobile"/><child link="base"/></joint>')
    urdf = write(tmp_path, robot(links_extra=base))
    pts = write(tmp_path, "measurement,feature,q1_rad,q2_rad,q3_rad\nm,f,0.1,0.2,0.3\n", "p.csv")
    argv = ["tip", str(pts), "--arm", str(urdf), "--tip-frame", "tip", "-o", str(tmp_path / "t.csv")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "3 joint columns, but the arm has 6 joints" in err and "--base-frame" in err and "--hold-joint" in err, err
    assert not (tmp_path / "t.csv").exists()
    assert main(argv + ["--base-frame", "base"]) == 0
