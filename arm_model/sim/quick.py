"""The simulator's fast path: small campaigns from a known true model (tests, studies, benchmarks).

The full campaign (:func:`arm_model.sim.simulate`) has an operator, force signals, a drawn truth and
encoder quantisation. This path takes the true arm as given, ``model`` (a core
:class:`~arm_model.model.ArmModel` with any effects that need no joint torques) with parameter errors
``p_true``, draws artefact points in a working volume and finds the encoder readings that put the
true deflected ball centre on each point with the position-only inverse kinematics of
:func:`arm_model.sim.ik.solve_positions` (the model's own exact Jacobian, the redundancy drawn at
random). Every true deflected ball centre lies on its artefact (to 1e-12 m) before the probing noise
is added.

Artefacts made: ball bars (two spheres or two seats at a certified length, several positions),
seat articulations, spheres, rings (inner cylinders) and planes, and reference (tracker) points
seen through a random rigid transform ``T_ref_base``.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..geometry import cone_directions, perpendicular_basis, rotation_xyz
from ..io import Artefacts, Distance, Feature, PointSet, atomic_write_text, format_artefacts, write_csv
from ..model import ArmModel, AuxData
from .artefacts import shoulder
from .ik import random_q, solve_positions

__all__ = ["SynthSpec", "SynthCampaign", "random_truth", "random_q", "make_campaign"]


@dataclass(frozen=True)
class SynthSpec:
    """What to measure (lengths [m], forces [N]).

    Attributes:
        ballbars: ball-bar positions (one measurement each).
        ballbar_length: certified centre distance [m].
        ballbar_kind: "sphere" (probed spheres) or "seat" (kinematic seats, articulations).
        ballbar_points: points per sphere (or articulations per seat) at each end.
        seats: single-point articulation measurements; ``articulations`` points each.
        spheres: reference-sphere measurements; ``sphere_points`` points each, ``sphere_diameter``.
        rings: ring measurements (``ring_points`` points in 3 rows), ``ring_diameter``.
        planes: plane measurements, ``plane_points`` each.
        reference_points: tracker points (one measurement), ``reference_noise`` per axis [m].
        force: mean contact force [N] along the surface normal (0: no force columns).
        noise: probing noise of a ball centre per axis [m].
        u_length: certificate uncertainty of the ball bar [m].
        centre: middle of the working volume [m] (base frame); ``spread`` its half-size [m].
    """
    ballbars: int = 8
    ballbar_length: float = 0.5
    ballbar_kind: str = "sphere"
    ballbar_points: int = 6
    seats: int = 2
    articulations: int = 12
    spheres: int = 1
    sphere_points: int = 12
    sphere_diameter: float = 0.025
    rings: int = 0
    ring_points: int = 24
    ring_diameter: float = 0.174996
    planes: int = 0
    plane_points: int = 12
    reference_points: int = 0
    reference_noise: float = 5e-6
    force: float = 0.0
    noise: float = 2e-6
    u_length: float = 0.8e-6
    centre: tuple = (0.55, 0.0, 0.15)
    spread: tuple = (0.2, 0.35, 0.2)


@dataclass
class SynthCampaign:
    """Points and artefacts like the readers give, plus the truth (never read by the analysis)."""
    points: PointSet
    artefacts: Artefacts
    truth: dict                      # true parameter errors by name (SI)
    p_true: np.ndarray
    true_centres: np.ndarray         # (N, 3) [m] artefact points before the probing noise
    reference_points: PointSet | None = None     # tracker points (feature "", with ref)
    reference_true: np.ndarray | None = None     # their true ball centres [m]
    T_ref_base: np.ndarray | None = None
    #: per joint column: its unit suffix and factor from SI (ArmDescription.joint_column_units; () all degrees)
    column_units: tuple = ()

    def write(self, out_dir) -> dict:
        """Write ``points.csv``, ``points-ref.csv`` (with reference points) and ``artefacts.toml``
        (docs/formats.md §3, §4); returns ``{role: Path}``."""
        out = Path(out_dir)
        files = {"points": _write_points(out / "points.csv", self.points, self.column_units)}
        if self.reference_points is not None:
            files["reference"] = _write_points(out / "points-ref.csv", self.reference_points, self.column_units)
        text = format_artefacts(self.artefacts.features.values(), self.artefacts.distances)
        files["artefacts"] = atomic_write_text(out / "artefacts.toml", text)
        return files


def _write_points(path, pts: PointSet, column_units=()) -> Path:
    cols = {"measurement": pts.measurement, "feature": pts.feature}
    for j in range(pts.n_joints):
        unit, factor = column_units[j] if column_units else ("deg", None)
        cols[f"q{j + 1}_{unit}"] = np.degrees(pts.q[:, j]) if factor is None else pts.q[:, j] * factor
    if pts.force is not None:
        for k, a in enumerate("xyz"):
            cols[f"f{a}_N"] = pts.force[:, k]
    if pts.temperature is not None:
        cols["temperature_C"] = pts.temperature
    ref = np.zeros((len(pts), 0, 3)) if pts.ref is None else pts.ref
    for m in range(ref.shape[1]):
        for k, a in enumerate("xyz"):
            cols[f"{a}{'' if ref.shape[1] == 1 else m + 1}_ref_mm"] = ref[:, m, k] * 1e3
    return write_csv(path, cols, fmt="%.15g")


def random_truth(model: ArmModel, rng, length: float = 50e-6, angle: float = 1e-4,
                 probe: float = 50e-6) -> np.ndarray:
    """Random base errors: lengths N(0, length) [m], angles N(0, angle) [rad], probe offset
    N(0, probe) [m]; compliances and effect parameters zero."""
    p = np.zeros(model.spec.size)
    for i, (n, u) in enumerate(zip(model.spec.names, model.spec.units, strict=True)):
        if n.startswith("probe.compliance") or i >= model.base_size:
            continue
        if n.startswith("probe."):
            p[i] = rng.normal(0, probe)
        elif u == "m":
            p[i] = rng.normal(0, length)
        elif u == "rad":
            p[i] = rng.normal(0, angle)
    return p


#: the sphere points' normals: uniform on the cap of this half angle about the base z axis (cos = 0.2)
SPHERE_CAP = float(np.arccos(0.2))


def _tracker_points(model: ArmModel, p_true, spec: SynthSpec, rng, T_ref_base=None):
    """``(points, T_ref_base, true ball centres)`` of ``spec.reference_points`` free points a tracker sees
    (the ball centre itself, marker 1), in ``T_ref_base`` (default: drawn at random)."""
    desc, nr = model.desc, spec.reference_points
    needs_t = "temperature" in model.needs()
    q_ref = random_q(desc, nr, rng)
    x_true = model.ball_centres(q_ref, None, p_true, AuxData(temperature=np.full(nr, 20.0)) if needs_t else None)
    if T_ref_base is None:
        T_ref_base = np.eye(4)
        T_ref_base[:3, :3] = rotation_xyz(rng.uniform(-np.pi, np.pi, 3))
        T_ref_base[:3, 3] = rng.uniform(-2, 2, 3)
    t_ref = np.asarray(T_ref_base, float)
    seen = x_true + rng.normal(0, spec.noise, (nr, 3))
    x_ref = seen @ t_ref[:3, :3].T + t_ref[:3, 3] + rng.normal(0, spec.reference_noise, (nr, 3))
    points = PointSet(path="<synthetic reference>", measurement=np.array(["tracker"] * nr, dtype=object),
                      feature=np.array([""] * nr, dtype=object), q=q_ref,
                      temperature=np.full(nr, 20.0) if needs_t else None, ref=x_ref[:, None, :],
                      lines=np.arange(2, nr + 2))
    return points, t_ref, x_true


class _Targets:
    """The artefact points of a synthetic campaign as they are laid out: measurement and feature of each
    point, its target ball centre [m] and surface normal, the features and distances (random draws from
    ``rng`` in the order of the steps)."""

    def __init__(self, desc, spec: SynthSpec, rng):
        self.spec, self.rng = spec, rng
        self.ball = desc.probe.ball_diameter
        self.centre, self.spread = np.asarray(spec.centre), np.asarray(spec.spread)
        self.origin = shoulder(desc)
        self.meas, self.feat, self.targets, self.normals = [], [], [], []
        self.features: dict[str, Feature] = {}
        self.distances: list[Distance] = []

    def reachable(self, x) -> bool:
        return bool(0.35 <= np.linalg.norm(x - self.origin) <= 0.85)

    def place(self) -> np.ndarray:
        while True:
            x = self.centre + self.rng.uniform(-1, 1, 3) * self.spread
            if self.reachable(x):
                return x

    def add(self, m, f, pts, nrm) -> None:
        self.meas.extend([m] * len(pts))
        self.feat.extend([f] * len(pts))
        self.targets.extend(pts)
        self.normals.extend(nrm)

    def sphere_points(self, c, diameter, k):
        nrm = cone_directions(self.rng, (0.0, 0.0, 1.0), SPHERE_CAP, k)
        return c + nrm * (diameter + self.ball) / 2, nrm

    def ballbars(self) -> None:
        spec, rng = self.spec, self.rng
        if spec.ballbar_kind == "sphere":
            self.features["bar-A"] = Feature("bar-A", "sphere", spec.sphere_diameter)
            self.features["bar-B"] = Feature("bar-B", "sphere", spec.sphere_diameter)
        else:
            self.features["bar-A"] = Feature("bar-A", "seat")
            self.features["bar-B"] = Feature("bar-B", "seat")
        self.distances.append(Distance(("bar-A", "bar-B"), spec.ballbar_length, spec.u_length))
        for i in range(spec.ballbars):
            while True:
                d = rng.normal(size=3)
                d[2] *= 0.5
                d /= np.linalg.norm(d)
                a = self.place() - d * spec.ballbar_length / 2
                b = a + d * spec.ballbar_length
                if self.reachable(a) and self.reachable(b):
                    break
            for fid, c in (("bar-A", a), ("bar-B", b)):
                if spec.ballbar_kind == "sphere":
                    pts, nrm = self.sphere_points(c, spec.sphere_diameter, spec.ballbar_points)
                else:
                    pts, nrm = np.tile(c, (spec.ballbar_points, 1)), np.tile([0, 0, 1.0], (spec.ballbar_points, 1))
                self.add(f"bar-{i + 1:02d}", fid, pts, nrm)

    def seats(self) -> None:
        spec = self.spec
        self.features["seat"] = Feature("seat", "seat")
        for i in range(spec.seats):
            c = self.place()
            self.add(f"seat-{i + 1:02d}", "seat", np.tile(c, (spec.articulations, 1)),
                     np.tile([0, 0, 1.0], (spec.articulations, 1)))

    def spheres(self) -> None:
        spec = self.spec
        self.features["sphere"] = Feature("sphere", "sphere", spec.sphere_diameter)
        for i in range(spec.spheres):
            pts, nrm = self.sphere_points(self.place(), spec.sphere_diameter, spec.sphere_points)
            self.add(f"sphere-{i + 1:02d}", "sphere", pts, nrm)

    def rings(self) -> None:
        spec, rng = self.spec, self.rng
        self.features["ring"] = Feature("ring", "ring", spec.ring_diameter)
        rad = (spec.ring_diameter - self.ball) / 2
        for i in range(spec.rings):
            c = self.place()
            axis = np.array([0, 0, 1.0]) + rng.normal(0, 0.05, 3)
            axis /= np.linalg.norm(axis)
            e1, e2 = perpendicular_basis(axis)
            k = spec.ring_points
            ang = np.linspace(0, 2 * np.pi, k, endpoint=False) + rng.uniform(0, 2 * np.pi)
            h = np.repeat([-0.01, 0.0, 0.01], int(np.ceil(k / 3)))[:k]
            radial = np.outer(np.cos(ang), e1) + np.outer(np.sin(ang), e2)
            self.add(f"ring-{i + 1:02d}", "ring", c + rad * radial + np.outer(h, axis), -radial)

    def planes(self) -> None:
        spec, rng = self.spec, self.rng
        self.features["plane"] = Feature("plane", "plane")
        for i in range(spec.planes):
            c = self.place()
            nrm = np.array([0, 0, 1.0]) + rng.normal(0, 0.1, 3)
            nrm /= np.linalg.norm(nrm)
            e1, e2 = perpendicular_basis(nrm)
            uv = rng.uniform(-0.1, 0.1, (spec.plane_points, 2))
            pts = c + uv[:, :1] * e1 + uv[:, 1:] * e2 + nrm * self.ball / 2
            self.add(f"plane-{i + 1:02d}", "plane", pts, np.tile(nrm, (spec.plane_points, 1)))


def make_campaign(model: ArmModel, spec: SynthSpec = SynthSpec(), seed: int = 0, p_true=None,
                  T_ref_base=None) -> SynthCampaign:
    """Make a campaign on the true arm ``(model, p_true)`` (default: :func:`random_truth`)."""
    rng = np.random.default_rng(seed)
    desc = model.desc
    p_true = random_truth(model, rng) if p_true is None else np.asarray(p_true, float)
    lay = _Targets(desc, spec, rng)
    for count, step in ((spec.ballbars, lay.ballbars), (spec.seats, lay.seats), (spec.spheres, lay.spheres),
                        (spec.rings, lay.rings), (spec.planes, lay.planes)):
        if count:
            step()
    meas, feat, targets, normals = lay.meas, lay.feat, lay.targets, lay.normals
    features, distances = lay.features, lay.distances
    n_art = len(targets)
    targets = np.array(targets).reshape(-1, 3)
    normals = np.array(normals).reshape(-1, 3)
    noise = rng.normal(0, spec.noise, targets.shape)  # type: ignore[attr-defined]
    force_base = None
    if spec.force > 0:
        mag = rng.gamma(4.0, spec.force / 4.0, n_art)
        force_base = normals * mag[:, None]
    q_art, w_art = (solve_positions(model, p_true, targets + noise, rng, force_base) if n_art  # type: ignore[operator]
                    else (np.zeros((0, desc.n_joints)), np.zeros((0, 6))))
    n = len(meas)
    needs_t = "temperature" in model.needs()
    points = PointSet(path="<synthetic points>", measurement=np.array(meas, dtype=object),
                      feature=np.array(feat, dtype=object), q=q_art,
                      force=w_art[:, :3].copy() if spec.force > 0 else None,
                      force_kind="xyz" if spec.force > 0 else None,
                      temperature=np.full(n, 20.0) if needs_t else None, lines=np.arange(2, n + 2))
    reference_points, t_ref, x_true = (_tracker_points(model, p_true, spec, rng, T_ref_base)
                                       if spec.reference_points else (None, None, None))
    artefacts = Artefacts("<synthetic artefacts>", features, tuple(distances))
    truth = {name: float(v) for name, v in zip(model.spec.names, p_true, strict=True)}
    return SynthCampaign(points, artefacts, truth, p_true, targets, reference_points, x_true, t_ref,
                         desc.joint_column_units)
