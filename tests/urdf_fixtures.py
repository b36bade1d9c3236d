"""URDF texts of small serial chains for tests (one writer, so that every test arm has the same shape)."""
from __future__ import annotations


def _xyz(v) -> str:
    return " ".join(repr(float(x)) for x in v)


def serial_urdf(name: str, base: str, joints, tip: str, tip_xyz, masses=None, effort: float = 10.0) -> str:
    """The URDF text of a serial chain: the link ``base``, then revolute joints ``j1`` ... ``jN`` (one a row of
    ``joints``: ``(origin xyz [m], origin rpy [rad], axis, lower [rad], upper [rad])``) to links ``l1`` ... ``lN``,
    then a fixed joint ``<tip>_joint`` at ``tip_xyz`` [m] to the link ``tip``. ``masses``: ``(mass [kg], centre of
    mass xyz [m])`` of each link ``lk`` (an ``<inertial>`` of inertia 0.01 kg m^2 about each axis), or None."""
    links = []
    for k in range(1, len(joints) + 1):
        if masses is None:
            links.append(f'  <link name="l{k}"/>')
        else:
            m, com = masses[k - 1]
            links.append(f'  <link name="l{k}"><inertial><origin xyz="{_xyz(com)}"/><mass value="{m:g}"/>\n'
                         '    <inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>')
    rows = []
    for k, (xyz, rpy, axis, lower, upper) in enumerate(joints, start=1):
        parent = base if k == 1 else f"l{k - 1}"
        rows.append(f'  <joint name="j{k}" type="revolute"><parent link="{parent}"/><child link="l{k}"/>\n'
                    f'    <origin xyz="{_xyz(xyz)}" rpy="{_xyz(rpy)}"/>\n'
                    f'    <axis xyz="{_xyz(axis)}"/><limit lower="{float(lower)!r}" upper="{float(upper)!r}" '
                    f'effort="{effort:g}" velocity="1"/></joint>')
    return "\n".join([
        '<?xml version="1.0"?>', f'<robot name="{name}">', f'  <link name="{base}"/>', *links,
        f'  <link name="{tip}"/>',
        *rows,
        f'  <joint name="{tip}_joint" type="fixed"><parent link="l{len(joints)}"/><child link="{tip}"/>'
        f'<origin xyz="{_xyz(tip_xyz)}"/></joint>',
        "</robot>", ""])
