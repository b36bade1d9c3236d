"""URDF generated from the arm description, with the probe's virtual elastic joints and visuals.

Chain: ``base_link -> j1 ... jJ (revolute, z) -> flange (the last joint frame, fixed) -> stylus_root
(the bending hinge, in the probe frame's orientation, fixed; at (x, y, 0) for an unrotated probe) -> probe_bend_y
(revolute, y) -> probe_bend_x (revolute, x) ->
probe_axial (prismatic, z) -> ball (fixed, at (0, 0, L))``. The elastic joints carry no limits of
interest; they are set by statics from the measured wrench (see :mod:`arm_model.chain`).
"""
from __future__ import annotations

import math
from functools import lru_cache
from xml.sax.saxutils import escape as _xml_escape

import numpy as np

from .description import ArmDescription

__all__ = ["urdf_text", "kept_link_names", "ELASTIC_JOINTS", "BALL_FRAME", "FLANGE_FRAME",
           "ARM_RGBA", "BALL_RGBA"]

ELASTIC_JOINTS = ("probe_bend_y", "probe_bend_x", "probe_axial")
BALL_FRAME = "ball"
FLANGE_FRAME = "flange"
ARM_RGBA = (0.95, 0.45, 0.05, 1.0)    # orange links: the viewer's tests look for this colour
JOINT_RGBA = (0.25, 0.25, 0.28, 1.0)
PROBE_RGBA = (0.75, 0.75, 0.78, 1.0)
BALL_RGBA = (0.85, 0.1, 0.1, 1.0)


def escape(text: str) -> str:
    """``text`` safe inside an XML attribute in double quotes (``& < > "``; a control character becomes U+FFFD)."""
    text = "".join(c if c.isprintable() else "\ufffd" for c in str(text))
    return _xml_escape(text, {'"': "&quot;"})


def _comment(text: str) -> str:
    """``text`` safe inside an XML comment (no ``--``)."""
    return escape(text).replace("--", "- -")


def _rot(axis: str, angle: float) -> np.ndarray:
    """4x4 rotation about base ``axis`` ('x' or 'z')."""
    from scipy.spatial.transform import Rotation  # here: `aacmm --help` imports this module, not scipy
    t = np.eye(4)
    t[:3, :3] = Rotation.from_euler(axis, angle).as_matrix()
    return t


def _rx(a):
    return _rot("x", a)


def _rz(a):
    return _rot("z", a)


def _tr(x, y, z):
    t = np.eye(4)
    t[:3, 3] = (x, y, z)
    return t


def origin_matrix(origin) -> np.ndarray:
    """4x4 of a URDF origin (x, y, z, roll, pitch, yaw): T(xyz) Rz(yaw) Ry(pitch) Rx(roll)."""
    x, y, z, roll, pitch, yaw = origin
    from .geometry import rotation_xyz
    t = _tr(x, y, z)
    t[:3, :3] = rotation_xyz((roll, pitch, yaw))
    return t


def _f(x: float) -> str:
    return repr(float(x) + 0.0)    # + 0.0: no "-0.0"


def _origin(t: np.ndarray) -> str:
    from .geometry import rpy_from_matrix
    r, p, y = rpy_from_matrix(t[:3, :3])
    return (f'<origin xyz="{_f(t[0, 3])} {_f(t[1, 3])} {_f(t[2, 3])}" '
            f'rpy="{_f(r)} {_f(p)} {_f(y)}"/>')


def _rgba(c) -> str:
    return " ".join(repr(float(v)) for v in c)


def _cylinder_between(p0, p1, radius: float, material: str) -> str:
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    v = p1 - p0
    length = float(np.linalg.norm(v))
    if length < 1e-6:
        return ""
    t = np.eye(4)
    from .geometry import frame_along
    t[:3, :3] = frame_along(v, 2)
    t[:3, 3] = (p0 + p1) / 2
    return (f'<visual>{_origin(t)}<geometry><cylinder radius="{_f(radius)}" length="{_f(length)}"/>'
            f'</geometry><material name="{material}"/></visual>')


def _joint_housing(radius: float) -> str:
    return (f'<visual><origin xyz="0 0 0" rpy="0 0 0"/><geometry><cylinder radius="{_f(radius)}" '
            f'length="{_f(2.2 * radius)}"/></geometry><material name="joint"/></visual>')


def _inertial(mass: float, com) -> str:
    if mass <= 0:
        return ""
    i = 1e-6
    return (f'<inertial><origin xyz="{_f(com[0])} {_f(com[1])} {_f(com[2])}" rpy="0 0 0"/>'
            f'<mass value="{_f(mass)}"/><inertia ixx="{i}" ixy="0" ixz="0" iyy="{i}" iyz="0" izz="{i}"/>'
            f'</inertial>')


BASE_VISUAL = ('<visual><origin xyz="0 0 0.01" rpy="0 0 0"/><geometry><cylinder radius="0.07" length="0.02"/>'
               '</geometry><material name="joint"/></visual>')


def _user_visuals(desc: ArmDescription, row: int) -> str:
    """The visuals of the user's URDF (:attr:`ArmDescription.visuals`) on the link of ``row`` (-1: the
    base), or an empty text: then the generated cylinders draw it."""
    out = []
    for k, v in enumerate(w for w in desc.visuals if w.row == row):
        mat = ('<material name="joint"/>' if v.rgba is None else
               f'<material name="user_{row + 1}_{k}"><color rgba="{_rgba(v.rgba)}"/></material>')
        out.append(f"<visual>{_origin(np.array(v.pose, dtype=float))}{v.geometry}{mat}</visual>")
    return "".join(out)


def _row_frames(desc: ArmDescription, i: int, tail_prev: np.ndarray):
    """Row ``i`` as a URDF joint: (its origin in the parent link, the row's tail after the joint (standard
    DH), its axis, the waypoints of its link's visual, the row's end frame in the joint's child link)."""
    j, n = desc.joints[i], len(desc.joints)
    nxt = desc.joints[i + 1] if i + 1 < n else None
    if desc.convention == "urdf":
        waypoints = [(0, 0, 0), tuple(origin_matrix(nxt.origin)[:3, 3])] if nxt else [(0, 0, 0)]
        return origin_matrix(j.origin), np.eye(4), j.axis, waypoints, np.eye(4)
    z = (0.0, 0.0, 1.0)
    if desc.convention == "dh":
        # a revolute joint turns by theta_offset + q before Tz(d); a prismatic one slides by d + q after Rz
        origin = tail_prev @ _rz(j.theta_offset) @ (_tr(0, 0, j.d) if j.prismatic else np.eye(4))
        tail = (np.eye(4) if j.prismatic else _tr(0, 0, j.d)) @ _tr(j.a, 0, 0) @ _rx(j.alpha)
        waypoints = [(0, 0, 0), (0, 0, j.d), (j.a, 0, j.d)] if not j.prismatic else [(0, 0, 0), (j.a, 0, 0)]
        return origin, tail, z, waypoints, tail
    origin = _rx(j.alpha) @ _tr(j.a, 0, 0) @ _rz(j.theta_offset) @ _tr(0, 0, j.d)
    waypoints = [(0, 0, 0)]
    if nxt is not None:
        o_next = _rx(nxt.alpha) @ _tr(nxt.a, 0, 0) @ _rz(nxt.theta_offset) @ _tr(0, 0, nxt.d)
        waypoints = [(0, 0, 0), (nxt.a, 0, 0), tuple(o_next[:3, 3])]
    return origin, np.eye(4), z, waypoints, np.eye(4)


def _off_chain_masters(desc: ArmDescription, base_link: str) -> list[str]:
    """A joint for each master a ``<mimic>`` of the chain follows from off the chain (a gripper's motor joint
    read by the encoder column named after it), on a branch of its own from the base link, with the column's
    limits: without it the mimic tag has no master and the URDF read back would take the follower's value as
    its own column (another column name, the multiplier and offset lost). Written ahead of the chain: Pinocchio
    parses a master before the joints that mimic it."""
    rows = {j.name for j in desc.joints}
    masters = [e for e in desc.encoders if e.name not in rows]
    out = []
    for k, e in enumerate(masters):
        unit_range = 1.0 if e.prismatic else 2 * math.pi
        lower = e.lower if e.lower is not None else -unit_range
        upper = e.upper if e.upper is not None else unit_range
        out += [f'  <joint name="{escape(e.name)}" type="{e.kind}"><parent link="{escape(base_link)}"/>'
                f'<child link="mimic_master_{k + 1}"/><origin xyz="0 0 0" rpy="0 0 0"/><axis xyz="0 0 1"/>'
                f'<limit lower="{_f(lower)}" upper="{_f(upper)}" effort="100" velocity="3"/></joint>',
                f'  <link name="mimic_master_{k + 1}"/>']
    return out


def _generated_links(desc: ArmDescription) -> set[str]:
    """The names :func:`urdf_text` gives its own links (the chain's, the probe's, the mimic masters')."""
    masters = [e for e in desc.encoders if e.name not in {j.name for j in desc.joints}]
    return ({f"link_{i + 1}" for i in range(len(desc.joints))} | {f"mimic_master_{k + 1}" for k in range(len(masters))}
            | {FLANGE_FRAME, "stylus_root", "probe_bend_y_link", "probe_bend_x_link", "stylus"})


def kept_link_names(desc: ArmDescription) -> tuple[str, str]:
    """The base and tip link names of ``desc``'s generated URDF: those of the URDF it was read from
    (``base_frame`` or ``base_link``, ``tip_frame``), so that the same ``--base-frame``/``--tip-frame`` read the
    generated file too; ``base_link`` and :data:`BALL_FRAME` for a description TOML, or where a name is one the
    generated file gives a link of its own."""
    own = _generated_links(desc)
    base = desc.base_frame if desc.base_frame and desc.base_frame not in own else "base_link"
    tip = desc.tip_frame if desc.tip_frame and desc.tip_frame not in own | {base} else BALL_FRAME
    return base, tip


def urdf_text(desc: ArmDescription, base_link: str = "base_link", tip_link: str = BALL_FRAME) -> str:
    """The URDF of ``desc`` (standard or modified DH) as text; ``base_link`` and ``tip_link`` name its first link
    and its ball's (a chain generated for a URDF arm keeps the names of its base and tip frames).

    Written once for the same description (:attr:`~arm_model.description.ArmDescription.exact_key`) and names
    among the last :data:`URDF_CACHE` (every Pinocchio model of a description is built from it: the torques of
    each fit, the equilibrium of each model)."""
    return _urdf_text(_Exactly(desc), base_link, tip_link)


#: descriptions whose URDF text is kept (the least recently used dropped first)
URDF_CACHE = 32


class _Exactly:
    """A description as a cache's key: equal when their :attr:`~arm_model.description.ArmDescription.exact_key`
    is (every field, every number exactly)."""
    __slots__ = ("desc",)

    def __init__(self, desc: ArmDescription) -> None:
        self.desc = desc

    def __eq__(self, other: object) -> bool:
        return isinstance(other, _Exactly) and other.desc.exact_key == self.desc.exact_key

    def __hash__(self) -> int:
        return hash(self.desc.exact_key)


@lru_cache(maxsize=URDF_CACHE)
def _urdf_text(key: _Exactly, base_link: str, tip_link: str) -> str:
    desc = key.desc
    n = len(desc.joints)
    lines = ['<?xml version="1.0"?>',
             f"<!-- generated by `aacmm urdf` from the arm description '{_comment(desc.name)}' "
             f"({desc.convention}); do not edit -->",
             f'<robot name="{escape(desc.name)}">',
             f'  <material name="arm"><color rgba="{_rgba(ARM_RGBA)}"/></material>',
             f'  <material name="joint"><color rgba="{_rgba(JOINT_RGBA)}"/></material>',
             f'  <material name="probe"><color rgba="{_rgba(PROBE_RGBA)}"/></material>',
             f'  <material name="ball"><color rgba="{_rgba(BALL_RGBA)}"/></material>',
             f'  <link name="{escape(base_link)}">{_user_visuals(desc, -1) or BASE_VISUAL}</link>']
    lines += _off_chain_masters(desc, base_link)
    radii = np.linspace(0.03, 0.018, n)
    parent = escape(base_link)
    tail_prev = np.eye(4)   # the previous row's tail, for standard DH
    for i, j in enumerate(desc.joints):
        origin, tail, axis, waypoints, row_end = _row_frames(desc, i, tail_prev)
        unit_range = 1.0 if j.prismatic else 2 * math.pi
        lower = j.lower if j.lower is not None else -unit_range
        upper = j.upper if j.upper is not None else unit_range
        mimic = ""
        if j.mimic is not None:
            mimic = (f'<mimic joint="{escape(j.mimic.joint)}" multiplier="{_f(j.mimic.multiplier)}" '
                     f'offset="{_f(j.mimic.offset)}"/>')
        lines.append(f'  <joint name="{escape(j.name)}" type="{j.kind}"><parent link="{parent}"/>'
                     f'<child link="link_{i + 1}"/>{_origin(origin)}<axis xyz="{_f(axis[0])} {_f(axis[1])} '
                     f'{_f(axis[2])}"/>'
                     f'<limit lower="{_f(lower)}" upper="{_f(upper)}" effort="100" velocity="3"/>{mimic}</joint>')
        visuals = [_user_visuals(desc, i)] if _user_visuals(desc, i) else [_joint_housing(float(radii[i]) * 1.3)] + [
            _cylinder_between(a, b, float(radii[i]), "arm") for a, b in zip(waypoints[:-1], waypoints[1:], strict=True)]
        com = row_end @ np.array([*j.com, 1.0])
        lines.append(f'  <link name="link_{i + 1}">{_inertial(j.mass, com[:3])}{"".join(visuals)}</link>')
        parent = f"link_{i + 1}"
        tail_prev = tail
    p = desc.probe
    lever = p.stylus_length
    hinge = np.eye(4)       # T_last_hinge: the probe frame's orientation at p_last - L z_probe
    if p.rotation is not None:
        hinge[:3, :3] = p.rotation
    hinge[:3, 3] = np.asarray(p.p_last) - lever * hinge[:3, 2]
    lines += [
        f'  <joint name="{FLANGE_FRAME}_joint" type="fixed"><parent link="{parent}"/>'
        f'<child link="{FLANGE_FRAME}"/>{_origin(tail_prev)}</joint>',
        f'  <link name="{FLANGE_FRAME}">'
        f'{_cylinder_between(hinge[:3, 3], hinge[:3, 3] + 0.012 * hinge[:3, 2], 0.012, "joint")}</link>',
        f'  <joint name="stylus_root_joint" type="fixed"><parent link="{FLANGE_FRAME}"/>'
        f'<child link="stylus_root"/>{_origin(hinge)}</joint>',
        '  <link name="stylus_root"/>',
        '  <joint name="probe_bend_y" type="revolute"><parent link="stylus_root"/><child link="probe_bend_y_link"/>'
        '<origin xyz="0 0 0" rpy="0 0 0"/><axis xyz="0 1 0"/><limit lower="-0.1" upper="0.1" effort="1" '
        'velocity="1"/></joint>',
        '  <link name="probe_bend_y_link"/>',
        '  <joint name="probe_bend_x" type="revolute"><parent link="probe_bend_y_link"/>'
        '<child link="probe_bend_x_link"/>'
        '<origin xyz="0 0 0" rpy="0 0 0"/><axis xyz="1 0 0"/><limit lower="-0.1" upper="0.1" effort="1" '
        'velocity="1"/></joint>',
        '  <link name="probe_bend_x_link"/>',
        '  <joint name="probe_axial" type="prismatic"><parent link="probe_bend_x_link"/><child link="stylus"/>'
        '<origin xyz="0 0 0" rpy="0 0 0"/><axis xyz="0 0 1"/><limit lower="-0.001" upper="0.001" effort="1" '
        'velocity="1"/></joint>',
        '  <link name="stylus">'
        f'{_cylinder_between((0, 0, 0), (0, 0, max(lever - p.ball_diameter / 2, 0.0)), 0.003, "probe")}</link>',
        f'  <joint name="{BALL_FRAME}_joint" type="fixed"><parent link="stylus"/><child link="{escape(tip_link)}"/>'
        f'<origin xyz="0 0 {_f(lever)}" rpy="0 0 0"/></joint>',
        f'  <link name="{escape(tip_link)}"><visual><origin xyz="0 0 0" rpy="0 0 0"/><geometry>'
        f'<sphere radius="{_f(p.ball_diameter / 2)}"/></geometry><material name="ball"/></visual></link>',
        "</robot>",
    ]
    return "\n".join(lines) + "\n"
