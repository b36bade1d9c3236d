"""An arm given as a URDF (docs/formats.md §2): the chain from the root link to the tip frame.

The file is read with lxml (so that every error names its line) and modelled with yourdfpy. The chain
runs from the root link to ``tip_frame``; other branches (fingers, sensors) are held at zero. Its moving
joints are revolute, continuous (revolute without limits) and prismatic; a ``<mimic>`` joint follows its
master as the URDF says (``multiplier``, ``offset``): it takes no encoder column when its master is on the
chain, and reads its master's column when the master is off it (a gripper finger mimicking the other
finger); a multiplier of 0 holds it at its offset. Fixed joints on the chain are folded into the next
moving joint's origin; those after the last moving joint into the probe pose: the tip frame's full pose in
the last joint frame gives the ball centre and the probe frame (its z axis along the stylus, towards the
ball), whatever its orientation. The virtual bending hinge sits where the stylus line passes closest to
the last joint origin; if the tip frame's z points back past that origin, |p| behind the ball. A tip frame
at the last joint's origin (a robot's flange, a wrist link) is a tip without a stylus: rigid, its
compliances 0. The project's own virtual elastic probe joints (``probe_bend_y``, ``probe_bend_x``,
``probe_axial`` of ``aacmm urdf``) are recognised: they are held at zero and their hinge sets the stylus
length.

Only what the chain uses is checked beyond being numbers: joint origins, axes, limits and mimics when the
file is read, the masses of the links folded into the chain when they are folded. Visual and collision
content (meshes, mirrored scales, missing mesh files), inertia tensors, efforts and damping are never used.

Masses: each moving joint of the chain carries the mass and centre of mass of everything it moves
up to the next moving joint of the chain: its child link's ``<inertial>`` plus those of every link
hanging from it through fixed joints or side branches (held at zero), folded into the child link's
frame. A masses file (:func:`load_masses`, ``--masses``) gives or replaces link inertials for URDFs
without them.

A URDF carries no probe data: the ball diameter comes from a ``<sphere>`` on the tip link if there is
one; the force range and compliances from the caller (default: the seed paper's probe).
"""
from __future__ import annotations

import io
import logging
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

from .csv_io import parse_number
from .description import (
    MIN_STYLUS,
    ArmDescription,
    JointRow,
    Mimic,
    Probe,
    TomlReader,
    Visual,
    default_lever,
    load_description,
)
from .effects import PAPER_STYLUS_COMPLIANCE
from .errors import InputError, beside, did_you_mean, id_problem, named_in, open_input, parse_toml, read_text, resolved
from .shipped import arm_path
from .units import implausible
from .urdf import ELASTIC_JOINTS, origin_matrix

log = logging.getLogger(__name__)

__all__ = ["description_from_urdf", "load_arm", "is_urdf", "tip_candidates", "URDF_SUFFIXES", "load_masses",
           "calibrated_urdf_text", "PAPER_PROBE",
           "LinkMass"]

#: the seed paper's probe: 4 mm ball, 13 N range, FEM compliances [m], [N], [m/N]
PAPER_PROBE = dict(ball_diameter=0.004, max_force=13.0, bending_compliance_x=PAPER_STYLUS_COMPLIANCE[0],
                   bending_compliance_y=PAPER_STYLUS_COMPLIANCE[1], axial_compliance=PAPER_STYLUS_COMPLIANCE[2])

_JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")
#: numeric attributes of URDF elements: tag -> {attribute: count}; every one must be that many numbers
#: (a file whose numbers are not numbers is broken for every reader)
_NUMERIC = {
    "origin": {"xyz": 3, "rpy": 3}, "axis": {"xyz": 3}, "mass": {"value": 1},
    "limit": {"lower": 1, "upper": 1, "effort": 1, "velocity": 1},
    "inertia": {k: 1 for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")},
    "sphere": {"radius": 1}, "cylinder": {"radius": 1, "length": 1}, "box": {"size": 3},
    "mesh": {"scale": 3}, "color": {"rgba": 4}, "dynamics": {"damping": 1, "friction": 1},
    "mimic": {"multiplier": 1, "offset": 1}, "calibration": {"rising": 1, "falling": 1},
    "safety_controller": {"soft_lower_limit": 1, "soft_upper_limit": 1, "k_position": 1, "k_velocity": 1},
}
#: the numbers the kinematics use, by (parent tag, tag, attribute) -> the quantity whose plausible range
#: (arm_model.units.PLAUSIBLE_SI) they keep (None: finite only), and every number of an ``<inertial>``: urdfdom
#: refuses a non-finite one there and Pinocchio then drops the link's inertial without a word, and a calibrated
#: URDF carries it to every dynamics tool. Only these are checked beyond being numbers when the file is read; a
#: mass the chain uses is moreover not negative (:func:`_checked_mass`), one off the chain is warned
#: (:func:`_warn_negative_masses`); inertia tensors are not judged (none is used). Visual and collision
#: geometry, efforts, velocities, damping are never used here (a mirrored mesh's negative scale is no error).
_USED = {("joint", "origin", "xyz"): "length", ("joint", "origin", "rpy"): "angle", ("joint", "axis", "xyz"): "ratio",
         ("joint", "limit", "lower"): None, ("joint", "limit", "upper"): None,
         ("joint", "mimic", "multiplier"): "ratio", ("joint", "mimic", "offset"): None,
         ("inertial", "mass", "value"): "mass", ("inertial", "origin", "xyz"): "length",
         ("inertial", "origin", "rpy"): "angle",
         **{("inertial", "inertia", k): "inertia" for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")}}
#: used numbers that may be infinite: a joint limit of +-inf is no limit (as +-1e16 from SDF converters is)
_UNBOUNDED = {("joint", "limit", "lower"), ("joint", "limit", "upper")}
#: a negative mass [kg] smaller than this is rounding noise (taken as 0)
_MASS_NOISE = 1e-9
_ELASTIC_TYPES = dict(zip(ELASTIC_JOINTS, ("revolute", "revolute", "prismatic"), strict=True))


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
    tree: Any                    # lxml ElementTree
    robot: Any                   # yourdfpy Robot
    joint_elements: dict         # name -> lxml element
    link_elements: dict

    def line(self, name: str, kind: str = "joint") -> int | None:
        el = (self.joint_elements if kind == "joint" else self.link_elements).get(name)
        return None if el is None else el.sourceline

    def error(self, msg: str, name: str | None = None, kind: str = "joint", column: str | None = None):
        return InputError(msg, self.path, None if name is None else self.line(name, kind), column)


#: lxml's refusals that urdfdom (Pinocchio's and ROS's URDF parser, built on TinyXML) reads past, as real robots
#: ship them (pybullet's minitaur, humanoid and differential robots, Drake's UR5e): (the start of lxml's message,
#: what is tolerated). Each is repaired in the bytes without moving a line, and said once as a warning.
_TOLERATED = (("Unsupported version", "an XML declaration with an unknown version (read as 1.0)"),
              ("XML declaration allowed only at the start", "an XML declaration after blank lines (ignored)"),
              ("Extra content at the end of the document", "NUL bytes after the end of the document (ignored)"),
              ("Namespace prefix", "a namespace prefix never declared (declared for reading)"))


def _repaired(data: bytes, message: str) -> bytes | None:
    """``data`` with the fault lxml reported in ``message`` repaired as urdfdom reads past it (:data:`_TOLERATED`),
    lines unmoved; None if it is no such fault."""
    import re
    if message.startswith("Unsupported version"):
        m = re.match(rb"(\s*<\?xml\s+version\s*=\s*[\"'])([^\"']*)", data.lstrip(b"\xef\xbb\xbf"))
        if m:
            start = len(data) - len(data.lstrip(b"\xef\xbb\xbf")) + m.end(1)
            return data[:start] + b"1.0" + data[start + len(m.group(2)):]
    elif message.startswith("XML declaration allowed only at the start"):
        m = re.search(rb"<\?xml[^>]*\?>", data)
        enc = re.search(rb"encoding\s*=\s*[\"']([^\"']*)", m.group(0)) if m else None
        if m and not data[:m.start()].lstrip(b"\xef\xbb\xbf").strip() and \
                (enc is None or enc.group(1).lower() in (b"utf-8", b"utf8", b"us-ascii", b"ascii")):   # (not guessed)
            return data[:m.start()] + b" " * (m.end() - m.start()) + data[m.end():]
    elif message.startswith("Extra content at the end of the document"):
        stripped = data.rstrip(b"\x00\t\r\n ")       # (the tail: NUL bytes and blanks only)
        if b"\x00" in data[len(stripped):]:
            return stripped + b"\n"
    elif message.startswith("Namespace prefix"):
        prefix, root = re.match(r"Namespace prefix ([A-Za-z_][\w.-]*)", message), re.search(rb"<robot(?=[\s>/])", data)
        if prefix and root and prefix.group(1) not in ("xml", "xmlns"):
            decl = f' xmlns:{prefix.group(1)}="urn:aacmm:undeclared:{prefix.group(1)}"'.encode()
            return data[:root.end()] + decl + data[root.end():]
    return None


def _parse_xml(path: Path, data: bytes):
    """The lxml tree of a URDF, parsed safely: no entity resolved, nothing fetched; a DOCTYPE that declares
    entities or names an external DTD is refused (a URDF needs neither, and yourdfpy, which parses the file
    again, would print its parse errors on standard error). What urdfdom reads past (:data:`_TOLERATED`) is
    repaired with a warning; any other XML error is refused at its line and column."""
    from lxml import etree
    tolerated = []
    for _ in range(2 + 4 * len(_TOLERATED)):        # each repair removes one fault; a few prefixes at most
        try:
            tree = etree.parse(io.BytesIO(data), etree.XMLParser(remove_comments=False, resolve_entities=False,
                                                                  no_network=True, load_dtd=False))
            break
        except etree.XMLSyntaxError as exc:
            line, col = exc.position if exc.position else (None, None)
            fixed = _repaired(data, exc.msg)
            if fixed is None or fixed == data or (line, exc.msg) in {(k, m) for k, m, _ in tolerated}:   # no progress
                raise InputError(f"not valid XML: {exc.msg}", path, line,
                                 None if col is None else f"column {col}") from None
            tolerated.append((line, exc.msg, next(what for start, what in _TOLERATED if exc.msg.startswith(start))))
            data = fixed
    else:
        raise InputError("not valid XML: too many faults to read past", path)
    if tolerated:
        said = "; ".join(dict.fromkeys(f"line {line}: {what}" for line, _, what in tolerated))
        log.warning(f"{path} is not strict XML, read as urdfdom (Pinocchio's and ROS's URDF parser) reads it: {said}")
    info = tree.docinfo
    if info.system_url or info.public_id or (info.internalDTD is not None and any(info.internalDTD.iterentities())):
        raise InputError("a <!DOCTYPE> that declares entities or names an external DTD: a URDF needs neither (entities "
                         "could read other files or the network); remove it", path,
                         data[: max(data.find(b"<!DOCTYPE"), 0)].count(b"\n") + 1)
    root = tree.getroot()
    pi = next(root.iter(etree.ProcessingInstruction), None)
    if pi is not None:      # urdfdom (TinyXML) takes it for a misplaced XML declaration and refuses the file
        raise InputError(f"a processing instruction <?{pi.target} ...?> inside <robot>: urdfdom (Pinocchio's and ROS's "
                         "parser) refuses the file; remove it", path, pi.sourceline)
    ns = etree.QName(root).namespace
    if ns is not None and root.prefix is None and "xacro" not in ns:
        # <robot xmlns="...">: urdfdom reads the names as written (Pinocchio takes the file); so do we
        for el in root.iter(f"{{{ns}}}*"):
            el.tag = etree.QName(el).localname
        etree.cleanup_namespaces(tree)
    return tree


def _check_numbers(root, path: Path) -> None:
    """Every numeric attribute holds numbers (count and syntax); those the kinematics use (:data:`_USED`)
    are finite and plausible too."""
    for el in root.iter(*_NUMERIC):
        parent = el.getparent()
        ptag = None if parent is None else parent.tag
        for attr, n in _NUMERIC[el.tag].items():
            text = el.get(attr)
            if text is None:
                continue
            parts = text.split() if text.isascii() else None    # (split() also splits at a no-break space)
            vals = [parse_number(v) for v in parts] if parts is not None and len(parts) == n else None
            used = (ptag, el.tag, attr) in _USED
            if used and vals and None not in vals and (ptag, el.tag, attr) in _UNBOUNDED:
                vals = [0.0 if math.isinf(v) else v for v in vals]      # +-inf: no limit (a NaN stays refused)
            if vals is None or None in vals or (used and not all(map(math.isfinite, vals))):
                raise InputError(f"<{el.tag} {attr}=...> must be {n} finite number{'s' if n > 1 else ''}, "
                                 f"got {text!r}", path, el.sourceline, f"key '{el.tag}.{attr}'")
            quantity = _USED.get((ptag, el.tag, attr)) if used else None
            wrong = implausible(vals, quantity) if quantity else None
            if wrong:
                raise InputError(f"<{el.tag} {attr}=...>: {wrong[1]}", path, el.sourceline, f"key '{el.tag}.{attr}'")


def _drop_shapeless(root, path: Path) -> None:
    """A ``<visual>`` or ``<collision>`` whose ``<geometry>`` holds no shape first (empty, or another element): left
    out with a warning, as urdfdom leaves it out ("Could not parse visual element"; Pinocchio reads the file). The
    kinematics never use it; yourdfpy stopped at it ("list index out of range", "Unknown tag: foo": no line)."""
    for geometry in list(root.iter("geometry")):
        kids = [c for c in geometry if isinstance(c.tag, str)]
        holder = geometry.getparent()
        if (kids and kids[0].tag in ("box", "cylinder", "sphere", "mesh")) or holder is None or \
                holder.tag not in ("visual", "collision") or holder.getparent() is None:
            continue
        what = f"<{kids[0].tag}>" if kids else "nothing"
        log.warning(f"{path}, line {geometry.sourceline}: a <{holder.tag}> whose <geometry> holds {what} where a box, "
                    "cylinder, sphere or mesh is expected: left out, as urdfdom leaves it out")
        holder.getparent().remove(holder)


def _check_not_xacro(root, path: Path) -> None:
    """An InputError at the first trace of an unexpanded xacro file: an element of the xacro namespace
    (``<xacro:macro>``, ``<xacro:include>``) or an attribute holding ``${...}`` or ``$(...)``. Read as a URDF it
    would lose what the macros and includes define, or fail later at a number that is an expression."""
    from lxml import etree
    for el in root.iter(etree.Element):
        if "xacro" in (etree.QName(el).namespace or "") or str(el.tag).startswith("xacro:"):
            raise InputError(f"<{etree.QName(el).localname}> of the xacro namespace: this is a xacro file, not a "
                             "URDF; expand it first (xacro robot.urdf.xacro > robot.urdf)", path, el.sourceline)
        for attr, value in el.attrib.items():
            if "${" in value or "$(" in value:
                raise InputError(f"<{el.tag} {attr}={value!r}>: a xacro expression: this is a xacro file, not a URDF; "
                                 "expand it first (xacro robot.urdf.xacro > robot.urdf)", path, el.sourceline,
                                 f"key '{el.tag}.{attr}'")


def _warn_repeated(el, what: str, tags: tuple, path: Path) -> None:
    """A warning for each of ``tags`` that ``el`` holds more than once: the first is used, as urdfdom uses it."""
    for tag in tags:
        found = el.findall(tag)
        if len(found) > 1:
            log.warning(f"{path}, line {found[1].sourceline}: {what} has {len(found)} <{tag}> elements (lines "
                        f"{', '.join(str(f.sourceline) for f in found)}): the first is used, as urdfdom uses it")


def _check_tree(root, path: Path) -> tuple[dict, dict]:
    """(links, joints) by name, lxml elements; names unique, joint types known, every parent and child
    defined, each link the child of one joint at most."""
    links, joints = {}, {}
    for el in root.findall("link"):
        name = el.get("name")
        if not name:
            raise InputError("a <link> has no name", path, el.sourceline)
        if id_problem(name):        # (&#10; in an attribute): a name goes into frames, parameters and CSV tables
            raise InputError(f"a <link> name {id_problem(name)}", path, el.sourceline, "key 'link.name'")
        if name in links:
            raise InputError(f"link '{name}' is defined twice (first on line {links[name].sourceline})",
                             path, el.sourceline)
        links[name] = el
        _warn_repeated(el, f"link '{name}'", ("inertial",), path)
    children = {}
    for el in root.findall("joint"):
        name, jtype = el.get("name"), el.get("type")
        if not name:
            raise InputError("a <joint> has no name", path, el.sourceline)
        if id_problem(name):
            raise InputError(f"a <joint> name {id_problem(name)}", path, el.sourceline, "key 'joint.name'")
        if name in joints:
            raise InputError(f"joint '{name}' is defined twice (first on line {joints[name].sourceline})",
                             path, el.sourceline)
        if jtype not in _JOINT_TYPES:
            why = (": a ball joint is pybullet's extension, not URDF (urdfdom refuses it too); give it as three "
                   "revolute joints" if jtype == "spherical" else "")
            raise InputError(f"joint '{name}': type must be one of {', '.join(_JOINT_TYPES)}, got {jtype!r}{why}",
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
        _warn_repeated(el, f"joint '{name}'", ("parent", "child", "origin", "axis", "limit", "mimic"), path)
        mimic = el.find("mimic")
        if mimic is not None and not mimic.get("joint"):
            raise InputError(f"joint '{name}': its <mimic> names no joint (joint=\"...\", the joint it follows)", path,
                             mimic.sourceline, "key 'mimic.joint'")
        if jtype in ("revolute", "prismatic") and el.find("limit") is None:
            raise InputError(f"joint '{name}' ({jtype}) has no <limit>: the URDF format requires one on a {jtype} "
                             "joint (urdfdom, Pinocchio's and ROS's parser, refuses the file too); add <limit "
                             "lower=... upper=... effort=... velocity=...>" + (", or make it type=\"continuous\" if "
                             "it turns without end" if jtype == "revolute" else ""), path, el.sourceline)
        joints[name] = el
    _check_no_loop(joints, path)
    roots = [name for name in links if name not in children]
    if len(roots) > 1:
        first, other = links[roots[0]], links[roots[1]]
        raise InputError(f"two root links, '{roots[0]}' (line {first.sourceline}) and '{roots[1]}' (line "
                         f"{other.sourceline}): a link no joint leads to is a root, and a URDF is one tree (urdfdom, "
                         "Pinocchio's and ROS's parser, refuses the file too); join it to the tree with a joint, or "
                         "remove it", path, other.sourceline)
    return links, joints


def _check_no_loop(joints: dict, path: Path) -> None:
    """An InputError at a joint of any loop of the tree (a joint whose child is its own parent, or a ring of joints
    anywhere, not only on the chain used: urdfdom refuses such a file, and a calibrated URDF would carry it on)."""
    parent = {el.find("child").get("link"): (el.find("parent").get("link"), el) for el in joints.values()}
    done: set = set()
    for start in parent:
        seen: set = set()
        link = start
        while link in parent and link not in done:
            if link in seen:
                el = parent[link][1]
                raise InputError(f"the joints form a loop through link '{link}' (a URDF is a tree)", path,
                                 el.sourceline, f"key 'joint.{el.get('name')}'")
            seen.add(link)
            link = parent[link][0]
        done |= seen


def _read_urdf(path: str | Path) -> _Urdf:
    """Read and check a URDF; every problem is an InputError naming the file and the line. Visual and
    collision content (meshes, their scales and files) is not checked: the kinematics never use it."""
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
    _check_not_xacro(root, path)         # (before the name: a xacro file of macros has none)
    if not root.get("name"):
        raise InputError("<robot> has no name", path, root.sourceline)
    if id_problem(root.get("name")):    # the arm's name: in every file name, model file, URDF and report (the rule of
        raise InputError(f"the <robot> name {id_problem(root.get('name'))}", path, root.sourceline,  # a DH table's)
                         "key 'robot.name'")
    _check_numbers(root, path)
    links, joints = _check_tree(root, path)
    _drop_shapeless(root, path)
    try:
        from lxml import etree
        model = yourdfpy.URDF.load(io.BytesIO(etree.tostring(tree)), build_scene_graph=False, load_meshes=False,
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

    ``moving``: the revolute, continuous and prismatic joints, each with ``prefix`` = the product of the
    fixed (or held) joints' origins between the previous moving frame and it, and its :class:`Mimic` (None
    for a joint read by its own encoder); ``tool_prefix``: the same from the last moving frame to the tip
    joint's parent; ``tip_joint``: the joint whose child is the tip. ``hinge``: T_last_hinge of the
    project's elastic probe joints, None without them.
    """
    moving: list            # (joint, prefix 4x4, Mimic | None)
    tool_prefix: np.ndarray | None     # None: the tip joint moves (no fixed tool frame to rewrite)
    tip_joint: Any                # yourdfpy Joint
    T_last_tip: np.ndarray
    hinge: np.ndarray | None
    base: str = ""          # the link the chain starts at (its frame is the arm's base frame)
    held: dict = field(default_factory=dict)   # joint name -> the value it is held at [rad] or [m]


def _kind(jtype: str) -> str:
    return "prismatic" if jtype == "prismatic" else "revolute"


def _mimic(u: _Urdf, j) -> Mimic | None:
    """The URDF ``<mimic>`` of joint ``j`` resolved to a joint read by an encoder (a mimic of a mimic: the
    multipliers and offsets composed), or an error naming the joint."""
    if j.mimic is None or j.type == "fixed":
        return None
    by_name = {k.name: k for k in u.robot.joints}
    mult = 1.0 if j.mimic.multiplier is None else float(j.mimic.multiplier)
    off = 0.0 if j.mimic.offset is None else float(j.mimic.offset)
    name, seen = j.mimic.joint, {j.name}
    while True:
        master = by_name.get(name)
        if master is None:
            raise u.error(f"joint '{j.name}' mimics '{name}', which the URDF does not define", j.name)
        if master.name in seen:
            raise u.error(f"joint '{j.name}': its <mimic> joints form a loop through '{name}'", j.name)
        if master.type not in ("revolute", "continuous", "prismatic"):
            raise u.error(f"joint '{j.name}' mimics the {master.type} joint '{name}': a mimic follows a moving "
                          "joint", j.name)
        if _kind(master.type) != _kind(j.type):
            raise u.error(f"joint '{j.name}' ({_kind(j.type)}) mimics '{name}' ({_kind(master.type)}): the "
                          "toolkit follows a joint of the same kind only", j.name)
        if master.mimic is None:
            return Mimic(name, mult, off)
        seen.add(name)
        m2 = 1.0 if master.mimic.multiplier is None else float(master.mimic.multiplier)
        o2 = 0.0 if master.mimic.offset is None else float(master.mimic.offset)
        mult, off, name = mult * m2, mult * o2 + off, master.mimic.joint


def _held(j, value: float) -> np.ndarray:
    """T_parent_child of joint ``j`` held at ``value`` [rad] or [m]: its origin times its motion."""
    from .jacobian import elementary_motion
    axis = np.asarray(j.axis if j.axis is not None else (1.0, 0.0, 0.0), dtype=float)
    axis = axis / np.linalg.norm(axis)
    return _T(j.origin) @ elementary_motion("T" if j.type == "prismatic" else "R", tuple(axis), value)


@dataclass
class _Turned:
    """A URDF joint walked from its child to its parent, for a chain whose base frame lies below another
    branch of the tree (a humanoid's foot, the hand on a table). ``T_parent_child(q) = T_origin M(axis, q)``
    walked backwards is ``M(axis, q)^-1 T_origin^-1 = M(-axis, q) T_origin^-1``: a moving joint at the child's
    frame about the opposite axis (same encoder value, limits and mimic), then a fixed joint with the inverse
    origin. The attributes are those of yourdfpy's Joint that the chain reads."""
    name: str
    type: str
    parent: str
    child: str
    origin: np.ndarray
    axis: Any = None
    mimic: Any = None
    limit: Any = None


def _hung_from(u: _Urdf, base_frame: str | None, tip_frame: str) -> _Urdf:
    """``u`` with its tree hung from ``base_frame`` when that link is not on the way from the root to
    ``tip_frame`` (else ``u`` itself): every joint between the root and ``base_frame`` is turned
    (:class:`_Turned`), so the chain base -> tip, the masses each joint carries and the links each row moves
    follow from the same tree walk as for a chain from the root. A robot standing on one foot: the masses
    are then those it carries over that foot."""
    by_child = {j.child: j for j in u.robot.joints}
    if base_frame is None or base_frame not in u.link_elements:
        return u
    link, up = tip_frame, set()
    while link in by_child and link not in up:
        up.add(link)
        link = by_child[link].parent
    if base_frame in up or base_frame == link:
        return u
    path, link = [], base_frame
    while link in by_child and len(path) <= len(by_child):
        path.append(by_child[link])
        link = by_child[link].parent
    turned = {j.name for j in path}
    joints = [j for j in u.robot.joints if j.name not in turned]
    for j in path:
        back = np.linalg.inv(_T(j.origin))
        if j.type == "fixed":
            joints.append(_Turned(j.name, "fixed", j.child, j.parent, back))
            continue
        axis = np.asarray(j.axis if j.axis is not None else (1.0, 0.0, 0.0), dtype=float)
        mid = f"{j.child}~{j.name}"
        joints.append(_Turned(j.name, j.type, j.child, mid, np.eye(4), -axis, j.mimic, j.limit))
        joints.append(_Turned(f"{j.name}~origin", "fixed", mid, j.parent, back))
    log.debug(f"{u.path}: the chain starts at '{base_frame}', below the root: {len(path)} joints walked backwards")
    return replace(u, robot=SimpleNamespace(name=u.robot.name, joints=joints, links=u.robot.links))


def _walk_to_root(u: _Urdf, tip_frame: str, base_frame: str | None = None) -> list:
    """The joints from the root (or from ``base_frame``, a link on the way) to ``tip_frame``, in order."""
    by_child = {j.child: j for j in u.robot.joints}
    chain, link, seen = [], tip_frame, set()
    while link in by_child and link != base_frame:
        if link in seen:
            raise u.error(f"the joints form a loop through link '{link}'", by_child[link].name)
        seen.add(link)
        chain.append(by_child[link])
        link = by_child[link].parent
    chain.reverse()
    return chain


def _limits(u: _Urdf, j) -> tuple[float, float] | None:
    """The (lower, upper) limits [rad or m] of a URDF joint, or None: a continuous joint, no <limit>, a joint declared
    locked (lower = upper: its value still comes from the data), or limits beyond plausible ("unlimited" as URDFs
    made from SDF write it, +-1e16: no limit)."""
    if j.type == "continuous" or j.limit is None or j.limit.lower is None or j.limit.upper is None:
        return None
    lower, upper = float(j.limit.lower), float(j.limit.upper)
    if math.isinf(lower) or math.isinf(upper):       # one side unbounded: the joint has no limits to hold to
        return None
    if lower > upper:
        raise u.error(f"joint '{j.name}': lower limit {lower:g} is above upper limit {upper:g}", j.name)
    if lower == upper or implausible([lower, upper], "length" if j.type == "prismatic" else "angle"):
        return None
    return lower, upper


def _held_values(u: _Urdf, chain: list, tip_frame: str, hold: dict | None, elastic: set) -> dict:
    """``--hold-joint``: joint name -> value in the user's unit (deg, or mm for a prismatic joint), checked
    to be a moving joint of the chain (not one of the probe's ``elastic`` joints, the toolkit's model of its
    compliance), as [rad] or [m]. A value beyond the joint's declared limits is warned and used, as an encoder
    angle beyond them is (docs/guarantees.md, section 3): the limits are the description's claim, the held value
    the user's statement of where the joint is."""
    on_chain = {j.name: j for j in chain}
    out = {}
    for name, value in (hold or {}).items():
        j = on_chain.get(name)
        moving = [k.name for k in chain if k.type in ("revolute", "continuous", "prismatic") and k.name not in elastic]
        if j is None or j.type not in ("revolute", "continuous", "prismatic") or name in elastic:
            what = ("the probe's elastic joint (its compliance, modelled from the force)" if name in elastic else
                    f"a {j.type} joint" if j is not None else "not a joint of the chain")
            raise InputError(f"joint '{name}' is {what}{did_you_mean(name, moving) if j is None else ''}: "
                             f"--hold-joint names a moving joint on the chain to '{tip_frame}' "
                             f"(they are: {', '.join(moving)})", u.path, None, "key '--hold-joint'")
        out[name] = value * 1e-3 if j.type == "prismatic" else np.radians(value)
        limits = _limits(u, j)
        if limits is not None and not limits[0] - 1e-12 <= out[name] <= limits[1] + 1e-12:
            f, unit = (1e3, "mm") if j.type == "prismatic" else (180.0 / np.pi, "deg")
            log.warning(f"{u.path}: --hold-joint: joint '{name}' held at {value:g} {unit}, beyond its limits "
                        f"[{limits[0] * f:.6g}, {limits[1] * f:.6g}] {unit} (the URDF's <limit>): used as given, as "
                        "an encoder angle beyond its limits is; check the value or the limits")
    return out


def tip_candidates(u: _Urdf, most: int = 8) -> str:
    """The links a chain ends at (no joint below them), those behind the most moving joints first, as a phrase
    for messages: ``"the chains end at tool0 (6 moving joints), ..."``, or that there is none."""
    by_child = {j.child: j for j in u.robot.joints}
    parents = {j.parent for j in u.robot.joints}
    depth: dict[str, int] = {}          # link -> moving joints above it (each link's walk stops at a known one)
    for start in u.link_elements:
        path, link = [], start
        while link in by_child and link not in depth and link not in path:     # (a loop ends the walk)
            path.append(link)
            link = by_child[link].parent
        n = depth.get(link, 0)
        for link in reversed(path):
            n += by_child[link].type in ("revolute", "continuous", "prismatic")
            depth[link] = n
    counts = sorted((-depth.get(leaf, 0), leaf) for leaf in u.link_elements if leaf not in parents and depth.get(leaf))
    if not counts:
        return "no link of this URDF hangs from a moving joint"
    shown = ", ".join(f"{leaf if len(leaf) <= 60 else leaf[:55] + '...'} ({-n} moving joint{'s' if n < -1 else ''})"
                      for n, leaf in counts[:most])          # (a name may be 100 000 characters long: cut)
    return "the chains end at " + shown + (f", and {len(counts) - most} more" if len(counts) > most else "")


def _frame_problem(u: _Urdf, frame: str, option: str) -> InputError:
    """The error for a ``--tip-frame`` or ``--base-frame`` that names no link: a joint's name says which link
    is its child; anything else, the nearest link's name and the links chains end at."""
    if frame in u.joint_elements:
        child = u.joint_elements[frame].find("child").get("link")
        return InputError(f"'{frame}' is a joint, not a link: {option} names a link (this joint's child link is "
                          f"'{child}')", u.path, u.line(frame), f"key '{option}'")
    return InputError(f"no link named '{frame}'{did_you_mean(frame, u.link_elements)}; {tip_candidates(u)} "
                      f"({len(u.link_elements)} links in all)", u.path, None, f"key '{option}'")


def _chain(u: _Urdf, tip_frame: str, base_frame: str | None = None, hold: dict | None = None) -> _Chain:
    for frame, option in ((tip_frame, "--tip-frame"), (base_frame, "--base-frame")):
        if frame is not None and frame not in u.link_elements:
            raise _frame_problem(u, frame, option)
    chain = _walk_to_root(u, tip_frame, base_frame)
    if not chain and base_frame is None:
        raise InputError(f"link '{tip_frame}' hangs from no joint: it is a root of the URDF, so no chain reaches it; "
                         f"the tip frame is a link a chain reaches: {tip_candidates(u)}", u.path,
                         u.line(tip_frame, "link"), "key '--tip-frame'")
    base = chain[0].parent if chain else tip_frame
    if base_frame is not None and base != base_frame:
        ancestors = [j.parent for j in chain]
        raise InputError(f"link '{base_frame}' is not on the chain from the root to '{tip_frame}' (its links: "
                         f"{', '.join(ancestors + [tip_frame])}): the base frame is a link the chain passes "
                         "through", u.path, None, "key '--base-frame'")
    elastic = [j for j in chain if _ELASTIC_TYPES.get(j.name) == j.type]
    held = {j.name for j in elastic} if len(elastic) == len(ELASTIC_JOINTS) else set()
    held_at = _held_values(u, chain, tip_frame, hold, held)
    moving, pending, tool_prefix, hinge = [], np.eye(4), np.eye(4), None
    for j in chain:
        if j.child == tip_frame:
            tool_prefix = pending.copy()
        if j.name == ELASTIC_JOINTS[0] and held:
            hinge = pending @ _T(j.origin)
        if j.type == "fixed" or j.name in held:
            pending = pending @ _T(j.origin)
            continue
        if j.type not in ("revolute", "continuous", "prismatic") and j.child == tip_frame:
            raise u.error(f"the tip frame '{tip_frame}' hangs from the {j.type} joint '{j.name}', which moves it "
                          "freely: no chain of joints gives its place; the tip frame is a link that joints place",
                          j.name)
        if j.type not in ("revolute", "continuous", "prismatic"):
            raise u.error(f"joint '{j.name}' on the chain to '{tip_frame}' is {j.type}: the toolkit models "
                          "revolute, continuous and prismatic joints (a floating or planar joint is a base the "
                          f"URDF moves freely: start the chain after it, --base-frame {j.child})", j.name)
        if j.name in held_at:                                       # --hold-joint: a fixed joint
            pending = pending @ _held(j, held_at[j.name])
            continue
        mimic = _mimic(u, j)
        if mimic is not None and mimic.multiplier == 0.0:         # held at its offset: a fixed joint
            pending = pending @ _held(j, mimic.offset)
            continue
        moving.append((j, pending, mimic))
        pending = np.eye(4)
        hinge = None
    if not moving and held_at:
        raise InputError(f"--hold-joint holds every moving joint between '{base}' and '{tip_frame}' "
                         f"({', '.join(held_at)}): the chain needs one the points give", u.path, None,
                         "key '--hold-joint'")
    if not moving:
        raise InputError(f"no revolute, continuous or prismatic joint between '{base}' and '{tip_frame}'", u.path,
                         None, "key '--tip-frame'")
    tip_joint = chain[-1]
    if tip_joint.type != "fixed" and tip_joint.name not in held and tip_joint.name not in held_at:
        tool_prefix = None
    return _Chain(moving, tool_prefix, tip_joint, pending, hinge, base, held_at)


# ---------------------------------------------------------------------------------------------
# masses

def _inertials(u: _Urdf, masses: dict | None) -> dict[str, tuple[float, np.ndarray]]:
    """Link -> (mass [kg], centre of mass [m] in the link frame): the URDF's, replaced by ``masses``
    (unchecked: :func:`_fold_masses` checks those it uses)."""
    out = {}
    for link in u.robot.links:
        inert = link.inertial
        if inert is not None and inert.mass:
            out[link.name] = (float(inert.mass), _T(inert.origin)[:3, 3].copy())
    for name, m in (masses or {}).items():
        out[name] = (m.mass, np.asarray(m.com, dtype=float))
    return out


def _checked_mass(u: _Urdf, link: str, mass: float, com: np.ndarray) -> float:
    """A link's ``<inertial>`` as the chain uses it: a finite, plausible mass, not negative beyond rounding
    noise (a negative rounding residue is 0), and a finite, plausible centre of mass; an error names the
    element's line."""
    inertial = u.link_elements[link].find("inertial")
    for tag, attr, vals, quantity in (("mass", "value", [mass], "mass"), ("origin", "xyz", list(com), "length")):
        el = inertial.find(tag) if inertial is not None else None
        line = (el if el is not None else u.link_elements[link]).sourceline
        if not all(map(math.isfinite, vals)):
            raise InputError(f"<{tag} {attr}=...> of link '{link}' must be finite numbers, got "
                             f"{el.get(attr) if el is not None else vals!r}", u.path, line, f"key '{tag}.{attr}'")
        wrong = implausible(vals, quantity)
        if wrong:
            raise InputError(f"<{tag} {attr}=...> of link '{link}': {wrong[1]}", u.path, line, f"key '{tag}.{attr}'")
    if mass < -_MASS_NOISE:
        el = inertial.find("mass")
        raise InputError(f"<mass value=...> of link '{link}' must not be negative, got {el.get('value')!r}", u.path,
                         el.sourceline, "key 'mass.value'")
    return max(mass, 0.0)


def _warn_negative_masses(u: _Urdf, used: set) -> None:
    """One warning for the negative masses (beyond rounding) of links the chain does not use (``used``: the links
    whose masses it folds; a negative one of those is refused): no body has one, and a calibrated URDF keeps it.
    Inertia tensors are not judged: the toolkit uses none, and 21 of the 55 URDFs of example-robot-data 4.1 hold
    placeholder tensors that no body has (one moment larger than the other two together: 3e-6 0 0)."""
    bad = [(name, mass) for name, link in u.link_elements.items() if name not in used
           and (mass := link.find("inertial/mass")) is not None and float(mass.get("value", "0")) < -_MASS_NOISE]
    if bad:
        shown = "; ".join(f"link '{name}', {m.get('value')} kg (line {m.sourceline})" for name, m in bad[:3])
        log.warning(f"{u.path}, line {bad[0][1].sourceline}: a negative mass, which no body has, on {len(bad)} link(s) "
                    f"off the chain: {shown}{'; ...' if len(bad) > 3 else ''}; not used, but a calibrated URDF keeps "
                    "it as it was")


def _fold_masses(u: _Urdf, ch: _Chain, masses: dict | None) -> list[tuple[float, tuple]]:
    """(mass, com in the joint's child frame) of each moving joint: its child link and everything
    hanging from it (fixed joints, side branches at zero) up to the next moving joint."""
    inert = _inertials(u, masses)
    moving_names = {j.name for j, _, _ in ch.moving}
    kids: dict[str, list] = {}
    for j in u.robot.joints:
        kids.setdefault(j.parent, []).append(j)
    out, used = [], set()
    for j, _, _ in ch.moving:
        total, first = 0.0, np.zeros(3)
        stack = [(j.child, np.eye(4))]
        while stack:
            link, T = stack.pop()
            used.add(link)
            if link in inert:
                m, c = inert[link]
                if link not in (masses or {}):          # a masses file's values are checked when it is read
                    m = _checked_mass(u, link, m, c)
                total += m
                first += m * (T[:3, :3] @ c + T[:3, 3])
            for k in kids.get(link, ()):
                if k.name not in moving_names:
                    stack.append((k.child, T @ (_held(k, ch.held[k.name]) if k.name in ch.held else _T(k.origin))))
        com = first / total if total > 0 else np.zeros(3)
        out.append((total, tuple(float(v) for v in com)))
    _warn_negative_masses(u, used)
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
        if vals["mass"] < 0:        # (its plausible bound, PLAUSIBLE_SI["mass"], is the reader's)
            raise r.error(f"mass must not be negative, got {vals['mass']:g} kg", "link", i, "mass_kg")
        if any(abs(vals.get(k, 0.0)) > 100.0 for k in ("com_x", "com_y", "com_z")):
            raise r.error("a centre of mass more than 100 m from its link frame is not plausible", "link", i)
        out[name] = LinkMass(vals["mass"], tuple(vals.get(k, 0.0) for k in ("com_x", "com_y", "com_z")),
                             (str(path), r.lines.get(("link", i, "name"), r.lines.get(("link", i)))))
    return out


# ---------------------------------------------------------------------------------------------
# the description

def _ball_diameter(u: _Urdf, tip_frame: str) -> float | None:
    """Diameter [m] of a sphere centred on the tip link (visual or collision), if there is one: the ball."""
    for g in u.link_elements[tip_frame]:
        if not isinstance(g.tag, str) or g.tag not in ("visual", "collision"):
            continue
        sphere, origin = g.find("geometry/sphere"), g.find("origin")
        xyz = [parse_number(v) for v in (origin.get("xyz", "0 0 0") if origin is not None else "0 0 0").split()]
        if sphere is None or sphere.get("radius") is None or not all(v is not None and abs(v) <= 1e-9 for v in xyz):
            continue
        radius = parse_number(sphere.get("radius"))
        if radius == 0.0:           # a point (a foot's contact sphere of radius 0, as pybullet's laikago): no ball
            continue
        wrong = None if radius is None or not math.isfinite(radius) else implausible(radius, "length")
        if radius is None or not math.isfinite(radius) or wrong or radius <= 0:
            why = ("must not be negative" if radius is not None and radius < 0
                   else wrong[1] if wrong else "must be a finite number")
            raise InputError(f"<sphere radius=...> of the tip link '{tip_frame}' (the probe ball) {why}, got "
                             f"{sphere.get('radius')!r}", u.path, sphere.sourceline, "key 'sphere.radius'")
        return 2.0 * radius
    return None


def _row(u: _Urdf, j, prefix: np.ndarray, mimic: Mimic | None, mass: float, com: tuple) -> JointRow:
    """A moving joint of the chain as a row: its origin after the fixed joints folded before it (``prefix``),
    its unit axis, kind, limits ([rad] or [m]; none for a continuous joint, a locked one, or limits beyond the
    plausible range of an angle or a length) and mimic."""
    T = prefix @ _T(j.origin)
    axis = np.asarray(j.axis if j.axis is not None else (1.0, 0.0, 0.0), dtype=float)
    if np.linalg.norm(axis) < 1e-9:
        raise u.error(f"joint '{j.name}' has a zero axis", j.name)
    lower, upper = _limits(u, j) or (None, None)
    roll, pitch, yaw = _rpy(T)
    return JointRow(name=j.name, origin=(float(T[0, 3]), float(T[1, 3]), float(T[2, 3]), roll, pitch, yaw),
                    axis=tuple(float(v) for v in axis / np.linalg.norm(axis)), lower=lower, upper=upper,
                    mass=mass, com=com, kind=_kind(j.type), mimic=mimic)


def _probe_of(u: _Urdf, ch: _Chain, tip_frame: str, probe: dict | None) -> Probe:
    """The probe of the tip frame: its pose in the last joint frame; the stylus hinge of the project's
    elastic joints, else where the stylus line passes closest to the last joint origin, else (a tool
    pointing back past or across that origin) |p| behind the ball; no stylus (rigid, compliances 0) for a
    tip at the last joint's origin (a flange, a wrist link, a tracker marker on it)."""
    T_tip = ch.T_last_tip
    p_last = tuple(float(v) for v in T_tip[:3, 3])
    rpy = tuple(float(v) + 0.0 for v in _rpy(T_tip))
    if np.allclose(T_tip[:3, :3], np.eye(3), atol=0, rtol=0):
        rpy = (0.0, 0.0, 0.0)
    if ch.hinge is not None:
        lever = float((T_tip[:3, 3] - ch.hinge[:3, 3]) @ T_tip[:3, 2])
    else:
        lever = default_lever(p_last, T_tip[:3, :3])
    pr = dict(PAPER_PROBE)
    ball = _ball_diameter(u, tip_frame)
    if ball is not None:
        pr["ball_diameter"] = ball
    if lever == 0.0:
        pr.update(bending_compliance_x=0.0, bending_compliance_y=0.0, axial_compliance=0.0)
    pr.update(probe or {})
    pro = Probe(p_last=p_last, rpy=rpy, lever=lever, **pr)
    if lever == 0.0 and pro.compliance.any():
        raise InputError(f"the tip frame '{tip_frame}' lies at the origin of the last joint frame: a tip without a "
                         "stylus, which no force bends; a compliant probe needs its ball beyond the last joint "
                         "(give a tip frame there, or zero compliances)", u.path, u.line(ch.tip_joint.name),
                         "key '--tip-frame'")
    if lever != 0.0 and not pro.stylus_length >= MIN_STYLUS:
        raise InputError(f"the tip frame '{tip_frame}' lies at the stylus hinge of the probe's elastic joints: a "
                         "probe needs its ball beyond its hinge", u.path, u.line(ch.tip_joint.name),
                         "key '--tip-frame'")
    return pro


# ---------------------------------------------------------------------------------------------
# the user's visuals, for the viewer

def _link_frames(u: _Urdf, ch: _Chain) -> dict[str, tuple[int, np.ndarray]]:
    """link -> (row, T_row_link): the links that move with each chain row (from its joint's child up to
    the next moving joint of the chain, side branches at zero) and, as row -1, those before the first."""
    moving = {j.name: i for i, (j, _, _) in enumerate(ch.moving)}
    kids: dict[str, list] = {}
    for j in u.robot.joints:
        kids.setdefault(j.parent, []).append(j)
    stack = [(ch.base, -1, np.eye(4))] + [(j.child, moving[j.name], np.eye(4)) for j, _, _ in ch.moving]
    out = {}
    while stack:
        link, row, T = stack.pop()
        out[link] = (row, T)
        for k in kids.get(link, ()):
            if k.name not in moving:
                stack.append((k.child, row, T @ _T(k.origin)))
    return out


def _package_roots(pkg: str, here: Path) -> list[Path]:
    """Where ``package://pkg/`` may live, in ROS's order of preference after the URDF's own tree: a folder ``pkg``
    beside the URDF or above it (or the folder holding the URDF, if named ``pkg``), then each folder of
    ``ROS_PACKAGE_PATH`` (ROS 1: the package itself or a folder holding it) and ``share/pkg`` under each prefix of
    ``AMENT_PREFIX_PATH`` (ROS 2), as a sourced ROS workspace sets them."""
    import os
    roots = [d / pkg for d in (here, *here.parents)] + [d for d in (here, *here.parents) if d.name == pkg]
    for entry in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep):
        if entry:
            d = Path(entry).expanduser()
            roots += [d] if d.name == pkg else [d / pkg]
    for entry in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
        if entry:
            roots.append(Path(entry).expanduser() / "share" / pkg)
    return roots


def _mesh_file(u: _Urdf, name: str) -> Path | None:
    """The file of a ``<mesh filename>``: ``package://pkg/...`` found where :func:`_package_roots` says,
    ``file://`` and absolute paths as they are, others relative to the URDF; None if absent."""
    if name.startswith("file://"):
        name = name[len("file://"):]
    if name.startswith("package://"):
        pkg, _, rest = name[len("package://"):].partition("/")
        return next((resolved(c) for c in (r / rest for r in _package_roots(pkg, beside(u.path))) if c.is_file()),
                    None)
    cand = resolved(named_in(u.path, name))
    return cand if cand.is_file() else None


def _rgba_of(u: _Urdf, visual) -> tuple | None:
    mat = visual.find("material")
    if mat is None:
        return None
    color = mat.find("color")
    if color is None and mat.get("name"):
        named = u.tree.getroot().find(f"material[@name='{mat.get('name')}']") if "'" not in mat.get("name") else None
        color = None if named is None else named.find("color")
    vals = None if color is None else [parse_number(v) for v in color.get("rgba", "").split()]
    return tuple(vals) if vals and len(vals) == 4 and all(v is not None and 0 <= v <= 1 for v in vals) else None


def _visuals(u: _Urdf, ch: _Chain) -> tuple[tuple[Visual, ...], tuple[str, ...]]:
    """(visuals, missing): the user's ``<visual>`` elements on the links the chain moves (and its base), each in
    its row's link frame, for the viewer; and the file names of the meshes not found (:func:`_mesh_file`), which,
    like a visual with numbers that are not finite, are left out (the kinematics never use them)."""
    from copy import deepcopy

    from lxml import etree

    from .urdf import origin_matrix
    out, missing = [], []
    for link, (row, T) in _link_frames(u, ch).items():
        if link not in u.link_elements:          # the frame between a turned joint's motion and its origin
            continue
        for vis in u.link_elements[link].findall("visual"):
            geom, origin = vis.find("geometry"), vis.find("origin")
            shape = None if geom is None else next((k for k in geom if isinstance(k.tag, str)), None)
            if shape is None or shape.tag not in ("box", "cylinder", "sphere", "mesh"):
                continue
            nums = [parse_number(v) for v in ((origin.get("xyz", "0 0 0") + " " + origin.get("rpy", "0 0 0"))
                                               if origin is not None else "0 0 0 0 0 0").split()]
            if len(nums) != 6 or not all(v is not None and math.isfinite(v) for v in nums):
                continue
            shape = deepcopy(shape)
            if shape.tag == "mesh":
                found = _mesh_file(u, shape.get("filename", ""))
                if found is None:
                    missing.append(shape.get("filename", ""))
                    continue
                shape.set("filename", str(found))
            pose = T @ origin_matrix(nums)
            out.append(Visual(row, tuple(map(tuple, pose.tolist())),
                              f"<geometry>{etree.tostring(shape, encoding='unicode').strip()}</geometry>",
                              _rgba_of(u, vis)))
    if missing:
        log.debug(f"{u.path}: {len(missing)} mesh file(s) not found: the viewer draws the arm without them")
    return tuple(out), tuple(dict.fromkeys(missing))


def description_from_urdf(path: str | Path, tip_frame: str, probe: dict | None = None,
                          name: str | None = None, masses: dict | None = None,
                          base_frame: str | None = None, hold: dict | None = None) -> ArmDescription:
    """Read the serial chain root -> ``tip_frame`` (a link name) of a URDF as a description.

    Args:
        path: URDF file.
        tip_frame: the link at the ball centre (or the tool point: a flange, a marker); its orientation is
            the probe frame's (z along the stylus, towards the ball). At the origin of the last moving joint
            it is a tip without a stylus (rigid: compliances 0).
        base_frame: a link on the way from the root to ``tip_frame`` where the chain starts instead (its frame
            is then the arm's base frame; the joints before it are not the arm's).
        hold: joint name -> value [deg, or mm for a prismatic joint]: moving joints of the chain the points do
            not give (a tool changer's joint always at rest), held there as fixed joints.
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
    u = _hung_from(u, base_frame, tip_frame)
    ch = _chain(u, tip_frame, base_frame, hold)
    rows = [_row(u, j, prefix, mimic, mass, com)
            for (j, prefix, mimic), (mass, com) in zip(ch.moving, _fold_masses(u, ch, masses), strict=True)]
    visuals, missing = _visuals(u, ch)
    return ArmDescription(name=name or u.robot.name or Path(path).stem, convention="urdf", joints=tuple(rows),
                          probe=_probe_of(u, ch, tip_frame, probe), source=str(path), tip_frame=tip_frame,
                          visuals=visuals, missing_meshes=missing, base_frame=base_frame,
                          held_joints=tuple(sorted((hold or {}).items())))


#: the names a URDF goes by: a xacro file is sent to the URDF reader too, which says to expand it
URDF_SUFFIXES = (".urdf", ".xacro", ".xml")


def is_urdf(path: str | Path) -> bool:
    """Whether ``path`` is read as a URDF: named ``.urdf``, ``.xacro`` or ``.xml`` (any case), or a regular file of
    another name whose first character past blanks (and a UTF-8 byte order mark) is ``<``: XML, which a description
    TOML never is (a robot's description as its vendor names it, ``robot.URDF``, ``model``)."""
    path = Path(path)
    if path.suffix.lower() in URDF_SUFFIXES:
        return True
    try:
        if not path.is_file():
            return False
        with open(path, "rb") as fh:
            head = fh.read(4096)
    except OSError:
        return False
    return head.lstrip(b"\xef\xbb\xbf").lstrip().startswith(b"<")


def load_arm(path: str | Path, tip_frame: str | None = None, probe: dict | None = None,
             masses: str | Path | None = None, base_frame: str | None = None,
             hold: dict | None = None) -> ArmDescription:
    """An arm from a description TOML, a shipped arm's name (``aacmm7``) or, with ``tip_frame``, a URDF
    file; ``masses``: a masses file (:func:`load_masses`) for a URDF arm; ``base_frame``: for a URDF, the link
    the chain starts at (default its root)."""
    path = arm_path(path)
    if is_urdf(path):
        if not tip_frame:        # (the file read first: a xacro file says so, a good one lists its chains' ends)
            raise InputError("an arm given as a URDF needs --tip-frame (the link at the ball centre, or the tool "
                             f"point); {tip_candidates(_read_urdf(path))}", path)
        return description_from_urdf(path, tip_frame, probe, masses=None if masses is None else load_masses(masses),
                                     base_frame=base_frame, hold=hold)
    if hold:
        raise InputError("--hold-joint is for an arm given as a URDF (a joint of its chain); this arm is a TOML "
                         "file", path)
    if base_frame is not None:
        raise InputError("--base-frame is for an arm given as a URDF (where its chain starts); this arm is a TOML "
                         "file", path)
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


def _add_tool_frame(u: _Urdf, tip: str, probe: Probe) -> str:
    """A fixed child link of the tip link at the calibrated tool point (a tip that hangs from a moving
    joint, a flange, has no fixed joint whose origin could take it): ``<tip>_calibrated``; its name."""
    from lxml import etree
    root = u.tree.getroot()
    name = f"{tip}_calibrated"
    while name in u.link_elements or name + "_joint" in u.joint_elements:
        name += "_"
    root.append(etree.Comment(f" aacmm calibrate: the calibrated tool point of '{_comment_safe(tip)}', link "
                              f"'{_comment_safe(name)}': give it as the tip frame "))
    etree.SubElement(root, "link", name=name)
    joint = etree.SubElement(root, "joint", name=name + "_joint", type="fixed")
    etree.SubElement(joint, "parent", link=tip)
    etree.SubElement(joint, "child", link=name)
    T = np.eye(4)
    T[:3, 3] = probe.p_last
    if probe.rotation is not None:
        T[:3, :3] = probe.rotation
    _set_origin(joint, T)
    log.info(f"calibrated URDF: the tool point is the new link '{name}' on '{tip}' (--tip-frame {name})")
    return name


def _comment_safe(text: str) -> str:
    return str(text).replace("--", "- -")


def calibrated_urdf_text(nominal: ArmDescription, calibrated: ArmDescription) -> str:
    """The calibrated arm as a URDF.

    For an arm read from a URDF (``nominal.tip_frame``): the user's own file, with only the origins
    of the chain's moving joints whose row changed and the tip joint's xyz (the tool offset)
    rewritten; names, meshes, inertials, limits, comments, other joints and frames are kept. A tip that
    hangs from a moving joint (a flange) gets a fixed child link at the calibrated tool point,
    ``<tip>_calibrated``. For a description TOML: the generated URDF (:func:`arm_model.urdf.urdf_text`).
    """
    from lxml import etree

    from .urdf import kept_link_names, urdf_text

    if not nominal.tip_frame or not nominal.source or not is_urdf(nominal.source):
        return urdf_text(calibrated)
    u = _read_urdf(nominal.source)
    hung = _hung_from(u, nominal.base_frame, nominal.tip_frame)
    if hung is not u:
        log.info(f"calibrated URDF: the chain runs from '{nominal.base_frame}' against the URDF's tree (joints "
                 "walked backwards), which the file's own origins cannot take: written as the chain's own URDF "
                 f"('{nominal.base_frame}' to '{nominal.tip_frame}')")
        base, tip = kept_link_names(nominal)
        return urdf_text(calibrated, base_link=base, tip_link=tip)
    ch = _chain(u, nominal.tip_frame, nominal.base_frame, dict(nominal.held_joints))
    names = [j.name for j, _, _ in ch.moving]
    if names != [j.name for j in nominal.joints] or names != [j.name for j in calibrated.joints]:
        raise InputError("the URDF's chain no longer matches the arm that was calibrated (was it edited?)",
                         u.path)
    for (j, prefix, _), row_nom, row_cal in zip(ch.moving, nominal.joints, calibrated.joints, strict=True):
        if row_cal.origin == row_nom.origin:
            continue
        T = np.linalg.inv(prefix) @ origin_matrix(row_cal.origin)
        _set_origin(u.joint_elements[j.name], T)
    if calibrated.probe.p_last != nominal.probe.p_last and ch.tool_prefix is None:
        _add_tool_frame(u, nominal.tip_frame, calibrated.probe)
    elif calibrated.probe.p_last != nominal.probe.p_last:
        el = u.joint_elements[ch.tip_joint.name]
        T = _T(ch.tip_joint.origin).copy()
        T[:3, 3] = (np.linalg.inv(ch.tool_prefix) @ np.array([*calibrated.probe.p_last, 1.0]))[:3]
        _set_origin(el, T, xyz_only=True)
    text = etree.tostring(u.tree, encoding="unicode")
    decl = u.tree.docinfo.xml_version
    has_decl = Path(nominal.source).read_bytes().lstrip().startswith(b"<?xml")
    return (f'<?xml version="{decl or "1.0"}"?>\n' if has_decl else "") + text + "\n"
