"""Redundant inverse kinematics on the true arm, for many points at once.

Two solvers. :func:`solve_ik` (the full simulator) places the ball and orients the stylus, at true
angles of a :class:`~arm_model.sim.truth.Truth`. :func:`solve_positions` (the fast path of
:mod:`arm_model.sim.quick`) places only the ball, directly in encoder readings of a core
:class:`~arm_model.model.ArmModel`, so every effect the model holds (but joint torques) is in the
truth. The rest of this docstring is about :func:`solve_ik`.

Constraints per point: the deflected ball centre at a target (3), the stylus (probe z axis) along a
required direction (2; the residual is ``z - u``, so the opposite direction is no solution), and
optionally the probe x axis towards a required direction (1). A 7-axis
arm keeps one or two redundant degrees of freedom (elbow swivel, handle roll); they are drawn at
random like an operator does, by starting each solve from a random configuration inside the joint
limits. Damped Gauss-Newton on all pending points in parallel (numpy), with the exact joint
Jacobians of one forward pass of the chain (:func:`arm_model.jacobian.joint_screws`); solutions outside the limits or
pointing the wrong way are rejected and retried from a new random start.

The wrench that deflects the probe is the world-frame contact force rotated into the probe frame
of the current configuration, so it is recomputed at every iteration; at convergence the true
deflected ball centre is on target to ``tol`` [m].
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..effects import Geometry
from ..errors import NumericalError
from ..geometry import cone_directions
from .truth import Truth

__all__ = ["IKTargets", "IKResult", "solve_ik", "solve_points", "solve_positions", "joint_limits",
           "random_q", "wrap_into_limits", "ball_jacobian"]

_L0 = 0.1        # position scale [m] of the residual


@dataclass(frozen=True)
class IKTargets:
    """Per-point targets, base frame.

    Attributes:
        position: (N, 3) deflected ball centre [m].
        stylus: (N, 3) unit direction of the probe z axis (from the flange towards the ball).
        x_dir: (N, 3) unit direction for the probe x axis (perpendicular to ``stylus``), or NaN rows
            where the roll is free.
        force: (N, 3) force the part exerts on the ball [N], base frame.
        torque: (N, 3) torque about the ball centre [N m], base frame.
        temperature: (N,) arm temperature [°C].
        stylus_axis, stylus_cone: (N, 3), (N,) [rad]: the cone the stylus direction was drawn from;
            a point that finds no solution for its direction gets a new one from this cone (the
            operator changes the approach). None: the direction is fixed.
    """
    position: np.ndarray
    stylus: np.ndarray
    x_dir: np.ndarray
    force: np.ndarray
    torque: np.ndarray
    temperature: np.ndarray
    stylus_axis: np.ndarray | None = None
    stylus_cone: np.ndarray | None = None

    def take(self, idx) -> IKTargets:
        return IKTargets(*(None if a is None else a[idx]
                           for a in (self.position, self.stylus, self.x_dir, self.force, self.torque,
                                     self.temperature, self.stylus_axis, self.stylus_cone)))


@dataclass(frozen=True)
class IKResult:
    """q: (N, J) true joint angles [rad]; wrench: (N, 6) probe-frame wrench at the solution;
    attempts: (N,) random starts used; position_error: (N,) [m]; direction_error: (N,) [rad];
    stylus, x_dir: (N, 3) the directions finally used (changed where the first was out of reach)."""
    q: np.ndarray
    wrench: np.ndarray
    attempts: np.ndarray
    position_error: np.ndarray
    direction_error: np.ndarray
    stylus: np.ndarray
    x_dir: np.ndarray


#: the travel [m] taken for a prismatic joint without limits
_FREE_TRAVEL = 0.1


def joint_limits(desc) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) [rad] ([m] for a prismatic joint) of each encoder column; a joint without limits gets
    (-pi, pi) (a prismatic one +-0.1 m)."""
    free = [_FREE_TRAVEL if j.prismatic else np.pi for j in desc.encoders]
    lo = np.array([-f if j.lower is None else j.lower for j, f in zip(desc.encoders, free, strict=True)])
    hi = np.array([f if j.upper is None else j.upper for j, f in zip(desc.encoders, free, strict=True)])
    return lo, hi


def random_q(desc, n: int, rng, margin: float = 0.05) -> np.ndarray:
    """(n, J) joint values uniform within the limits less ``margin`` [rad] (full turns clipped to +-pi; a
    prismatic joint keeps ``margin`` of its travel from each end)."""
    lo, hi = joint_limits(desc)
    prismatic = np.array([j.prismatic for j in desc.encoders])
    gap = np.where(prismatic, margin * (hi - lo), margin)
    lo = np.where(prismatic, lo, np.maximum(lo, -np.pi)) + gap
    hi = np.where(prismatic, hi, np.minimum(hi, np.pi)) - gap
    return rng.uniform(lo, hi, size=(n, desc.n_joints))


def wrap_into_limits(q, lower, upper) -> tuple[np.ndarray, np.ndarray]:
    """Shift each angle by whole turns into [-pi, pi), or else into [lower, upper] where possible;
    returns (q, ok)."""
    q = np.asarray(q, dtype=float)
    q = np.mod(q + np.pi, 2 * np.pi) - np.pi
    for turn in (2 * np.pi, -2 * np.pi):
        q = np.where((q < lower) | (q > upper), np.where(((q + turn) >= lower) & ((q + turn) <= upper),
                                                         q + turn, q), q)
    ok = np.all((q >= lower) & (q <= upper), axis=1)
    return q, ok


def _take_geom(geom: Geometry, idx, reps: int = 1) -> Geometry:
    def t(v):
        if isinstance(v, np.ndarray) and v.ndim == 1:
            return np.tile(v[idx], reps)
        return v
    return Geometry([[t(v) for v in r] for r in geom.rows], [t(v) for v in geom.p_last],
                    [t(v) for v in geom.compliance])


def ball_jacobian(truth: Truth, q, temperature, wrench) -> np.ndarray:
    """(N, 3, J) d ball / d q [m/rad] of the true arm at true angles ``q`` (N, J) with a fixed
    probe-frame ``wrench`` (N, 6) (exact: :meth:`Truth.pose_jacobian`)."""
    return truth.pose_jacobian(q, truth.geometry(temperature), wrench)[3]


def _residual_and_jacobian(truth: Truth, q, geom, tg: IKTargets, has_x):
    """Residual (N, 9) = ((ball - target) / L0, z - stylus, x - x_dir (0 where the roll is free))
    and its exact Jacobian (N, 9, J), the wrench held at its value for q."""
    pos, z, x, jb, jz, jx, w = truth.pose_jacobian(q, geom, load=(tg.force, tg.torque))
    hx = has_x[:, None]
    r = np.concatenate([(pos - tg.position) / _L0, z - tg.stylus,
                        np.where(hx, x - np.nan_to_num(tg.x_dir), 0.0)], axis=1)
    jac = np.concatenate([jb / _L0, jz, np.where(hx[:, :, None], jx, 0.0)], axis=1)
    return r, jac, pos, w


def _solve_batch(truth: Truth, q, tg: IKTargets, tol: float, max_iter: int):
    """Damped Gauss-Newton (Levenberg-Marquardt) from starts ``q``;
    returns (q, converged, wrench, position error [m], direction error)."""
    n, j = q.shape
    geom_all = truth.geometry(tg.temperature)
    has_x = ~np.isnan(tg.x_dir[:, 0])
    q = q.copy()
    done = np.zeros(n, bool)
    wrench = np.zeros((n, 6))
    pos_err = np.full(n, np.inf)
    dir_err = np.full(n, np.inf)
    active = np.arange(n)
    lam = 1e-9
    taken = -1                      # the number of points sub and geom were taken for (active only shrinks)
    for it in range(max_iter):
        if active.size == 0:
            break
        if active.size != taken:
            sub, geom, taken = tg.take(active), _take_geom(geom_all, active), active.size
        r, jac, pos, w = _residual_and_jacobian(truth, q[active], geom, sub, has_x[active])
        pe = np.linalg.norm(pos - sub.position, axis=1)
        de = np.max(np.abs(r[:, 3:]), axis=1)
        conv = (pe < tol) & (de < 1e-12)
        pos_err[active], dir_err[active], wrench[active] = pe, de, w
        done[active[conv]] = True
        keep = ~conv
        if it >= 25:   # a start that is still far away after 25 steps is dropped (a new start is cheaper)
            keep &= np.linalg.norm(r, axis=1) < 1e-5
        active, r, jac = active[keep], r[keep], jac[keep]
        if active.size == 0:
            break
        jt = np.transpose(jac, (0, 2, 1))
        a = jt @ jac + lam * np.eye(j)
        step = -np.linalg.solve(a, (jt @ r[:, :, None]))[:, :, 0]
        norm = np.linalg.norm(step, axis=1, keepdims=True)
        step *= np.minimum(1.0, 0.4 / np.maximum(norm, 1e-300))
        q[active] += step
        bad = ~np.all(np.isfinite(q[active]), axis=1)
        if np.any(bad):
            active = active[~bad]
    return q, done, wrench, pos_err, dir_err


def _redraw(targets: IKTargets, idx, rng) -> IKTargets:
    """New stylus directions (uniform in each point's cone) for the points ``idx``."""
    stylus, x_dir = targets.stylus.copy(), targets.x_dir.copy()
    cone, axis = targets.stylus_cone, targets.stylus_axis
    if cone is None or axis is None:        # no cone: the stylus directions are fixed
        return targets
    for i in idx:
        if cone[i] <= 0:
            continue
        u = cone_directions(rng, axis[i], cone[i], 1)[0]
        stylus[i] = u
        if not np.isnan(x_dir[i, 0]):
            x = x_dir[i] - (x_dir[i] @ u) * u
            x_dir[i] = x / np.linalg.norm(x)
    return IKTargets(targets.position, stylus, x_dir, targets.force, targets.torque, targets.temperature,
                     targets.stylus_axis, targets.stylus_cone)


def solve_ik(truth: Truth, targets: IKTargets, rng: np.random.Generator, tol: float = 1e-12,
             max_attempts: int = 120, max_iter: int = 80, labels=None, redraw_every: int = 5,
             starts=None) -> IKResult:
    """Solve every point from random starts inside the joint limits (see the module docstring).
    After every ``redraw_every`` failed starts a point gets a new stylus direction from its cone.
    ``starts``: optional (N, J) first starts [rad] (NaN rows: random), e.g. articulations found
    without contact force.

    Raises :class:`~arm_model.NumericalError` naming the points (``labels``) that found no valid
    solution in ``max_attempts`` starts (a target out of reach, or a direction the arm cannot take).
    """
    result, pending = solve_points(truth, targets, rng, tol, max_attempts, max_iter, redraw_every, starts)
    if pending.size:
        names = [str(labels[i]) if labels is not None else f"point {i}" for i in pending[:8]]
        raise NumericalError(
            f"inverse kinematics found no solution inside the joint limits for {pending.size} point(s) after "
            f"{max_attempts} random starts: {', '.join(names)}{' ...' if pending.size > 8 else ''}; "
            "the target is probably out of reach: move the artefact closer to the arm")
    return result


def solve_points(truth: Truth, targets: IKTargets, rng: np.random.Generator, tol: float = 1e-12,
                 max_attempts: int = 120, max_iter: int = 80, redraw_every: int = 5, starts=None):
    """Like :func:`solve_ik` but returns (IKResult, indices of the points without a solution)
    instead of raising (their rows of the result are NaN)."""
    desc = truth.nominal
    n, j = len(targets.position), desc.n_joints
    lo, hi = joint_limits(desc)
    span_lo, span_hi = np.maximum(lo, -np.pi), np.minimum(hi, np.pi)
    q_out = np.full((n, j), np.nan)
    w_out = np.zeros((n, 6))
    attempts = np.zeros(n, int)
    pos_err = np.full(n, np.inf)
    dir_err = np.full(n, np.inf)
    pending = np.arange(n)
    for attempt in range(max_attempts):
        if pending.size == 0:
            break
        if attempt and attempt % redraw_every == 0 and targets.stylus_cone is not None:
            targets = _redraw(targets, pending, rng)
        attempts[pending] += 1
        q0 = rng.uniform(span_lo, span_hi, (pending.size, j))
        if attempt == 0 and starts is not None:
            given = np.asarray(starts, dtype=float)[pending]
            q0 = np.where(np.isnan(given[:, :1]), q0, given)
        sub = targets.take(pending)
        q, conv, w, pe, de = _solve_batch(truth, q0, sub, tol, max_iter)
        q, inside = wrap_into_limits(q, lo, hi)
        _, z, x = truth.pose(q, _take_geom(truth.geometry(sub.temperature), np.arange(pending.size)))
        right_way = np.einsum("ni,ni->n", z, sub.stylus) > 0
        has_x = ~np.isnan(sub.x_dir[:, 0])
        right_way &= ~has_x | (np.einsum("ni,ni->n", x, np.nan_to_num(sub.x_dir)) > 0)
        ok = conv & inside & right_way
        idx = pending[ok]
        q_out[idx], w_out[idx], pos_err[idx], dir_err[idx] = q[ok], w[ok], pe[ok], de[ok]
        pending = pending[~ok]
    return IKResult(q_out, w_out, attempts, pos_err, dir_err, targets.stylus, targets.x_dir), pending


def _model_jacobian(model, n: int):
    """CasADi function (q, w, aux, p) -> (ball (3, n), d ball/dq) of the core model, mapped over n points
    (the model's own exact derivatives through every effect)."""
    import casadi as ca

    f = model.casadi_function()
    q, w, aux, p = (ca.SX.sym(nm, f.size1_in(i)) for i, nm in enumerate(("q", "w", "aux", "p")))
    x = f(q, w, aux, p)
    return ca.Function("xq", [q, w, aux, p], [x, ca.jacobian(x, q)]).map(n)


def solve_positions(model, p, targets, rng, force_base=None, tol: float = 1e-12, tries: int = 20,
                    starts: int = 32) -> tuple[np.ndarray, np.ndarray]:
    """Encoder readings that put the deflected ball centre of the core model ``(model, p)`` on
    ``targets`` (n, 3) [m]: the fast path's position-only inverse kinematics.

    Each point starts from the nearest of ``starts`` random poses (the redundancy gives random
    articulations); damped Gauss-Newton with the minimum-norm step on all points at once; a point that
    does not converge or ends outside the joint limits is retried from new starts. ``force_base``
    (n, 3) [N]: the contact force in the base frame, rotated into the probe frame of the current pose
    at every step. Returns (q (n, J) [rad], wrench (n, 6), probe frame); raises
    :class:`~arm_model.NumericalError` for the points not reached in ``tries`` rounds.
    """
    from ..kinematics import probe_rotations
    from ..model import ArmModel, AuxData

    if model.needs() - {"temperature"}:
        raise ValueError("the fast path's inverse kinematics supports effects that need no joint torques")
    targets = np.asarray(targets, dtype=float)
    desc = model.desc
    n, jn = len(targets), desc.n_joints
    lo, hi = joint_limits(desc)
    lo, hi = np.maximum(lo, -np.pi), np.minimum(hi, np.pi)
    aux_t = "temperature" in model.needs()

    def first(idx):            # the nearest of `starts` random poses to each target
        cand = random_q(desc, starts * len(idx), rng)
        xc = model.ball_centres(cand, None, p, AuxData(temperature=np.full(len(cand), 20.0)) if aux_t
                                else None).reshape(len(idx), starts, 3)
        best = np.argmin(np.linalg.norm(xc - targets[idx, None, :], axis=2), axis=1)
        return cand.reshape(len(idx), starts, jn)[np.arange(len(idx)), best]

    q = first(np.arange(n))
    w = np.zeros((n, 6))
    aux = np.zeros((ArmModel.aux_width(jn), n))
    aux[0] = 20.0
    fn = _model_jacobian(model, n)
    todo = np.ones(n, bool)
    for _attempt in range(tries):
        for it in range(100):
            if force_base is not None:
                w[:, :3] = np.einsum("nji,nj->ni", probe_rotations(desc, q, p[: model.base_size]), force_base)
            x, jq = fn(q.T, w.T, aux, p)
            x = np.asarray(x).T
            jq = np.asarray(jq).reshape(3, n, jn).transpose(1, 0, 2)
            e = targets - x
            err = np.linalg.norm(e, axis=1)
            if np.all(err[todo] < tol) and it > 0:
                break
            lam = np.minimum(1e-2, err)[:, None, None] ** 2
            a = jq @ jq.transpose(0, 2, 1) + lam * np.eye(3)
            dq = np.einsum("nji,nj->ni", jq, np.linalg.solve(a, e[:, :, None])[:, :, 0])
            step = np.linalg.norm(dq, axis=1, keepdims=True)
            q = np.where(todo[:, None], q + dq * np.minimum(1.0, 0.5 / np.maximum(step, 1e-300)), q)
        bad = (err > tol) | np.any(q < lo, axis=1) | np.any(q > hi, axis=1)
        if not bad.any():
            return q, w
        q[bad] = first(np.flatnonzero(bad))
        todo = bad
    raise NumericalError(f"inverse kinematics (fast path): {int(bad.sum())} of {n} targets not reached within "
                         "the joint limits")
