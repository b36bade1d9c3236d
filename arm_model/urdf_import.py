"""An arm given as a URDF (docs/formats.md §2): the chain from the root link to the tip frame.

The file is read with lxml (so that every error names its line) and modelled with yourdfpy. The chain
runs from the root link to ``tip_frame``; other branches (fingers, sensors) are held at zero. Fixed
joints on the chain are folded into the next revolute joint's origin; those after the last revolute
joint into the probe pose: the tip frame's full pose in the last joint frame gives the ball centre and
the probe frame (its z axis along the stylus, towards the ball), whatever its orientation. The virtual
bending hinge sits where the stylus line passes closest to the last joint origin; if the tip frame's z
points back past that origin, |p| behind the ball. The project's
own virtual elastic probe joints (``probe_bend_y``, ``probe_bend_x``, ``probe_axial`` of
``aacmm urdf``) are recognised: they are held at zero and their hinge sets the stylus length.

Masses: each revolute joint of the chain carries the mass and centre of mass of everything it moves
up to the next revolute joint of the chain: its child link's ``<inertial>`` plus those of every link
hanging from it through fixed joints or side branches (held at zero), folded into the child link's
frame. A masses file (:func:`load_masses`, ``--masses``) gives or replaces link inertials for URDFs
without them.

A URDF carries no probe data: the ball diameter comes from a ``<sphere>`` on the tip link if there is
one; the force range and compliances from the caller (default: the seed paper's probe).
"""
from __future__ import annotations

import io
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ._csv import parse_number
from ._errors import InputError, open_input, parse_toml, read_text
from ._units import implausible
from .description import ArmDescription, JointRow, Probe, TomlReader, load_description
from .shipped import arm_path
from .urdf import ELASTIC_JOINTS, _origin_matrix

__all__ = ["description_from_urdf", "load_arm", "load_masses", "calibrated_urdf_text", "PAPER_PROBE",
           "LinkMass"]

#: the seed paper's probe: 4 mm ball, 13 N range, FEM compliances [m], [N], [m/N]
PAPER_PROBE = dict(ball_diameter=0.004, max_force=13.0, bending_compliance_x=1.42e-5,
                   bending_compliance_y=1.42e-5, axial_compliance=8.76e-8)

_JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")
#: numeric attributes of URDF elements: tag -> {attribute: count}
_NUMERIC = {
    "origin": {"xyz": 3, "rpy": 3}, "axis": {"xyz": 3}, "mass": {"value": 1},
    "limit": {"lower": 1, "upper": 1, "effort": 1, "velocity": 1},
    "inertia": {k: 1 for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")},
    "sphere": {"radius": 1}, "cylinder": {"radius": 1, "length": 1}, "box": {"size": 3},
    "mesh": {"scale": 3}, "color": {"rgba": 4}, "dynamics": {"damping": 1, "friction": 1},
    "mimic": {"multiplier": 1, "offset": 1}, "calibration": {"rising": 1, "falling": 1},
    "safety_controller": {"soft_lower_limit": 1, "soft_upper_limit": 1, "k_position": 1, "k_velocity": 1},
}
#: (tag, attribute) -> the quantity whose plausible range (arm_model._units.PLAUSIBLE_SI) its numbers keep
_QUANTITY = {("origin", "xyz"): "length", ("origin", "rpy"): "angle", ("mass", "value"): "mass", ("axis", "xyz"): "ratio",
             ("sphere", "radius"): "length", ("cylinder", "radius"): "length", ("cylinder", "length"): "length",
             ("box", "size"): "length"}
#: (tag, attribute) whose numbers are sizes, masses, or colours: never negative
_NOT_NEGATIVE = {("mass", "value"), ("sphere", "radius"), ("cylinder", "radius"), ("cylinder", "length"),
                 ("box", "size"), ("mesh", "scale"), ("color", "rgba"), ("inertia", "ixx"), ("inertia", "iyy"),
                 ("inertia", "izz")}
_ELASTIC_TYPES = dict(zip(ELASTIC_JOINTS, ("revolute", "revolute", "prismatic")))


@dataclass(frozen=True)
class LinkMass:
    """A link's mass [kg] and centre of mass [m] in its own frame (a URDF ``<inertial>``)."""
    mass: float
    com: tuple[float, float, float]
    #: where it was read (the masses file and the line of its [[link]]), for messages
    source: tuple[str, int | None] | None = field(default=None, compare=False)


# ---------------------------------------------------------------------------------------------
# reading and checking the file

@dataclass
class _Urdf:
    """A checked URDF: the lxml tree (for lines and for writing back) and the yourdfpy model."""
    path: Path
    tree: object                 # lxml ElementTree
    robot: object                # yourdfpy Robot
    joint_elements: dict         # name -> lxml element
    link_elements: dict

    def line(self, name: str, kind: str = "joint") -> int | None:
        el = (self.joint_elements if kind == "joint" else self.link_elements).get(name)
        return None if el is None else el.sourceline

    def error(self, msg: str, name: str | None = None, kind: str = "joint", column: str | None = None):
        return InputError(msg, self.path, None if name is None else self.line(name, kind), column)


def _parse_xml(path: Path, data: bytes):
    """The lxml tree of a URDF, parsed safely: no entity resolved, nothing fetched; a DOCTYPE that declares
    entities or names an external DTD is refused (a URDF needs neither, and yourdfpy, which parses the file
    again, would print its parse errors on standard error)."""
    from lxml import etree
    try:
        tree = etree.parse(io.BytesIO(data), etree.XMLParser(remove_comments=False, resolve_entities=False,
                                                              no_network=True, load_dtd=False))
    except etree.XMLSyntaxError as exc:
        line, col = exc.position if exc.position else (None, None)
        raise InputError(f"not valid XML: {exc.msg}", path, line, None if col is None else f"column {col}") from None
    info = tree.docinfo
    if info.system_url or info.public_id or (info.internalDTD is not None and any(info.internalDTD.iterentities())):
        raise InputError("a <!DOCTYPE> that declares entities or names an external DTD: a URDF needs neither (entities "
                         "could read other files or the network); remove it", path,
                         data[: max(data.find(b"<!DOCTYPE"), 0)].count(b"\n") + 1)
    return tree


def _read_urdf(path: str | Path) -> _Urdf:
    """Read and check a URDF; every problem is an InputError naming the file and the line."""
    import yourdfpy

    path = Path(path)
    with open_input(path, "the URDF") as fh:
        try:
            data = fh.read()
        except OSError as exc:
            raise InputError(f"cannot read the URDF: {exc.strerror}", path) from None
    tree = _parse_xml(path, data)
    root = tree.getroot()
    if root.tag != "robot":
        raise InputError(f"a URDF's root element is <robot>, got <{root.tag}>", path, root.sourceline)
    if not root.get("name"):
        raise InputError("<robot> has no name", path, root.sourceline)
    for el in root.iter():
        if not isinstance(el.tag, str):
            continue
        for attr, n in _NUMERIC.get(el.tag, {}).items():
            text = el.get(attr)
            if text is None:
                continue
            vals = [parse_number(v) for v in text.split()]
            if len(vals) != n or not all(v is not None and math.isfinite(v) for v in vals):
                raise InputError(f"<{el.tag} {attr}=...> must be {n} finite number{'s' if n > 1 else ''}, "
                                 f"got {text!r}", path, el.sourceline, f"key '{el.tag}.{attr}'")
            quantity = _QUANTITY.get((el.tag, attr))
            wrong = implausible(vals, quantity) if quantity else None
            if wrong:
                raise InputError(f"<{el.tag} {attr}=...>: {wrong[1]}", path, el.sourceline, f"key '{el.tag}.{attr}'")
            if (el.tag, attr) in _NOT_NEGATIVE and min(vals) < 0:
                raise InputError(f"<{el.tag} {attr}=...> must not be negative, got {text!r}", path, el.sourceline,
                                 f"key '{el.tag}.{attr}'")
            if el.tag == "color" and max(vals) > 1:
                raise InputError(f"<color rgba=...> takes four numbers in [0, 1], got {text!r}", path,
                                 el.sourceline, f"key '{el.tag}.{attr}'")
    links, joints = {}, {}
    for el in root.findall("link"):
        name = el.get("name")
        if not name:
            raise InputError("a <link> has no name", path, el.sourceline)
        if name in links:
            raise InputError(f"link '{name}' is defined twice (first on line {links[name].sourceline})",
                             path, el.sourceline)
        links[name] = el
    children = {}
    for el in root.findall("joint"):
        name, jtype = el.get("name"), el.get("type")
        if not name:
            raise InputError("a <joint> has no name", path, el.sourceline)
        if name in joints:
            raise InputError(f"joint '{name}' is defined twice (first on line {joints[name].sourceline})",
                             path, el.sourceline)
        if jtype not in _JOINT_TYPES:
            raise InputError(f"joint '{name}': type must be one of {', '.join(_JOINT_TYPES)}, got {jtype!r}",
                             path, el.sourceline)
        for tag in ("parent", "child"):
            sub = el.find(tag)
            if sub is None or not sub.get("link"):
                raise InputError(f"joint '{name}' has no <{tag} link=...>", path, el.sourceline)
            if sub.get("link") not in links:
                raise InputError(f"joint '{name}': {tag} link '{sub.get('link')}' is not defined", path,
                                 sub.sourceline)
        child = el.find("child").get("link")
        if child in children:
            raise InputError(f"link '{child}' is the child of two joints ('{children[child]}' and '{name}'): "
                             "a URDF is a tree", path, el.sourceline)
        children[child] = name
        if jtype in ("revolute", "prismatic") and el.find("limit") is None:
            raise InputError(f"joint '{name}' ({jtype}) has no <limit>", path, el.sourceline)
        joints[name] = el
    for el in root.iter("geometry"):
        kids = [k for k in el if isinstance(k.tag, str)]
        if len(kids) != 1 or kids[0].tag not in ("box", "cylinder", "sphere", "mesh"):
            raise InputError("<geometry> must hold one <box>, <cylinder>, <sphere> or <mesh>", path, el.sourceline)
    try:
        model = yourdfpy.URDF.load(io.BytesIO(data), build_scene_graph=False, load_meshes=False,
                                   load_collision_meshes=False)
    except Exception as exc:   # a case the checks above miss: still one located-as-possible message
        raise InputError(f"yourdfpy cannot read the URDF: {exc}", path) from None
    return _Urdf(path, tree, model.robot, joints, links)


def _rpy(T: np.ndarray) -> tuple[float, float, float]:
    """URDF rpy of a 4x4's rotation (:func:`arm_model.geometry.rpy_from_matrix`, imported when used:
    `aacmm --help` imports this module, not scipy)."""
    from .geometry import rpy_from_matrix
    return rpy_from_matrix(T[:3, :3])


def _T(origin) -> np.ndarray:
    return np.eye(4) if origin is None else np.asarray(origin, dtype=float)


@dataclass
class _Chain:
    """The chain root -> tip of a URDF.

    ``moving``: the revolute joints, each with ``prefix`` = the product of the fixed (or held)
    joints' origins between the previous moving frame and it; ``tool_prefix``: the same from the
    last moving frame to the tip joint's parent; ``tip_joint``: the joint whose child is the tip.
    ``hinge``: T_last_hinge of the project's elastic probe joints, None without them.
    """
    moving: list            # (joint, prefix 4x4)
    tool_prefix: np.ndarray
    tip_joint: object
    T_last_tip: np.ndarray
    hinge: np.ndarray | None


def _chain(u: _Urdf, tip_frame: str) -> _Chain:
    if tip_frame not in u.link_elements:
        raise InputError(f"no link named '{tip_frame}' (links: {', '.join(u.link_elements)})", u.path, None,
                         "key '--tip-frame'")
    by_child = {j.child: j for j in u.robot.joints}
    chain, link, seen = [], tip_frame, set()
    while link in by_child:
        if link in seen:
            raise u.error(f"the joints form a loop through link '{link}'", by_child[link].name)
        seen.add(link)
        chain.append(by_child[link])
        link = by_child[link].parent
    chain.reverse()
    elastic = [j for j in chain if _ELASTIC_TYPES.get(j.name) == j.type]
    held = {j.name for j in elastic} if len(elastic) == len(ELASTIC_JOINTS) else set()
    moving, pending, tool_prefix, hinge = [], np.eye(4), np.eye(4), None
    for j in chain:
        if j.child == tip_frame:
            tool_prefix = pending.copy()
        if j.name == ELASTIC_JOINTS[0] and held:
            hinge = pending @ _T(j.origin)
        if j.type == "fixed" or j.name in held:
            pending = pending @ _T(j.origin)
            continue
        if j.type not in ("revolute", "continuous"):
            raise u.error(f"joint '{j.name}' on the chain to '{tip_frame}' is {j.type}: the toolkit models "
                          "revolute joints only", j.name)
        moving.append((j, pending))
        pending = np.eye(4)
        hinge = None
    if not moving:
        raise InputError(f"no revolute joint between the root and '{tip_frame}'", u.path, None, "key '--tip-frame'")
    tip_joint = chain[-1]
    if tip_joint.type != "fixed" and tip_joint.name not in held:
        tool_prefix = None
    return _Chain(moving, tool_prefix, tip_joint, pending, hinge)


# ---------------------------------------------------------------------------------------------
# masses

def _inertials(u: _Urdf, masses: dict | None) -> dict[str, tuple[float, np.ndarray]]:
    """Link -> (mass [kg], centre of mass [m] in the link frame): the URDF's, replaced by ``masses``."""
    out = {}
    for link in u.robot.links:
        inert = link.inertial
        if inert is not None and inert.mass:
            if inert.mass < 0:
                raise u.error(f"link '{link.name}' has a negative mass", link.name, "link")
            out[link.name] = (float(inert.mass), _T(inert.origin)[:3, 3].copy())
    for name, m in (masses or {}).items():
        out[name] = (m.mass, np.asarray(m.com, dtype=float))
    return out


def _fold_masses(u: _Urdf, ch: _Chain, masses: dict | None) -> list[tuple[float, tuple]]:
    """(mass, com in the joint's child frame) of each moving joint: its child link and everything
    hanging from it (fixed joints, side branches at zero) up to the next moving joint."""
    inert = _inertials(u, masses)
    moving_names = {j.name for j, _ in ch.moving}
    kids: dict[str, list] = {}
    for j in u.robot.joints:
        kids.setdefault(j.parent, []).append(j)
    out = []
    for j, _ in ch.moving:
        total, first = 0.0, np.zeros(3)
        stack = [(j.child, np.eye(4))]
        while stack:
            link, T = stack.pop()
            if link in inert:
                m, c = inert[link]
                total += m
                first += m * (T[:3, :3] @ c + T[:3, 3])
            for k in kids.get(link, ()):
                if k.name not in moving_names:
                    stack.append((k.child, T @ _T(k.origin)))
        com = first / total if total > 0 else np.zeros(3)
        out.append((total, tuple(float(v) for v in com)))
    return out


def load_masses(path: str | Path) -> dict[str, LinkMass]:
    """Read a masses file: link masses for an arm given as a URDF without ``<inertial>`` tags.

    TOML, one ``[[link]]`` table a link: ``name`` (a link of the URDF), ``mass_kg`` and the centre of
    mass ``com_x_mm``, ``com_y_mm``, ``com_z_mm`` (default 0) in the link's own frame, as an
    ``<inertial>`` would give them. A link listed here replaces that link's ``<inertial>``.
    """
    text = read_text(path, "the masses file")
    data = parse_toml(text, path)
    r = TomlReader(str(path), text)
    unknown = sorted(set(data) - {"link"})
    if unknown:
        raise r.error(f"unknown top-level key '{unknown[0]}' (known: link)", unknown[0])
    rows = data.get("link")
    if not isinstance(rows, list) or not rows or not all(isinstance(row, dict) for row in rows):
        raise r.error("no [[link]] tables (one per link: name, mass_kg, com_x_mm, com_y_mm, com_z_mm)", "link")
    out: dict[str, LinkMass] = {}
    spec = {"mass": ("mass", True), "com_x": ("length", False), "com_y": ("length", False),
            "com_z": ("length", False)}
    for i, row in enumerate(rows):
        name = row.get("name")
        if not isinstance(name, str) or not name:
            raise r.error("each [[link]] needs 'name', the URDF link", "link", i, "name")
        if name in out:
            raise r.error(f"link '{name}' is listed twice", "link", i, "name")
        vals = r.values(row, spec, ("link", i), text_keys=("name",))
        if not 0 <= vals["mass"] <= 1e4:
            raise r.error(f"mass must be in [0, 10000] kg, got {vals['mass']:g}", "link", i, "mass_kg")
        if any(abs(vals.get(k, 0.0)) > 100.0 for k in ("com_x", "com_y", "com_z")):
            raise r.error("a centre of mass more than 100 m from its link frame is not plausible", "link", i)
        out[name] = LinkMass(vals["mass"], tuple(vals.get(k, 0.0) for k in ("com_x", "com_y", "com_z")),
                             (str(path), r.lines.get(("link", i, "name"), r.lines.get(("link", i)))))
    return out


# ---------------------------------------------------------------------------------------------
# the description

def _ball_diameter(u: _Urdf, tip_frame: str) -> float | None:
    """Diameter [m] of a sphere centred on the tip link (visual or collision), if there is one."""
    link = next(l for l in u.robot.links if l.name == tip_frame)
    for g in list(link.visuals) + list(link.collisions):
        if g.geometry is not None and g.geometry.sphere is not None and np.allclose(_T(g.origin)[:3, 3], 0, atol=1e-9):
            return 2.0 * float(g.geometry.sphere.radius)
    return None


def description_from_urdf(path: str | Path, tip_frame: str, probe: dict | None = None,
                          name: str | None = None, masses: dict | None = None) -> ArmDescription:
    """Read the serial chain root -> ``tip_frame`` (a link name) of a URDF as a description.

    Args:
        path: URDF file.
        tip_frame: the link at the ball centre; its orientation is the probe frame's (z along the
            stylus, towards the ball).
        probe: ball_diameter [m], max_force [N], bending_compliance_x/_y, axial_compliance [m/N]
            (default :data:`PAPER_PROBE`, the ball diameter from a sphere on the tip link).
        masses: link -> :class:`LinkMass` (see :func:`load_masses`), replacing the URDF's inertials.
    """
    u = _read_urdf(path)
    if masses:
        for lname, m in masses.items():
            if lname not in u.link_elements:
                where = m.source if isinstance(m, LinkMass) and m.source else (u.path, None)
                raise InputError(f"the masses name link '{lname}', which the URDF {u.path} does not have "
                                 f"(links: {', '.join(u.link_elements)})", where[0], where[1],
                                 "key 'link.name'")
    ch = _chain(u, tip_frame)
    folded = _fold_masses(u, ch, masses)
    rows = []
    for (j, prefix), (mass, com) in zip(ch.moving, folded):
        T = prefix @ _T(j.origin)
        axis = np.asarray(j.axis if j.axis is not None else (1.0, 0.0, 0.0), dtype=float)
        if np.linalg.norm(axis) < 1e-9:
            raise u.error(f"joint '{j.name}' has a zero axis", j.name)
        lower = upper = None
        if j.type == "revolute" and j.limit is not None and j.limit.lower is not None and j.limit.upper is not None:
            lower, upper = float(j.limit.lower), float(j.limit.upper)
            if not lower < upper:
                raise u.error(f"joint '{j.name}': lower limit {lower:g} is not below upper limit {upper:g}", j.name)
        roll, pitch, yaw = _rpy(T)
        rows.append(JointRow(name=j.name, origin=(float(T[0, 3]), float(T[1, 3]), float(T[2, 3]), roll, pitch, yaw),
                             axis=tuple(float(v) for v in axis / np.linalg.norm(axis)), lower=lower, upper=upper,
                             mass=mass, com=com))
    T_tip = ch.T_last_tip
    p_last = tuple(float(v) for v in T_tip[:3, 3])
    rpy = tuple(float(v) + 0.0 for v in _rpy(T_tip))
    if np.allclose(T_tip[:3, :3], np.eye(3), atol=0, rtol=0):
        rpy = (0.0, 0.0, 0.0)
    lever = None
    if ch.hinge is not None:
        lever = float((T_tip[:3, 3] - ch.hinge[:3, 3]) @ T_tip[:3, 2])
    elif T_tip[:3, 2] @ T_tip[:3, 3] < 1e-3 * np.linalg.norm(T_tip[:3, 3]):
        # the tool points back past (or across) the last joint origin: hang the stylus |p| behind the ball
        lever = float(np.linalg.norm(T_tip[:3, 3]))
    pr = dict(PAPER_PROBE)
    ball = _ball_diameter(u, tip_frame)
    if ball is not None:
        pr["ball_diameter"] = ball
    pr.update(probe or {})
    pro = Probe(p_last=p_last, rpy=rpy, lever=lever, **pr)
    if not pro.stylus_length > 1e-6:
        raise InputError(f"the tip frame '{tip_frame}' lies at the origin of the last joint frame (or its stylus "
                         f"hinge): a probe needs a ball beyond the last joint", u.path, u.line(ch.tip_joint.name),
                         "key '--tip-frame'")
    return ArmDescription(name=name or u.robot.name or Path(path).stem, convention="urdf", joints=tuple(rows),
                          probe=pro, source=str(path), tip_frame=tip_frame)


def load_arm(path: str | Path, tip_frame: str | None = None, probe: dict | None = None,
             masses: str | Path | None = None) -> ArmDescription:
    """An arm from a description TOML, a shipped arm's name (``aacmm7``) or, with ``tip_frame``, a URDF
    file; ``masses``: a masses file (:func:`load_masses`) for a URDF arm."""
    path = arm_path(path)
    if path.suffix.lower() == ".urdf":
        if not tip_frame:
            raise InputError("an arm given as a URDF needs --tip-frame (the link at the ball centre)", path)
        return description_from_urdf(path, tip_frame, probe, masses=None if masses is None else load_masses(masses))
    if masses is not None:
        raise InputError("--masses is for an arm given as a URDF; a description TOML carries its masses in its "
                         "[[joint]] rows (mass_kg, com_x_mm, com_y_mm, com_z_mm)", masses)
    return load_description(path)


# ---------------------------------------------------------------------------------------------
# the calibrated URDF: the user's file with the identified origins changed

def _fmt(x: float) -> str:
    return repr(float(x) + 0.0)


def _set_origin(joint_el, T: np.ndarray, xyz_only: bool = False) -> None:
    """Write T into the joint's <origin> (created if absent); ``xyz_only`` keeps its rpy text."""
    from lxml import etree
    o = joint_el.find("origin")
    if o is None:
        o = etree.SubElement(joint_el, "origin")
    o.set("xyz", " ".join(_fmt(v) for v in T[:3, 3]))
    if not xyz_only:
        o.set("rpy", " ".join(_fmt(v) for v in _rpy(T)))


def calibrated_urdf_text(nominal: ArmDescription, calibrated: ArmDescription) -> str:
    """The calibrated arm as a URDF.

    For an arm read from a URDF (``nominal.tip_frame``): the user's own file, with only the origins
    of the chain's revolute joints whose row changed and the tip joint's xyz (the tool offset)
    rewritten; names, meshes, inertials, limits, comments, other joints and frames are kept. For a
    description TOML: the generated URDF (:func:`arm_model.urdf.urdf_text`).
    """
    from lxml import etree
    from .urdf import urdf_text

    if not nominal.tip_frame or not nominal.source or Path(nominal.source).suffix.lower() != ".urdf":
        return urdf_text(calibrated)
    u = _read_urdf(nominal.source)
    ch = _chain(u, nominal.tip_frame)
    names = [j.name for j, _ in ch.moving]
    if names != list(nominal.joint_names) or names != list(calibrated.joint_names):
        raise InputError("the URDF's chain no longer matches the arm that was calibrated (was it edited?)",
                         u.path)
    for (j, prefix), row_nom, row_cal in zip(ch.moving, nominal.joints, calibrated.joints):
        if row_cal.origin == row_nom.origin:
            continue
        T = np.linalg.inv(prefix) @ _origin_matrix(row_cal.origin)
        _set_origin(u.joint_elements[j.name], T)
    if calibrated.probe.p_last != nominal.probe.p_last:
        if ch.tool_prefix is None:
            raise InputError(f"the tip frame '{nominal.tip_frame}' hangs from a moving joint: the tool offset "
                             "cannot be written", u.path)
        el = u.joint_elements[ch.tip_joint.name]
        T = _T(ch.tip_joint.origin).copy()
        T[:3, 3] = (np.linalg.inv(ch.tool_prefix) @ np.array([*calibrated.probe.p_last, 1.0]))[:3]
        _set_origin(el, T, xyz_only=True)
    text = etree.tostring(u.tree, encoding="unicode")
    decl = u.tree.docinfo.xml_version
    has_decl = Path(nominal.source).read_bytes().lstrip().startswith(b"<?xml")
    return (f'<?xml version="{decl or "1.0"}"?>\n' if has_decl else "") + text + "\n"
