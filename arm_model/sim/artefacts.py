"""Artefacts and where the ball centre must be: one plan row a captured point.

For each task of a campaign this draws the points an operator takes (DATA-FORMATS §4 meaning):

* ring (inner cylinder, probed from inside, stylus parallel to its axis): ball centres on the
  cylinder of diameter D - ball diameter, rows at given depths below the top face; the part pushes
  the ball towards the axis.
* sphere (outer): ball centres on the sphere of diameter D + ball diameter; force along the outward
  normal at the contact.
* plane: ball centres on the plane offset by the ball radius; force along its normal.
* seat (kinematic seat, single-point articulation test): the ball centre is the seat point for
  every articulation; the seat pushes back along its axis (inside a cone).
* ball bar / length bar: two spheres (or seats) at a certified distance, one measurement a position,
  positions spread over the arm's volume.
* tracker nests: seats at random places whose ball centre a laser tracker also sees in its own
  frame, ``p_ref = T_ref_base p_base`` + noise (T_ref_base is unknown to the analysis).

Everything is in the arm's base frame, SI.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._errors import InputError
from ..chain import NUMPY_OPS, chain_point
from .campaign import Campaign, Task

__all__ = ["Plan", "make_plan", "random_rotation", "cone_directions", "perpendicular_basis"]


@dataclass
class Plan:
    """The points to capture, in capture order (N rows), and the artefacts' truth.

    Attributes:
        measurement, feature: (N,) ids.
        task: (N,) index of the task in the campaign.
        position: (N, 3) target (true, deflected) ball centre [m].
        normal: (N, 3) unit axis of the force the part exerts on the ball.
        cone: (N,) tangent of the half-angle of the cone around ``normal`` the force lies in.
        lever: (N,) [m] distance from the ball centre to the contact (friction torque), 0 for seats.
        stylus: (N, 3) required stylus direction (probe z, flange towards ball).
        stylus_axis, stylus_cone: (N, 3), (N,) [rad]: the cone ``stylus`` was drawn from (the inverse
            kinematics draws again from it when the arm cannot take the first direction).
        roll_along_force: (N,) True where the probe x axis must follow the force (ring, paper's sensor).
        roll_jitter: (N,) [rad] how far the operator misses that roll (uniform +-).
        reference: (N,) True for rows a tracker sees.
        features: artefact features for artefacts.toml: dicts (id, kind, SI values).
        distances: (between, length [m], u_length [m] or None, true length [m]).
        placements: per task id, where the artefact truly is (for the truth file).
        T_ref_base: per tracker task id, the (4, 4) transform from the arm base to the tracker.
        ref_noise: per tracker task id, the tracker's noise [m] (standard deviation per axis).
    """
    measurement: list = field(default_factory=list)
    feature: list = field(default_factory=list)
    task: list = field(default_factory=list)
    position: list = field(default_factory=list)
    normal: list = field(default_factory=list)
    cone: list = field(default_factory=list)
    lever: list = field(default_factory=list)
    stylus: list = field(default_factory=list)
    stylus_axis: list = field(default_factory=list)
    stylus_cone: list = field(default_factory=list)
    roll_along_force: list = field(default_factory=list)
    roll_jitter: list = field(default_factory=list)
    reference: list = field(default_factory=list)
    features: list = field(default_factory=list)
    distances: list = field(default_factory=list)
    placements: dict = field(default_factory=dict)
    T_ref_base: dict = field(default_factory=dict)
    ref_noise: dict = field(default_factory=dict)

    def add(self, measurement, feature, task, position, normal, cone, lever, stylus, roll=False,
            roll_jitter=0.0, reference=False, stylus_axis=None, stylus_cone=0.0):
        self.measurement.append(measurement)
        self.feature.append(feature)
        self.task.append(task)
        self.position.append(np.asarray(position, float))
        self.normal.append(np.asarray(normal, float))
        self.cone.append(float(cone))
        self.lever.append(float(lever))
        self.stylus.append(np.asarray(stylus, float))
        self.stylus_axis.append(np.asarray(stylus if stylus_axis is None else stylus_axis, float))
        self.stylus_cone.append(float(stylus_cone))
        self.roll_along_force.append(bool(roll))
        self.roll_jitter.append(float(roll_jitter))
        self.reference.append(bool(reference))

    def arrays(self) -> "Plan":
        """The same plan with numpy arrays for the per-point lists."""
        out = Plan(np.array(self.measurement, dtype=object), np.array(self.feature, dtype=object),
                   np.array(self.task, int), np.array(self.position).reshape(-1, 3),
                   np.array(self.normal).reshape(-1, 3), np.array(self.cone), np.array(self.lever),
                   np.array(self.stylus).reshape(-1, 3), np.array(self.stylus_axis).reshape(-1, 3),
                   np.array(self.stylus_cone), np.array(self.roll_along_force, bool),
                   np.array(self.roll_jitter), np.array(self.reference, bool), self.features,
                   self.distances, self.placements, self.T_ref_base, self.ref_noise)
        return out

    def __len__(self) -> int:
        return len(self.measurement)

    def extend(self, other: "Plan") -> None:
        """Append the per-point rows of ``other`` (lists) to this plan."""
        for name in ("measurement", "feature", "task", "position", "normal", "cone", "lever", "stylus",
                     "stylus_axis", "stylus_cone", "roll_along_force", "roll_jitter", "reference"):
            getattr(self, name).extend(getattr(other, name))


# ---------------------------------------------------------------------------------------------
# geometry helpers

def perpendicular_basis(u) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors perpendicular to the unit vector ``u`` and to each other (right-handed)."""
    u = np.asarray(u, float)
    a = np.array([1.0, 0, 0]) if abs(u[0]) < 0.9 else np.array([0, 1.0, 0])
    e1 = np.cross(u, a)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(u, e1)


def cone_directions(rng, axis, half_angle: float, n: int) -> np.ndarray:
    """(n, 3) unit directions uniform on the spherical cap of ``half_angle`` [rad] about ``axis``."""
    axis = np.asarray(axis, float)
    e1, e2 = perpendicular_basis(axis)
    cos_t = rng.uniform(np.cos(half_angle), 1.0, n)
    phi = rng.uniform(0, 2 * np.pi, n)
    sin_t = np.sqrt(np.maximum(0.0, 1 - cos_t ** 2))
    return (cos_t[:, None] * axis + sin_t[:, None] * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2))


def random_rotation(rng) -> np.ndarray:
    """A (3, 3) rotation drawn uniformly (unit quaternion from four normals)."""
    qv = rng.normal(size=4)
    w, x, y, z = qv / np.linalg.norm(qv)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _shoulder(desc) -> np.ndarray:
    """Origin [m] of the first joint frame at q = 0 (for a DH arm: the shoulder), base frame."""
    rows = [list(r) for r in desc.row_table()[:1]]
    return np.array(chain_point(desc.convention, rows, [0.0], (0.0, 0.0, 0.0), NUMPY_OPS,
                                None if desc.axes is None else desc.axes[:1]), float)


def _candidate(rng, o: dict, k: int, n: int, shoulder, spread=None):
    """A position for stratum k of n: azimuth stratified, radius and height uniform in the task's
    region, a random direction; None if an end (a bar of half length ``spread``) leaves the reach
    of the shoulder or the region."""
    az = 2 * np.pi * (k + rng.uniform()) / n
    r = rng.uniform(*o["radius"])
    h = rng.uniform(*o["height"])
    c = np.array([r * np.cos(az), r * np.sin(az), h])
    u = rng.normal(size=3)
    u /= np.linalg.norm(u)
    ends = [c] if spread is None else [c - spread * u, c + spread * u]
    if all(np.linalg.norm(e - shoulder) <= o["reach"] and np.hypot(e[0], e[1]) >= 0.2
           and o["height"][0] - 0.1 <= e[2] <= o["height"][1] + 0.1 for e in ends):
        return c, u
    return None


def _reachable(truth, parts: list, rng) -> np.ndarray:
    """For each part plan: can the true arm take every one of its points (no contact force)? One
    quick batch of inverse kinematics for all parts."""
    from .ik import IKTargets, solve_points

    p = Plan()
    owner = []
    for k, part in enumerate(parts):
        p.extend(part)
        owner += [k] * len(part)
    p = p.arrays()
    n = len(p)
    zeros = np.zeros((n, 3))
    targets = IKTargets(p.position, p.stylus, np.full((n, 3), np.nan), zeros, zeros, np.full(n, 20.0),
                        p.stylus_axis, p.stylus_cone)
    _, pending = solve_points(truth, targets, rng, tol=1e-9, max_attempts=12, max_iter=60)
    ok = np.ones(len(parts), bool)
    ok[np.array(owner, int)[pending]] = False
    return ok


def _place(plan, rng, o, n, shoulder, spread, make, truth, max_rounds: int = 40):
    """Place n positions (see :func:`_candidate`) whose points ``make(k, c, u, part)`` draws into a
    part plan; a position whose points the true arm cannot reach is drawn again."""
    chosen: list = [None] * n
    for _ in range(max_rounds):
        todo = [k for k in range(n) if chosen[k] is None]
        if not todo:
            break
        cands = []
        for k in todo:
            for _ in range(1000):
                cand = _candidate(rng, o, k, n, shoulder, spread)
                if cand is not None:
                    break
            else:
                continue
            part = Plan()
            info = make(k, cand[0], cand[1], part)
            cands.append((k, part, info))
        ok = _reachable(truth, [c[1] for c in cands], rng) if truth is not None and cands else \
            np.ones(len(cands), bool)
        for (k, part, info), good in zip(cands, ok):
            if good:
                chosen[k] = (part, info)
    missing = [k + 1 for k in range(n) if chosen[k] is None]
    if missing:
        raise ValueError(f"could not place position(s) {missing} of {n} inside the region (radius_mm "
                         f"{[round(v * 1e3) for v in o['radius']]}, height_mm "
                         f"{[round(v * 1e3) for v in o['height']]}) within reach of the arm "
                         f"(reach_mm = {o['reach'] * 1e3:g} from the shoulder); widen the region")
    for part, _ in chosen:
        plan.extend(part)
    return [info for _, info in chosen]


# ---------------------------------------------------------------------------------------------
# the tasks

def _ring(plan, k, t: Task, rng, ball_d):
    o = t.opts
    c, a = np.array(o["centre"]), np.array(o["axis"])
    e1, e2 = perpendicular_basis(a)
    radius = (o["diameter"] - ball_d) / 2
    plan.features.append({"id": t.id, "kind": "ring", "diameter": o["diameter"], "u_diameter": o["u_diameter"],
                          "form_error": o["form_error"]})
    plan.placements[t.id] = {"kind": "ring", "centre_m": c.tolist(), "axis": a.tolist(),
                             "diameter_m": o["diameter"], "ball_centre_radius_m": radius}
    npr = o["points_per_row"]
    for m in range(t.measurements):
        mid = f"{t.id}-{m + 1:02d}"
        for depth in o["depths"]:
            for i in range(npr):
                phi = 2 * np.pi * i / npr + rng.uniform(-1, 1) * o["angle_jitter"]
                dz = depth + rng.uniform(-1, 1) * o["depth_jitter"]
                radial = np.cos(phi) * e1 + np.sin(phi) * e2
                stylus = cone_directions(rng, -a, o["stylus_tilt"], 1)[0] if o["stylus_tilt"] > 0 else -a
                plan.add(mid, t.id, k, c - dz * a + radial * radius, -radial, np.nan, ball_d / 2, stylus,
                         roll=o["roll"] == "bend-along-force", roll_jitter=o["roll_jitter"], stylus_axis=-a,
                         stylus_cone=o["stylus_tilt"])


def _sphere_points(plan, mid, fid, k, t, rng, centre, diameter, n, polar_max, ball_d):
    up = np.array([0.0, 0.0, 1.0])
    r = (diameter + ball_d) / 2
    normals = np.vstack([up[None, :], cone_directions(rng, up, polar_max, n - 1)])[:n]
    for nrm in normals:
        stylus = cone_directions(rng, -nrm, t.opts["stylus_cone"], 1)[0]
        plan.add(mid, fid, k, centre + r * nrm, nrm, np.nan, ball_d / 2, stylus, stylus_axis=-nrm,
                 stylus_cone=t.opts["stylus_cone"])


def _sphere(plan, k, t, rng, ball_d):
    o = t.opts
    c = np.array(o["centre"])
    plan.features.append({"id": t.id, "kind": "sphere", "diameter": o["diameter"]})
    plan.placements[t.id] = {"kind": "sphere", "centre_m": c.tolist(), "diameter_m": o["diameter"]}
    for m in range(t.measurements):
        _sphere_points(plan, f"{t.id}-{m + 1:02d}", t.id, k, t, rng, c, o["diameter"], o["points"],
                       o["polar_max"], ball_d)


def _plane(plan, k, t, rng, ball_d):
    o = t.opts
    p0, nrm = np.array(o["point"]), np.array(o["normal"])
    e1, e2 = perpendicular_basis(nrm)
    plan.features.append({"id": t.id, "kind": "plane"})
    plan.placements[t.id] = {"kind": "plane", "point_m": p0.tolist(), "normal": nrm.tolist()}
    for m in range(t.measurements):
        for _ in range(o["points"]):
            u, v = rng.uniform(-0.5, 0.5, 2) * np.array(o["size"])
            stylus = cone_directions(rng, -nrm, o["stylus_cone"], 1)[0]
            plan.add(f"{t.id}-{m + 1:02d}", t.id, k, p0 + u * e1 + v * e2 + nrm * ball_d / 2, nrm, np.nan,
                     ball_d / 2, stylus, stylus_axis=-nrm, stylus_cone=o["stylus_cone"])


def _seat_points(plan, mid, fid, k, t, rng, position, axis, n, reference=False):
    for _ in range(n):
        stylus = cone_directions(rng, -np.asarray(axis), t.opts["stylus_cone"], 1)[0]
        plan.add(mid, fid, k, position, axis, np.tan(t.opts["force_cone"]), 0.0, stylus, reference=reference,
                 stylus_axis=-np.asarray(axis), stylus_cone=t.opts["stylus_cone"])


def _seat(plan, k, t, rng, ball_d):
    o = t.opts
    s, a = np.array(o["position"]), np.array(o["axis"])
    plan.features.append({"id": t.id, "kind": "seat"})
    plan.placements[t.id] = {"kind": "seat", "position_m": s.tolist(), "axis": a.tolist()}
    for m in range(t.measurements):
        _seat_points(plan, f"{t.id}-{m + 1:02d}", t.id, k, t, rng, s, a, o["articulations"])


def _ballbar(plan, k, t, rng, ball_d, desc, truth):
    o = t.opts
    fa, fb = f"{t.id}-A", f"{t.id}-B"
    true_len = o["true_length"] if o["true_length"] is not None else o["length"]
    if o["ends"] == "sphere":
        plan.features += [{"id": f, "kind": "sphere", "diameter": o["sphere_diameter"]} for f in (fa, fb)]
    else:
        plan.features += [{"id": f, "kind": "seat"} for f in (fa, fb)]
    plan.distances.append(((fa, fb), o["length"], o["u_length"], true_len))
    up = np.array([0.0, 0.0, 1.0])

    def make(m, c, u, part):
        mid = f"{t.id}-pos-{m + 1:02d}"
        a, b = c - true_len / 2 * u, c + true_len / 2 * u
        for fid, centre in ((fa, a), (fb, b)):
            if o["ends"] == "sphere":
                _sphere_points(part, mid, fid, k, t, rng, centre, o["sphere_diameter"], o["points_per_sphere"],
                               o["polar_max"], ball_d)
            else:
                _seat_points(part, mid, fid, k, t, rng, centre, up, o["articulations"])
        return {"measurement": mid, "A_m": a.tolist(), "B_m": b.tolist()}

    placed = _place(plan, rng, o, t.measurements, _shoulder(desc), true_len / 2, make, truth)
    plan.placements[t.id] = {"kind": "ballbar", "ends": o["ends"], "true_length_m": true_len,
                             "certified_length_m": o["length"], "positions": placed}


def _tracker(plan, k, t, rng, ball_d, desc, truth):
    o = t.opts
    rot = random_rotation(rng)
    d = rng.normal(size=3)
    d /= np.linalg.norm(d)
    T = np.eye(4)
    T[:3, :3] = rot
    T[:3, 3] = d * o["distance"]
    plan.T_ref_base[t.id] = T
    plan.ref_noise[t.id] = o["noise"]
    up = np.array([0.0, 0.0, 1.0])

    def make(m, c, u, part):
        fid = f"{t.id}-{m + 1:02d}"
        for rep in range(t.measurements):
            mid = fid if t.measurements == 1 else f"{fid}-{rep + 1:02d}"
            _seat_points(part, mid, fid, k, t, rng, c, up, o["articulations"], reference=True)
        return {"feature": fid, "position_m": c.tolist()}

    placed = _place(plan, rng, o, o["nests"], _shoulder(desc), None, make, truth)
    plan.features += [{"id": p["feature"], "kind": "seat"} for p in placed]
    plan.placements[t.id] = {"kind": "tracker", "nests": placed, "T_ref_base": T.tolist(),
                             "noise_m": o["noise"]}


def make_plan(campaign: Campaign, rng: np.random.Generator, truth=None) -> Plan:
    """Draw every point of every task, in capture order (tasks in file order). With ``truth``
    (:class:`~arm_model.sim.truth.Truth`), ball-bar and tracker positions the true arm cannot reach
    are drawn again."""
    plan = Plan()
    ball_d = campaign.arm.probe.ball_diameter
    for k, t in enumerate(campaign.tasks):
        if t.kind == "ring":
            _ring(plan, k, t, rng, ball_d)
        elif t.kind == "sphere":
            _sphere(plan, k, t, rng, ball_d)
        elif t.kind == "plane":
            _plane(plan, k, t, rng, ball_d)
        elif t.kind == "seat":
            _seat(plan, k, t, rng, ball_d)
        else:
            try:
                (_ballbar if t.kind == "ballbar" else _tracker)(plan, k, t, rng, ball_d, campaign.arm, truth)
            except ValueError as exc:
                raise InputError(str(exc), campaign.source or "<dict>", t.line, f"key 'task[{k + 1}]'") from None
    out = plan.arrays()
    mu = campaign.operator["friction_coefficient"]
    out.cone = np.where(np.isnan(out.cone), mu, out.cone)
    return out
