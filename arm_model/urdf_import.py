"""An arm given as a URDF (docs/formats.md §2): the chain from the root link to the tip frame.

Other branches are ignored (their joints held at zero). Fixed joints on the chain are folded into
the next revolute joint's origin; those after the last revolute joint into the probe point. The
probe frame is parallel to the last joint's frame, so the tip frame's own orientation is not used.
A URDF carries no probe data: ball diameter, force range and compliances come from the caller
(default: the seed paper's 85 mm probe) and the tools say so.
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from ._errors import InputError
from .description import ArmDescription, JointRow, Probe, load_description
from .shipped import arm_path
from .urdf import _origin_matrix, rpy_from_matrix

__all__ = ["description_from_urdf", "load_arm", "PAPER_PROBE"]

#: the seed paper's probe: 4 mm ball, 13 N range, FEM compliances [m], [N], [m/N]
PAPER_PROBE = dict(ball_diameter=0.004, max_force=13.0, bending_compliance_x=1.42e-5,
                   bending_compliance_y=1.42e-5, axial_compliance=8.76e-8)


def _floats(text: str | None, n: int, default, path, what) -> tuple:
    if text is None:
        return default
    try:
        vals = tuple(float(v) for v in text.split())
    except ValueError:
        raise InputError(f"{what}: expected {n} numbers, got {text!r}", path) from None
    if len(vals) != n or not all(math.isfinite(v) for v in vals):
        raise InputError(f"{what}: expected {n} finite numbers, got {text!r}", path)
    return vals


def description_from_urdf(path: str | Path, tip_frame: str, probe: dict | None = None,
                          name: str | None = None) -> ArmDescription:
    """Read the serial chain root -> ``tip_frame`` (a link name) of a URDF as a description.

    Args:
        path: URDF file.
        tip_frame: the link at the ball centre.
        probe: ball_diameter [m], max_force [N], bending_compliance_x/_y, axial_compliance [m/N]
            (default :data:`PAPER_PROBE`).
    """
    path = Path(path)
    try:
        root = ET.parse(path).getroot()
    except OSError as exc:
        raise InputError(f"cannot read the URDF: {exc.strerror}", path) from None
    except ET.ParseError as exc:
        line, col = exc.position
        raise InputError(f"not valid XML: {exc}", path, line, f"column {col}") from None
    links = {l.get("name"): l for l in root.findall("link")}
    if tip_frame not in links:
        raise InputError(f"no link named '{tip_frame}' (links: {', '.join(links)})", path, None,
                         "key '--tip-frame'")
    by_child = {}
    for j in root.findall("joint"):
        child = j.find("child")
        if child is not None:
            by_child[child.get("link")] = j
    chain, link = [], tip_frame
    while link in by_child:
        j = by_child[link]
        chain.append(j)
        link = j.find("parent").get("link")
    chain.reverse()
    rows, pending = [], np.eye(4)
    for j in chain:
        jname, jtype = j.get("name"), j.get("type")
        o = j.find("origin")
        xyz = _floats(None if o is None else o.get("xyz"), 3, (0.0, 0.0, 0.0), path, f"joint '{jname}' origin xyz")
        rpy = _floats(None if o is None else o.get("rpy"), 3, (0.0, 0.0, 0.0), path, f"joint '{jname}' origin rpy")
        T = pending @ _origin_matrix((*xyz, *rpy))
        if jtype == "fixed":
            pending = T
            continue
        if jtype not in ("revolute", "continuous"):
            raise InputError(f"joint '{jname}' on the chain to '{tip_frame}' is {jtype}: a measuring arm "
                             "has revolute joints only", path)
        a = j.find("axis")
        axis = np.array(_floats(None if a is None else a.get("xyz"), 3, (1.0, 0.0, 0.0), path,
                                f"joint '{jname}' axis"))
        if np.linalg.norm(axis) < 1e-9:
            raise InputError(f"joint '{jname}' has a zero axis", path)
        lim = j.find("limit")
        lower = upper = None
        if jtype == "revolute" and lim is not None and lim.get("lower") is not None:
            lower, upper = float(lim.get("lower")), float(lim.get("upper"))
        child = links[j.find("child").get("link")]
        mass, com = 0.0, (0.0, 0.0, 0.0)
        inert = child.find("inertial")
        if inert is not None and inert.find("mass") is not None:
            mass = float(inert.find("mass").get("value"))
            io = inert.find("origin")
            com = _floats(None if io is None else io.get("xyz"), 3, (0.0, 0.0, 0.0), path, f"link '{child.get('name')}' com")
        roll, pitch, yaw = rpy_from_matrix(T[:3, :3])
        rows.append(JointRow(name=jname, origin=(float(T[0, 3]), float(T[1, 3]), float(T[2, 3]), roll, pitch, yaw),
                             axis=tuple(float(v) for v in axis / np.linalg.norm(axis)), lower=lower, upper=upper,
                             mass=mass, com=tuple(com)))
        pending = np.eye(4)
    if not rows:
        raise InputError(f"no revolute joint between the root and '{tip_frame}'", path)
    p_last = pending[:3, 3]
    if p_last[2] <= 0:
        raise InputError(f"the tip frame '{tip_frame}' must lie beyond the last joint along its z axis "
                         f"(the probe z axis points along the stylus); got z = {p_last[2] * 1e3:.3f} mm",
                         path, None, "key '--tip-frame'")
    pr = dict(PAPER_PROBE, **(probe or {}))
    return ArmDescription(name=name or root.get("name", path.stem), convention="urdf", joints=tuple(rows),
                          probe=Probe(p_last=tuple(float(v) for v in p_last), **pr), source=str(path))


def load_arm(path: str | Path, tip_frame: str | None = None, probe: dict | None = None) -> ArmDescription:
    """An arm from a description TOML, a shipped arm's name (``aacmm7``) or, with ``tip_frame``, a URDF file."""
    path = arm_path(path)
    if path.suffix.lower() == ".urdf":
        if not tip_frame:
            raise InputError("an arm given as a URDF needs --tip-frame (the link at the ball centre)", path)
        return description_from_urdf(path, tip_frame, probe)
    return load_description(path)
