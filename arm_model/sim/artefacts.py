"""Artefacts and where the ball centre must be: one plan row a captured point.

For each task of a campaign this draws the points an operator takes (docs/formats.md §4 meaning):

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
* motion capture (``mocap``): no artefact and no contact: the robot holds random postures within its
  joint limits while an instrument (motion capture, laser tracker) sees markers fixed on the tip frame at
  offsets unknown to the analysis, in one frame of its own a session; one measurement a posture.

Everything is in the arm's base frame, SI.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..chain import NUMPY_OPS, chain_point
from ..errors import InputError, NumericalError
from ..geometry import ball_centre_radius, cone_directions, perpendicular_basis, random_rotation
from .campaign import Campaign, Task

__all__ = ["Plan", "make_plan", "shoulder"]


#: per-point fields of a plan, in order
ROW_FIELDS = ("measurement", "feature", "task", "position", "normal", "cone", "lever", "stylus", "stylus_axis",
              "stylus_cone", "roll_along_force", "roll_jitter", "reference", "redraw", "q_start", "posture",
              "frame")


@dataclass
class Plan:
    """The points to capture, in capture order (N rows), and the artefacts' truth.

    Per point (lists while drawing, arrays after :meth:`arrays`):
        measurement, feature: ids.
        task: index of the task in the campaign.
        position: (3,) target (true, deflected) ball centre [m].
        normal: (3,) unit axis of the force the part exerts on the ball.
        cone: tangent of the half-angle of the cone around ``normal`` the force lies in.
        lever: [m] distance from the ball centre to the contact (friction torque), 0 for seats.
        stylus: (3,) required stylus direction (probe z, flange towards ball).
        stylus_axis, stylus_cone: (3,), [rad]: the cone ``stylus`` was drawn from (the inverse
            kinematics draws again from it when the arm cannot take the first direction).
        roll_along_force: True where the probe x axis must follow the force (ring, paper's sensor).
        roll_jitter: [rad] how far the operator misses that roll (uniform +-).
        reference: True for rows a tracker sees.
        redraw: None, or how to draw another contact on the same feature when the arm cannot reach
            this one (sphere and plane points; the operator probes elsewhere).
        q_start: (J,) true joint angles [rad] of an articulation found without contact force (NaN:
            none yet); the final inverse kinematics starts there. For a posture: its true joint values.
        posture: True for a posture of a motion-capture task: ``q_start`` holds the true joint values, no
            contact, no inverse kinematics; ``position`` is the true tip once the truth has placed it.
        frame: the instrument frame (a key of ``T_ref_base``) of a reference row, "" for other rows.

    Artefacts: ``features`` (dicts for artefacts.toml: id, kind, SI values), ``distances``
    ((between, length [m], u_length [m] or None, true length [m])), ``placements`` (per task id, where
    the artefact truly is), ``T_ref_base`` (per instrument frame, the (4, 4) transform from the arm base
    to the instrument: a tracker task's id, a motion-capture task's id or ``<id>-s<k>`` for its session k),
    ``ref_noise`` (per instrument frame, its noise [m], 1 sigma per axis), ``markers`` (per motion-capture
    task id, (K, 3) the true markers' offsets [m] in the tip frame).
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
    redraw: list = field(default_factory=list)
    q_start: list = field(default_factory=list)
    posture: list = field(default_factory=list)
    frame: list = field(default_factory=list)
    features: list = field(default_factory=list)
    distances: list = field(default_factory=list)
    placements: dict = field(default_factory=dict)
    T_ref_base: dict = field(default_factory=dict)
    ref_noise: dict = field(default_factory=dict)
    markers: dict = field(default_factory=dict)

    def add(self, measurement, feature, task, position, normal, cone, lever, stylus, roll=False,
            roll_jitter=0.0, reference=False, stylus_axis=None, stylus_cone=0.0, redraw=None, frame="",
            posture=None):
        row = dict(measurement=measurement, feature=feature, task=task, position=np.asarray(position, float),
                   normal=np.asarray(normal, float), cone=float(cone), lever=float(lever),
                   stylus=np.asarray(stylus, float),
                   stylus_axis=np.asarray(stylus if stylus_axis is None else stylus_axis, float),
                   stylus_cone=float(stylus_cone), roll_along_force=bool(roll), roll_jitter=float(roll_jitter),
                   reference=bool(reference), redraw=redraw, q_start=posture, posture=posture is not None,
                   frame=str(frame))
        for name in ROW_FIELDS:
            getattr(self, name).append(row[name])

    def arrays(self, n_joints: int = 7) -> Plan:
        """The same plan with numpy arrays for the per-point fields."""
        kinds = {"measurement": object, "feature": object, "task": int, "roll_along_force": bool, "reference": bool,
                 "redraw": object, "posture": bool, "frame": object}
        out = {}
        for name in ROW_FIELDS:
            v = getattr(self, name)
            if name == "q_start":
                out[name] = np.array([np.full(n_joints, np.nan) if x is None else x for x in v]).reshape(-1, n_joints)
            elif name == "redraw":
                out[name] = np.empty(len(v), dtype=object)
                out[name][:] = v
            elif name in ("position", "normal", "stylus", "stylus_axis"):
                out[name] = np.array(v, dtype=float).reshape(-1, 3)
            else:
                out[name] = np.array(v, dtype=kinds.get(name, float))
        return Plan(**out, features=self.features, distances=self.distances, placements=self.placements,
                    T_ref_base=self.T_ref_base, ref_noise=self.ref_noise, markers=self.markers)

    def __len__(self) -> int:
        return len(self.measurement)

    def extend(self, other: Plan) -> None:
        """Append the per-point rows of ``other`` (lists) to this plan."""
        for name in ROW_FIELDS:
            getattr(self, name).extend(getattr(other, name))


# ---------------------------------------------------------------------------------------------
# sampling helpers (frames and rotations: :mod:`arm_model.geometry`)

def shoulder(desc) -> np.ndarray:
    """Origin [m] of the first joint frame at q = 0 (for a DH arm: the shoulder), base frame."""
    rows = [list(r) for r in desc.row_table()[:1]]
    return np.array(chain_point(desc.convention, rows, [0.0] * desc.n_joints, (0.0, 0.0, 0.0), NUMPY_OPS,
                                desc.chain_joints[:1]), float)


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
    quick batch of inverse kinematics for all parts; the articulations found become the parts'
    ``q_start`` (and their stylus directions the ones that worked)."""
    from .ik import IKTargets, solve_points

    p = Plan()
    owner = []
    for k, part in enumerate(parts):
        p.extend(part)
        owner += [(k, i) for i in range(len(part))]
    j = truth.nominal.n_joints
    p = p.arrays(j)
    n = len(p)
    zeros = np.zeros((n, 3))
    targets = IKTargets(p.position, p.stylus, np.full((n, 3), np.nan), zeros, zeros, np.full(n, 20.0),
                        p.stylus_axis, p.stylus_cone)
    res, pending = solve_points(truth, targets, rng, tol=1e-9, max_attempts=12, max_iter=60)
    ok = np.ones(len(parts), bool)
    for r in pending:
        ok[owner[r][0]] = False
    for r, (k, i) in enumerate(owner):
        if ok[k]:
            parts[k].q_start[i] = res.q[r]
            parts[k].stylus[i] = res.stylus[r]
    return ok


#: rounds a task's default region is tried before the positions it cannot hold are drawn from the workspace
REGION_ROUNDS = 40
#: rounds in a row that place nothing after which a default region is given up for the workspace (and the
#: workspace itself)
REGION_PATIENCE = 10
#: postures sampled for a chain's workspace (:func:`_workspace`)
WORKSPACE_SAMPLES = 4000


def _place(plan, rng, o, n, shoulder, spread, make, truth, max_rounds: int = 40):
    """Place n positions whose points ``make(k, c, u, axis, part)`` draws into a part plan (``c`` the centre,
    ``u`` the bar's direction, ``axis`` the seats' axis, out of the seat); a position whose points the true arm
    cannot reach is drawn again. Inside the task's region (:func:`_candidate`, seats facing up); when the task
    gives no region (``o["region_given"]`` false), a position the default region cannot hold after
    :data:`REGION_ROUNDS` rounds (or :data:`REGION_PATIENCE` rounds in a row placing nothing) is drawn from the
    chain's own workspace instead (:func:`_workspace_candidate`),
    so that any chain, whatever its size and wherever its base, gets its positions."""
    chosen: list = [None] * n
    up = np.array([0.0, 0.0, 1.0])
    fallback = truth is not None and not o.get("region_given", True)
    rounds = REGION_ROUNDS if fallback else max_rounds

    def in_region(k):
        cand = _first(lambda: _candidate(rng, o, k, n, shoulder, spread))
        return None if cand is None else (cand[0], cand[1], up)

    _fill(chosen, rng, rounds, truth, make, in_region, REGION_PATIENCE if fallback else None)
    if fallback and any(c is None for c in chosen):
        ws = _workspace(truth, rng)
        if ws is not None:
            _fill(chosen, rng, max_rounds, truth, make, lambda k: _workspace_candidate(rng, ws, k, n, spread),
                  REGION_PATIENCE)
    missing = [k + 1 for k in range(n) if chosen[k] is None]
    if missing:
        where = (f"inside the region (radius_mm {[round(v * 1e3) for v in o['radius']]}, height_mm "
                 f"{[round(v * 1e3) for v in o['height']]}) within reach of the arm (reach_mm = {o['reach'] * 1e3:g} "
                 "from the shoulder); widen the region, or give none: the chain's own workspace is then used"
                 if not fallback else "in the default region or anywhere in the chain's workspace with the "
                 "stylus in its cone about the seats' axis; a shorter bar, fewer articulations or a wider "
                 f"'stylus_cone' (a chain of {truth.nominal.n_joints} moving joints: with fewer than six, a seat's "
                 "articulations may have no room to turn the stylus about the ball)")
        raise ValueError(f"could not place position(s) {missing} of {n} {where}")
    for part, _ in chosen:
        plan.extend(part)
    return [info for _, info in chosen]


def _first(draw, tries: int = 1000):
    """The first of ``tries`` draws that is not None (None if all are)."""
    for _ in range(tries):
        cand = draw()
        if cand is not None:
            return cand
    return None


def _fill(chosen: list, rng, rounds: int, truth, make, draw, patience: int | None = None) -> None:
    """Fill the empty entries ``k`` of ``chosen`` with (part plan, info) of a candidate ``draw(k)`` -> (centre,
    direction, seat axis) or None, whose points the true arm reaches (:func:`_reachable`), in up to ``rounds``
    rounds: fewer when a round draws no candidate at all, or after ``patience`` rounds in a row that place
    nothing (None: no such limit)."""
    idle = 0
    for _ in range(rounds):
        todo = [k for k in range(len(chosen)) if chosen[k] is None]
        if not todo or (patience is not None and idle >= patience):
            return
        cands = []
        for k in todo:
            cand = draw(k)
            if cand is None:
                continue
            part = Plan()
            info = make(k, cand[0], cand[1], cand[2], part)
            cands.append((k, part, info))
        if not cands:                   # nothing to draw from: more rounds would not change that
            return
        ok = _reachable(truth, [c[1] for c in cands], rng) if truth is not None else np.ones(len(cands), bool)
        for (k, part, info), good in zip(cands, ok, strict=True):
            if good:
                chosen[k] = (part, info)
        idle = 0 if ok.any() else idle + 1


def _workspace(truth, rng, n: int = WORKSPACE_SAMPLES):
    """The chain's own workspace: (tip positions (M, 3) [m], stylus directions (M, 3)) of ``n`` random postures
    within the joint limits (the true arm, no contact), stylus = probe z (flange towards ball); None if the
    chain has no posture."""
    from .ik import random_q

    q = random_q(truth.nominal, n, rng)
    ball, z, _ = truth.pose(q, truth.geometry(np.full(n, 20.0)))
    good = np.all(np.isfinite(ball), axis=1) & np.all(np.isfinite(z), axis=1)
    return (ball[good], z[good]) if good.any() else None


def _workspace_candidate(rng, ws, k: int, n: int, spread):
    """A position for stratum k of n from the workspace ``ws`` (:func:`_workspace`): a posture's tip, stratified
    by azimuth about the workspace's centroid, whose stylus gives the seats' axis (against it); for a bar of
    half length ``spread``, its other end towards another posture's tip at about the bar's length whose stylus
    lies within 45 deg of the first's (so one articulation cone serves both seats). Returns (centre, unit
    direction, seat axis) or None."""
    ball, z = ws
    rel = ball - ball.mean(axis=0)
    az = np.arctan2(rel[:, 1], rel[:, 0])
    lo, hi = -np.pi + 2 * np.pi * k / n, -np.pi + 2 * np.pi * (k + 1) / n
    stratum = np.flatnonzero((az >= lo) & (az < hi))
    i = int(rng.choice(stratum if stratum.size else np.arange(len(ball))))
    a, axis = ball[i], -z[i]
    if spread is None:
        u = rng.normal(size=3)
        return a, u / np.linalg.norm(u), axis
    d = np.linalg.norm(ball - a, axis=1)
    alike = np.flatnonzero((z @ z[i] >= np.cos(np.radians(45.0))) & (d > 0))
    if not alike.size:
        return None
    near = alike[np.argsort(np.abs(d[alike] - 2 * spread))[:8]]      # a few of the closest to the length
    j = int(rng.choice(near))
    u = (ball[j] - a) / d[j]
    return a + spread * u, u, axis


# ---------------------------------------------------------------------------------------------
# the tasks

def ring_surface(placement: dict, phi):
    """Radius [m] of a ring's true bore at angle ``phi`` [rad] about its axis (from its first
    perpendicular axis): ``D/2 + (form/2) cos(lobes phi + phase)``, and its derivative d r / d phi."""
    r0, f = placement["diameter_m"] / 2, placement["true_form_error_m"] / 2
    n, ph = placement["form_lobes"], placement["form_phase_rad"]
    return r0 + f * np.cos(n * phi + ph), -f * n * np.sin(n * phi + ph)


def _ring(plan, k, t: Task, rng, ball_d):
    o = t.opts
    c, a = np.array(o["centre"]), np.array(o["axis"])
    e1, e2 = perpendicular_basis(a)
    plan.features.append({"id": t.id, "kind": "ring", "diameter": o["diameter"], "u_diameter": o["u_diameter"],
                          "form_error": o["form_error"]})
    place = {"kind": "ring", "centre_m": c.tolist(), "axis": a.tolist(), "e1": e1.tolist(), "e2": e2.tolist(),
             "diameter_m": o["diameter"], "true_form_error_m": o["true_form_error"],
             "form_lobes": o["form_lobes"], "form_phase_rad": float(rng.uniform(0, 2 * np.pi))}
    plan.placements[t.id] = place
    npr = o["points_per_row"]
    for m in range(t.measurements):
        mid = f"{t.id}-{m + 1:02d}"
        for depth in o["depths"]:
            for i in range(npr):
                phi = 2 * np.pi * i / npr + rng.uniform(-1, 1) * o["angle_jitter"]
                dz = depth + rng.uniform(-1, 1) * o["depth_jitter"]
                radial = np.cos(phi) * e1 + np.sin(phi) * e2
                tangent = -np.sin(phi) * e1 + np.cos(phi) * e2
                r, dr = ring_surface(place, phi)
                inward = -r * radial + dr * tangent          # the bore's normal, towards the axis
                inward /= np.linalg.norm(inward)
                contact = c - dz * a + r * radial
                stylus = cone_directions(rng, -a, o["stylus_tilt"], 1)[0] if o["stylus_tilt"] > 0 else -a
                plan.add(mid, t.id, k, contact + inward * ball_d / 2, inward, np.nan, ball_d / 2, stylus,
                         roll=o["roll"] == "bend-along-force", roll_jitter=o["roll_jitter"], stylus_axis=-a,
                         stylus_cone=o["stylus_tilt"])


def _sphere_points(plan, mid, fid, k, t, rng, centre, diameter, n, polar_max, ball_d, pole=None):
    """The pole (default the base z axis), then points uniform on the cap of ``polar_max`` about it."""
    up = np.array([0.0, 0.0, 1.0]) if pole is None else np.asarray(pole, dtype=float)
    r = ball_centre_radius("sphere", diameter, ball_d)
    normals = np.vstack([up[None, :], cone_directions(rng, up, polar_max, n - 1)])[:n]
    redraw = {"kind": "sphere", "centre": np.asarray(centre, float), "radius": r, "polar_max": polar_max,
              "pole": up}
    for nrm in normals:
        stylus = cone_directions(rng, -nrm, t.opts["stylus_cone"], 1)[0]
        plan.add(mid, fid, k, centre + r * nrm, nrm, np.nan, ball_d / 2, stylus, stylus_axis=-nrm,
                 stylus_cone=t.opts["stylus_cone"], redraw=redraw)


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
    redraw = {"kind": "plane", "origin": p0 + nrm * ball_d / 2, "e1": e1, "e2": e2,
              "size": np.array(o["size"])}
    for m in range(t.measurements):
        for _ in range(o["points"]):
            u, v = rng.uniform(-0.5, 0.5, 2) * redraw["size"]
            stylus = cone_directions(rng, -nrm, o["stylus_cone"], 1)[0]
            plan.add(f"{t.id}-{m + 1:02d}", t.id, k, redraw["origin"] + u * e1 + v * e2, nrm, np.nan,
                     ball_d / 2, stylus, stylus_axis=-nrm, stylus_cone=o["stylus_cone"], redraw=redraw)


def _seat_points(plan, mid, fid, k, t, rng, position, axis, n, reference=False, frame=""):
    styli = [cone_directions(rng, -np.asarray(axis), t.opts["stylus_cone"], 1)[0] for _ in range(n)]
    if t.opts.get("order", "random") == "sweep":          # going round the seat: by the stylus' azimuth about it
        e1, e2 = perpendicular_basis(np.asarray(axis, float))
        styli.sort(key=lambda s: float(np.arctan2(s @ e2, s @ e1)))
    for stylus in styli:
        plan.add(mid, fid, k, position, axis, np.tan(t.opts["force_cone"]), 0.0, stylus, reference=reference,
                 stylus_axis=-np.asarray(axis), stylus_cone=t.opts["stylus_cone"], frame=frame)


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

    def make(m, c, u, axis, part):
        mid = f"{t.id}-pos-{m + 1:02d}"
        a, b = c - true_len / 2 * u, c + true_len / 2 * u
        for fid, centre in ((fa, a), (fb, b)):
            if o["ends"] == "sphere":
                _sphere_points(part, mid, fid, k, t, rng, centre, o["sphere_diameter"], o["points_per_sphere"],
                               o["polar_max"], ball_d, axis)
            else:
                _seat_points(part, mid, fid, k, t, rng, centre, axis, o["articulations"])
        return {"measurement": mid, "A_m": a.tolist(), "B_m": b.tolist(), "axis": axis.tolist()}

    placed = _place(plan, rng, o, t.measurements, shoulder(desc), true_len / 2, make, truth)
    plan.placements[t.id] = {"kind": "ballbar", "ends": o["ends"], "true_length_m": true_len,
                             "certified_length_m": o["length"], "positions": placed}


def _instrument_frame(rng, distance: float) -> np.ndarray:
    """A random (4, 4) ``T_ref_base``: any orientation, the base at ``distance`` [m] from the instrument."""
    rot = random_rotation(rng)
    d = rng.normal(size=3)
    d /= np.linalg.norm(d)
    T = np.eye(4)
    T[:3, :3] = rot
    T[:3, 3] = d * distance
    return T


def _tracker(plan, k, t, rng, ball_d, desc, truth):
    o = t.opts
    T = _instrument_frame(rng, o["distance"])
    plan.T_ref_base[t.id] = T
    plan.ref_noise[t.id] = o["noise"]

    def make(m, c, u, axis, part):
        fid = f"{t.id}-{m + 1:02d}"
        for rep in range(t.measurements):
            mid = fid if t.measurements == 1 else f"{fid}-{rep + 1:02d}"
            _seat_points(part, mid, fid, k, t, rng, c, axis, o["articulations"], reference=True, frame=t.id)
        return {"feature": fid, "position_m": c.tolist(), "axis": axis.tolist()}

    placed = _place(plan, rng, o, o["nests"], shoulder(desc), None, make, truth)
    plan.features += [{"id": p["feature"], "kind": "seat"} for p in placed]
    plan.placements[t.id] = {"kind": "tracker", "nests": placed, "T_ref_base": T.tolist(),
                             "noise_m": o["noise"]}


def mocap_sessions(t: Task) -> list[str]:
    """The instrument frames (session ids) of a motion-capture task: its id alone, or ``<id>-s1`` ...."""
    n = t.opts["sessions"]
    return [t.id] if n == 1 else [f"{t.id}-s{s + 1}" for s in range(n)]


def _mocap(plan, k, t, rng, desc):
    """Random postures within the joint limits (one measurement each, no feature, no contact), split in
    order into the sessions, each seen in a random instrument frame; the markers at ``marker_distance``
    from the tip frame's origin in random directions."""
    from .ik import random_q

    o = t.opts
    n = o["postures"]
    q = random_q(desc, n, rng, margin=o["limit_margin"])
    u = rng.normal(size=(o["markers"], 3))
    offsets = u / np.linalg.norm(u, axis=1, keepdims=True) * o["marker_distance"]
    plan.markers[t.id] = offsets
    sessions = mocap_sessions(t)
    frames = {}
    for s in sessions:
        plan.T_ref_base[s] = frames[s] = _instrument_frame(rng, o["distance"])
        plan.ref_noise[s] = o["noise"]
    width = max(2, len(str(n)))
    nan3 = np.full(3, np.nan)
    for s, rows in zip(sessions, np.array_split(np.arange(n), len(sessions)), strict=True):
        for i in rows:
            plan.add(f"{t.id}-{i + 1:0{width}d}", "", k, nan3, nan3, 0.0, 0.0, nan3, reference=True, frame=s,
                     posture=q[i])
    plan.placements[t.id] = {"kind": "mocap", "marker_offsets_m": offsets.tolist(),
                             "T_ref_base": {s: T.tolist() for s, T in frames.items()}, "noise_m": o["noise"]}


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
        elif t.kind == "mocap":
            _mocap(plan, k, t, rng, campaign.arm)
        else:
            try:
                (_ballbar if t.kind == "ballbar" else _tracker)(plan, k, t, rng, ball_d, campaign.arm, truth)
            except np.linalg.LinAlgError as exc:        # (a ValueError too): the arithmetic, not the file
                raise NumericalError(f"task[{k + 1}] ({t.kind}): placing it in the true arm's workspace failed "
                                     f"({exc}); are the truth's errors far beyond the arm's size?") from None
            except ValueError as exc:
                raise InputError(str(exc), campaign.source or "<dict>", t.line, f"key 'task[{k + 1}]'") from None
    out = plan.arrays(campaign.arm.n_joints)
    mu = campaign.operator["friction_coefficient"]
    out.cone = np.where(np.isnan(out.cone), mu, out.cone)
    if truth is not None:
        settle(out, truth, rng)
    return out


def _redraw_row(plan: Plan, i: int, rng) -> None:
    """Another contact on the same feature for row i (sphere: a new point of its cap; plane: a new
    place), with a new stylus direction from its cone."""
    rd = plan.redraw[i]
    if rd["kind"] == "sphere":
        nrm = cone_directions(rng, rd["pole"], rd["polar_max"], 1)[0]
        plan.position[i] = rd["centre"] + rd["radius"] * nrm
        plan.normal[i] = nrm
        plan.stylus_axis[i] = -nrm
    else:
        u, v = rng.uniform(-0.5, 0.5, 2) * rd["size"]
        plan.position[i] = rd["origin"] + u * rd["e1"] + v * rd["e2"]
    plan.stylus[i] = cone_directions(rng, plan.stylus_axis[i], plan.stylus_cone[i], 1)[0]


def settle(plan: Plan, truth, rng, rounds: int = 8) -> None:
    """Find an articulation (no contact force) for every row without ``q_start``; a sphere or plane
    point the arm cannot reach is moved elsewhere on its feature, as an operator would. Rows that stay
    out of reach raise :class:`~arm_model.NumericalError` naming them."""
    from .ik import IKTargets, solve_points

    todo = np.flatnonzero(np.isnan(plan.q_start[:, 0]))  # type: ignore[call-overload]
    for _ in range(rounds):
        if todo.size == 0:
            return
        n = todo.size
        zeros = np.zeros((n, 3))
        targets = IKTargets(plan.position[todo], plan.stylus[todo], np.full((n, 3), np.nan), zeros, zeros,
                            np.full(n, 20.0), plan.stylus_axis[todo], plan.stylus_cone[todo])
        res, pending = solve_points(truth, targets, rng, tol=1e-9, max_attempts=15, max_iter=60)
        good = np.setdiff1d(np.arange(n), pending)
        plan.q_start[todo[good]] = res.q[good]
        plan.stylus[todo[good]] = res.stylus[good]
        todo = todo[pending]
        for i in todo:
            if plan.redraw[i] is not None:
                _redraw_row(plan, i, rng)
    if todo.size:
        rows = [f"{plan.measurement[i]} row {i + 1} (feature {plan.feature[i]}, ball centre "
                f"{np.round(plan.position[i] * 1e3, 1).tolist()} mm)" for i in todo[:6]]
        raise NumericalError(f"{todo.size} point(s) are out of the arm's reach (no articulation inside the joint "
                             f"limits): {'; '.join(rows)}{' ...' if todo.size > 6 else ''}; "
                             "move the artefact closer to the arm")
