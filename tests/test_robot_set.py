"""The field's own robot set: every URDF of the ``example-robot-data`` package (4.1.0), read as it ships.

For each URDF Pinocchio builds, every chain from the root to a leaf link with at least 3 moving joints
is read with that leaf as the tip frame, and the tip at random joint values within the limits (by the
Python API and by ``aacmm tip``) is compared with Pinocchio's own placement of that frame in the user's
file: the API to 1e-12 m (and the frame's axes to 1e-12), the command to its file's resolution (1e-6 mm).
The ``<mimic>`` joints are set here by the URDF's formula, written independently of the toolkit, and,
where Pinocchio's own mimic model builds, also through it.

The package is downloaded once (``pip download``, one 96 MB wheel) into a cache outside the repository
(``$XDG_CACHE_HOME/aacmm-toolkit``, default ``~/.cache/aacmm-toolkit``), only its URDFs kept; the tests
skip, saying why, when it cannot be fetched. The sweep is in the slow suite (``make test-slow``), which keeps
``make test`` off the network: ``test_every_robot`` (all of them, one robot of each difficulty checked by name:
:data:`QUICK`), which also checks that the table of docs/robots.md is the one this sweep finds.
"""
from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

from conftest import ROOT

#: one robot of each difficulty the set holds
QUICK = {
    "tiago_description/robots/tiago.urdf": "prismatic torso, a wrist origin 5e-12 rad from gimbal lock",
    "icub_description/robots/icub.urdf": "inertias of -5.4e-20 (rounding noise)",
    "panda_description/urdf/panda.urdf": "prismatic fingers, one mimicking the other off its chain",
    "z1_description/urdf/z1.urdf": "the tip frame at the last joint's origin",
    "talos_data/robots/talos_reduced.urdf": "mirrored meshes, mimic tags on fixed joints",
    "kinova_description/robots/kinova.urdf": "continuous joints",
    "ur_description/urdf/ur3.urdf": "an empty <robot> without a name: Pinocchio refuses it, so does the toolkit",
}
TABLE_START = "<!-- robot-set table: written from tests/test_robot_set.py (test_every_robot checks it) -->"
TABLE_END = "<!-- end of the robot-set table -->"


# ---------------------------------------------------------------------------------------------
# the reference: the user's file in Pinocchio, the mimic formula of the URDF written out here

def _chains(path: Path) -> list[tuple[str, int, set]]:
    """(leaf link, number of moving joints from the root, what its chain holds: "prismatic",
    "continuous", "mimic") of every leaf with at least 3 moving joints."""
    from lxml import etree
    root = etree.parse(str(path)).getroot()
    joints = root.findall("joint")
    by_child = {j.find("child").get("link"): j for j in joints}
    parents = {j.find("parent").get("link") for j in joints}
    out = []
    for link in root.findall("link"):
        leaf, n, kinds = link.get("name"), 0, set()
        if leaf in parents:
            continue
        name = leaf
        while name in by_child:
            j = by_child[name]
            if j.get("type") != "fixed":
                n += 1
                kinds |= {j.get("type")} & {"prismatic", "continuous"}
                kinds |= {"mimic"} if j.find("mimic") is not None else set()
            name = j.find("parent").get("link")
        if n >= 3:
            out.append((leaf, n, kinds))
    return out


def _file_notes(path: Path) -> set:
    """What the file holds that a strict reader once refused: mirrored meshes, negative inertia noise."""
    from lxml import etree
    root = etree.parse(str(path)).getroot()
    notes = set()
    if any(min(map(float, m.get("scale", "1 1 1").split())) < 0 for m in root.iter("mesh")):
        notes.add("mirrored meshes")
    if any(float(i.get(k, "0")) < 0 for i in root.iter("inertia") for k in ("ixx", "iyy", "izz")):
        notes.add("inertias of -1e-20 or so")
    return notes


def _mimics(path: Path) -> dict:
    """joint -> (master, multiplier, offset) of every moving ``<mimic>`` joint (URDF defaults 1 and 0)."""
    from lxml import etree
    out = {}
    for j in etree.parse(str(path)).getroot().findall("joint"):
        m = j.find("mimic")
        if m is not None and j.get("type") != "fixed":
            out[j.get("name")] = (m.get("joint"), float(m.get("multiplier", 1.0)), float(m.get("offset", 0.0)))
    return out


def _urdf_joint_values(mimic: dict, columns: dict):
    """The value of every moving joint of the URDF: a joint named by an encoder column takes its value, a
    ``<mimic>`` joint ``multiplier * master + offset``, any other joint 0."""
    def value(name, depth=0):
        if name in columns:
            return columns[name]
        if name in mimic and depth < 20:
            master, mult, off = mimic[name]
            return mult * value(master, depth + 1) + off
        return 0.0
    return value


def _configuration(model, value) -> np.ndarray:
    import pinocchio as pin
    x = pin.neutral(model)
    for jid in range(1, model.njoints):
        jm, v = model.joints[jid], value(model.names[jid])
        if jm.nq == 2:                                  # continuous: (cos, sin)
            x[jm.idx_q: jm.idx_q + 2] = (math.cos(v), math.sin(v))
        elif jm.nq == 1:
            x[jm.idx_q] = v
    return x


def _random_q(desc, rng, n: int) -> np.ndarray:
    q = np.empty((n, desc.n_joints))
    for k, e in enumerate(desc.encoders):
        lo, hi = (e.lower, e.upper) if e.lower is not None else ((-0.3, 0.3) if e.prismatic else (-math.pi, math.pi))
        q[:, k] = rng.uniform(lo, hi, n)
    return q


@dataclass
class RobotResult:
    """What the sweep found for one URDF file."""
    file: str
    pinocchio: str | None = None          # None: Pinocchio builds it; else why the toolkit refuses it too
    chains: int = 0
    loaded: int = 0
    refused: list = field(default_factory=list)      # (leaf, message)
    kinds: set = field(default_factory=set)          # "prismatic", "continuous", "mimic", "no stylus"
    worst: float = 0.0


def _check_robot(path: Path, rel: str, tmp: Path, cli: str) -> RobotResult:
    """Every chain of one URDF against Pinocchio; ``cli``: "all" chains, "one" (the longest) or "none"
    through ``aacmm tip`` too."""
    import pinocchio as pin

    from arm_model import InputError, ball_centres
    from arm_model.kinematics import probe_rotations
    from arm_model.urdf_import import description_from_urdf

    res = RobotResult(rel)
    try:
        model = pin.buildModelFromUrdf(str(path))
    except (RuntimeError, ValueError):
        try:                                    # the toolkit refuses it too, saying why
            description_from_urdf(path, "base_link")
        except InputError as exc:
            res.pinocchio = exc.reason
        return res
    try:
        mimic_model = pin.buildModelFromUrdf(str(path), mimic=True)
    except (RuntimeError, ValueError):
        mimic_model = None
    data = model.createData()
    mimic = _mimics(path)
    chains = _chains(path)
    longest = max(chains, key=lambda c: c[1])[0] if chains else None
    res.kinds |= _file_notes(path) if chains else set()
    for leaf, _, kinds in chains:
        res.chains += 1
        try:
            desc = description_from_urdf(path, leaf)
        except InputError as exc:
            res.refused.append((leaf, str(exc)))
            continue
        res.loaded += 1
        res.kinds |= kinds | ({"tip at the last joint"} if desc.probe.lever == 0.0 else set())
        rng = np.random.default_rng(zlib.crc32(f"{rel}:{leaf}".encode()))
        q = _random_q(desc, rng, 4)
        x, rot = ball_centres(desc, q), probe_rotations(desc, q)
        fid = model.getFrameId(leaf)
        for i in range(len(q)):
            value = _urdf_joint_values(mimic, dict(zip(desc.joint_names, q[i], strict=True)))
            pin.framesForwardKinematics(model, data, _configuration(model, value))
            ref = data.oMf[fid]
            err = max(np.abs(x[i] - ref.translation).max(), np.abs(rot[i] - ref.rotation).max())
            res.worst = max(res.worst, err)
            assert err <= 1e-12, f"{rel} -> {leaf}: {err:.3g} from Pinocchio"
            if mimic_model is not None:             # Pinocchio's own mimic joints: only the columns set
                md = mimic_model.createData()
                cols = dict(zip(desc.joint_names, q[i], strict=True))
                pin.framesForwardKinematics(mimic_model, md, _configuration(mimic_model, lambda n: cols.get(n, 0.0)))
                assert np.abs(md.oMf[mimic_model.getFrameId(leaf)].translation - x[i]).max() <= 1e-12, (rel, leaf)
        if cli == "all" or (cli == "one" and leaf == longest):
            _check_tip_command(path, leaf, desc, q, x, tmp)
    return res


def _check_tip_command(path: Path, leaf: str, desc, q, x, tmp: Path) -> None:
    """``aacmm tip`` on a points file of ``q`` (each column in its unit: deg, mm) gives ``x`` [m]."""
    from arm_model.cli import main
    units = desc.joint_column_units
    header = ",".join(["measurement", "feature"] + [f"q{k + 1}_{u}" for k, (u, _) in enumerate(units)])
    lines = [",".join(["m", ""] + [repr(float(v * f)) for v, (_, f) in zip(qi, units, strict=True)]) for qi in q]
    pts, out = tmp / "points.csv", tmp / "tips.csv"
    pts.write_text(header + "\n" + "\n".join(lines) + "\n")
    out.unlink(missing_ok=True)
    assert main(["tip", str(pts), "--arm", str(path), "--tip-frame", leaf, "-o", str(out), "-q"]) == 0
    got = np.loadtxt(out, delimiter=",", skiprows=1, usecols=(2, 3, 4), ndmin=2) * 1e-3
    assert np.abs(got - x).max() <= 1e-9, f"{path.name} -> {leaf}: aacmm tip"     # printed to 1e-6 mm


# ---------------------------------------------------------------------------------------------
# the tests

@pytest.mark.slow
def test_every_robot(robots, tmp_path):
    """Every URDF of the package: every chain Pinocchio builds loads and equals it (the API and ``aacmm
    tip``), and docs/robots.md holds the table this sweep writes. Among them one robot of each difficulty
    (:data:`QUICK`; its own test before, the same checks on the same chains, merged here): each has chains and
    loads them all, the one Pinocchio refuses is refused for having no name, and together they hold every kind."""
    results = [_check_robot(p, str(p.relative_to(robots)), tmp_path, cli="all") for p in sorted(robots.rglob("*.urdf"))]
    for r in results:
        assert r.loaded == r.chains, f"{r.file}: {r.refused[:2]}"
    quick = [r for r in results if r.file in QUICK]
    assert len(quick) == len(QUICK), sorted(set(QUICK) - {r.file for r in quick})
    kinds = set()
    for r in quick:
        if r.pinocchio is not None:
            assert "no name" in r.pinocchio
            continue
        assert r.chains and r.loaded == r.chains, r.refused
        kinds |= r.kinds
    assert {"prismatic", "continuous", "mimic", "tip at the last joint", "mirrored meshes"} <= kinds
    table = robot_table(results)
    doc = (ROOT / "docs" / "robots.md").read_text()
    assert TABLE_START in doc and TABLE_END in doc
    written = doc[doc.index(TABLE_START) + len(TABLE_START): doc.index(TABLE_END)].strip()
    assert written == table.strip(), "docs/robots.md is stale: its table should read\n" + table


def robot_table(results) -> str:
    """The Markdown table of docs/robots.md: per URDF file, what Pinocchio says, the chains to leaf links
    with at least 3 moving joints, how many load, and what they hold."""
    lines = ["| URDF (under `robots/`) | chains of >= 3 moving joints | load, equal to Pinocchio | holds |",
             "|---|---:|---:|---|"]
    for r in results:
        if r.pinocchio is not None:
            lines.append(f"| `{r.file}` | - | - | Pinocchio cannot build it; the toolkit refuses it too: "
                         f"\"{r.pinocchio}\" |")
            continue
        if not r.chains:
            lines.append(f"| `{r.file}` | 0 | - | no chain of 3 moving joints |")
            continue
        holds = ", ".join(sorted(r.kinds)) or "revolute joints"
        lines.append(f"| `{r.file}` | {r.chains} | {r.loaded} | {holds} |")
    total = [r for r in results if r.pinocchio is None and r.chains]
    lines.append(f"| **all** | **{sum(r.chains for r in total)}** | **{sum(r.loaded for r in total)}** | "
                 f"{len(total)} files with chains |")
    return "\n".join(lines) + "\n"
