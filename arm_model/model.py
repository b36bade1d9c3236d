"""An arm with effects: the base chain plus :mod:`arm_model.effects`, with one parameter vector.

``p = [base errors (arm_model.params order), effect 1 params, effect 2 params, ...]``.
The numpy batch path, the CasADi Function and the Pinocchio evaluation all run the same effect
code (:meth:`ArmModel._evaluate`) and are tested to agree.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from types import SimpleNamespace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .chain import NUMPY_OPS, ball_centre_expr
from .csv_io import label_rows
from .description import ArmDescription
from .effects import ArtefactDrift, Effect, Geometry, ModelInputs
from .params import ParamSpec, apply_params, param_spec, split_params

__all__ = ["ArmModel", "AuxData", "reading_motion", "points_motion", "capture_position", "capture_columns",
           "model_inputs", "CASADI_CACHE", "EQUILIBRIUM_TOL",
           "EQUILIBRIUM_MAX_ITER"]

#: the static equilibrium's tolerance [rad] (m for a prismatic joint): a joint angle's last step
EQUILIBRIUM_TOL = 1e-12
#: its fixed-point passes at most (a sag of 30 mrad converges in about 10)
EQUILIBRIUM_MAX_ITER = 60


@dataclass(frozen=True)
class AuxData:
    """Per-point data some effects need: temperature (N,) [°C], joint torques (N, J) [N m], time (N,) [s], the
    sign of each reading's last move (N, J) [1] (:func:`reading_motion`), each point's place in its measurement's
    capture (N, K) [1] (:func:`capture_columns`)."""
    temperature: np.ndarray | None = None
    tau_gravity: np.ndarray | None = None
    tau_contact: np.ndarray | None = None
    time: np.ndarray | None = None
    motion: np.ndarray | None = None
    capture: np.ndarray | None = None

    def select(self, mask: np.ndarray | slice) -> AuxData:
        return AuxData(*(None if a is None else a[mask] for a in (self.temperature, self.tau_gravity,
                                                                  self.tau_contact, self.time, self.motion,
                                                                  self.capture)))


def capture_position(measurement: ArrayLike, time: ArrayLike | None = None) -> np.ndarray:
    """(N,) each point's place in the capture of its measurement [1], -1/2 at its first point to +1/2 at its last:
    by the time stamps ``time`` (N,) [s] where every point of the measurement has one and they span a time, else by
    the rows' order within the measurement (the capture order: the rows of one measurement keep their file order),
    evenly spaced; 0 for a measurement of one point. The time base of :class:`~arm_model.effects.ArtefactDrift`."""
    meas = np.asarray(measurement)
    t = None if time is None else np.asarray(time, dtype=float)
    out = np.zeros(len(meas))
    for rows in label_rows(meas).values():
        stamps = None if t is None else t[rows]
        if stamps is not None and np.all(np.isfinite(stamps)) and np.ptp(stamps) > 0:
            out[rows] = (stamps - 0.5 * (stamps.min() + stamps.max())) / np.ptp(stamps)
        elif len(rows) > 1:
            out[rows] = np.arange(len(rows)) / (len(rows) - 1) - 0.5
    return out


def capture_columns(measurements: tuple[str, ...], measurement: ArrayLike, time: ArrayLike | None = None
                    ) -> np.ndarray:
    """(N, K) the capture place (:func:`capture_position`) of each point in the column of its measurement, one column
    each of ``measurements`` (K), 0 elsewhere: the ``capture`` input of :class:`~arm_model.effects.ArtefactDrift`."""
    meas = np.asarray(measurement)
    out = np.zeros((len(meas), len(measurements)))
    s = capture_position(meas, time)
    rows = label_rows(meas)
    for k, m in enumerate(measurements):
        if m in rows:
            out[rows[m], k] = s[rows[m]]
    return out


def reading_motion(q: ArrayLike, session: ArrayLike | None = None, time: ArrayLike | None = None) -> np.ndarray:
    """(N, J) the sign (-1, 0, +1) of each joint's move onto each point from the point captured before it: the
    previous point of the same session (``session`` (N,); None: one session) in the order of ``time`` (N,) [s]
    (None or not finite: the rows' order), rows with the same readings as it (one point seen by several markers)
    skipped; 0 for a session's first point. The direction a joint last turned, which a joint's play or an
    encoder's hysteresis follows (:class:`~arm_model.effects.JointHysteresis`). Vectorised: the rows sorted by
    session and time once; each run of equal readings takes the move onto its first row."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    n = len(q)
    t = None if time is None else np.asarray(time, dtype=float)
    key = np.arange(n, dtype=float) if t is None or not np.all(np.isfinite(t)) else t
    code = _session_codes(session, n)
    order = np.lexsort((key, code))                  # by session, then time; stable (rows' order for equal times)
    qs, cs = q[order], code[order]
    first = np.ones(n, bool)                         # a session's first point
    first[1:] = cs[1:] != cs[:-1]
    same = np.zeros(n, bool)                         # the readings of the row before it (==: NaN never the same)
    same[1:] = ~first[1:] & np.all(qs[1:] == qs[:-1], axis=1)
    start = np.maximum.accumulate(np.where(same, 0, np.arange(n)))   # the first row of each run of equal readings
    moved = np.flatnonzero(~same & ~first)
    sorted_out = np.zeros(q.shape)
    sorted_out[moved] = np.sign(qs[moved] - qs[start[moved - 1]])
    out = np.empty(q.shape)
    out[order] = sorted_out[start]
    return out


def points_motion(points: Any, given: np.ndarray | None = None) -> np.ndarray:
    """(N, J) the sign of each joint's last move onto each point of a :class:`~arm_model.io.PointSet`: ``given``
    when the caller has its own (calibration data's ``AuxData.motion``), else the points' own as measured
    (``points.motion``: the columns ``q1_move_sign`` ... of a points file, a live session's from its samples), else
    from the points (:func:`reading_motion` by their session and time). The one rule of the ``motion`` input."""
    if given is not None:
        return given
    own = getattr(points, "motion", None)         # a PointSet's; None on a namespace of q, session and time
    if own is not None:
        return np.asarray(own, dtype=float)
    return reading_motion(points.q, points.session, points.time)


def _session_codes(session: ArrayLike | None, n: int) -> np.ndarray:
    """(N,) an integer a session (the groups of ``==`` on the session values; None: one session)."""
    if session is None:
        return np.zeros(n, dtype=np.intp)
    codes: dict[Any, int] = {}
    return np.fromiter((codes.setdefault(s, len(codes)) for s in np.asarray(session, dtype=object).tolist()),
                       dtype=np.intp, count=n)


@dataclass(frozen=True)
class ArmModel:
    desc: ArmDescription
    effects: tuple[Effect, ...] = ()
    spec: ParamSpec = field(init=False)
    base_size: int = field(init=False)
    _slices: tuple[tuple[Effect, slice], ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not isinstance(self.desc, ArmDescription):
            raise TypeError(f"ArmModel: desc must be an ArmDescription (arm_model.load_description(...)), got "
                            f"{type(self.desc).__name__}")
        if isinstance(self.effects, (str, bytes)) or not isinstance(self.effects, (tuple, list)):
            raise TypeError(f"ArmModel: effects must be a tuple of effects, got {self.effects!r}")
        bad = next((e for e in self.effects if not isinstance(e, Effect)), None)
        if bad is not None:
            hint = " (an instance: call it, e.g. EFFECTS['thermal']())" if isinstance(bad, type) else \
                " (e.g. arm_model.effects.EFFECTS['thermal']())" if isinstance(bad, str) else ""
            raise TypeError(f"ArmModel: every effect must be an arm_model.effects.Effect{hint}, got {bad!r}")
        object.__setattr__(self, "effects", tuple(self.effects))
        base = param_spec(self.desc)
        names, units = list(base.names), list(base.units)
        slices = []
        for e in self.effects:
            defs = e.param_defs(self.desc)
            for n, u in defs:
                if n in names:
                    raise ValueError(f"parameter {n!r} is declared twice (effect {e.describe()})")
                names.append(n)
                units.append(u)
            slices.append((e, slice(len(names) - len(defs), len(names))))
        object.__setattr__(self, "spec", ParamSpec(tuple(names), tuple(units), self.desc.n_joints))
        object.__setattr__(self, "base_size", base.size)
        object.__setattr__(self, "_slices", tuple(slices))

    # -- structure ----------------------------------------------------------------------------
    def with_effects(self, *effects: Effect) -> ArmModel:
        return ArmModel(self.desc, tuple(self.effects) + tuple(effects))

    def needs(self) -> set[str]:
        return {n for e in self.effects for n in e.needs()}

    @property
    def capture_measurements(self) -> tuple[str, ...]:
        """The measurements whose capture place (``AuxData.capture``, one column each, this order) the effects read:
        those of its :class:`~arm_model.effects.ArtefactDrift` (at most one)."""
        drifts = [e for e in self.effects if isinstance(e, ArtefactDrift)]
        if len(drifts) > 1:
            raise ValueError("a model holds one artefact_drift at most (it covers every measurement)")
        return drifts[0].measurements if drifts else ()

    def lower_bounds(self) -> np.ndarray:
        """The smallest physical value [SI] of every parameter (``spec`` order; ``-inf``: none): a compliance
        cannot be negative in total, so the description's probe compliances (``probe.compliance_*``, errors
        added to its own) are at least minus its value and every effect's parameters at least its
        :meth:`~arm_model.effects.Effect.lower_bounds`. The one rule every fit (``calibrate``, the loop's) holds
        its parameters to and the model-file reader checks."""
        low = np.full(self.spec.size, -np.inf)
        probe = self.desc.probe
        for n, v in (("probe.compliance_x", probe.bending_compliance_x),
                     ("probe.compliance_y", probe.bending_compliance_y),
                     ("probe.compliance_z", probe.axial_compliance)):
            if n in self.spec.names:
                low[self.spec.index(n)] = -v
        for e, sl in self.effect_slices():
            low[sl] = e.lower_bounds(self.desc)
        return low

    def effect_slices(self) -> list[tuple[Effect, slice]]:
        """Each effect with the slice of its parameters in ``spec`` (worked out once, with ``spec``)."""
        return list(self._slices)

    # -- the one evaluation -------------------------------------------------------------------
    def _apply_effects(self, p: Any, inputs: ModelInputs, ops: Any) -> Geometry:
        """The geometry of ``p`` with every effect applied; ``inputs`` are modified in place."""
        rows, p_last, compliance = split_params(self.desc, p[: self.base_size] if p is not None else None)
        geom = Geometry([list(r) for r in rows], list(p_last), list(compliance))
        for e, sl in self.effect_slices():
            params = [p[i] for i in range(sl.start, sl.stop)] if p is not None else [0.0] * (sl.stop - sl.start)
            e.apply(self.desc, params, inputs, geom, ops)
        return geom

    def _evaluate(self, p: Any, inputs: ModelInputs, ops: Any) -> tuple[Any, Any, Any]:
        geom = self._apply_effects(p, inputs, ops)
        return ball_centre_expr(self.desc.convention, geom.rows, geom.p_last, geom.compliance,
                                inputs.q, inputs.wrench, ops, self.desc.chain_joints,
                                self.desc.probe.rotation, self.desc.probe.lever)

    def _check_aux(self, aux: AuxData | None, n: int) -> AuxData:
        aux = aux or AuxData()
        for name in self.needs():
            v = getattr(aux, name)
            if v is None:
                raise ValueError(f"the model's effects need per-point '{name}' (effects: "
                                 f"{', '.join(e.describe() for e in self.effects)})")
            if len(v) != n:
                raise ValueError(f"'{name}' has {len(v)} rows, q has {n}")
        return aux

    # -- numpy batch ----------------------------------------------------------------------------
    def ball_centres(self, q: ArrayLike, wrench: ArrayLike | None = None, p: ArrayLike | None = None,
                     aux: AuxData | None = None) -> np.ndarray:
        """(N, 3) deflection-aware ball centres [m]; ``p`` of size ``spec.size`` (None: zeros)."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        n = q.shape[0]
        aux = self._check_aux(aux, n)
        pv = None if p is None else np.asarray(p, dtype=float)
        if pv is not None and pv.shape != (self.spec.size,):
            raise ValueError(f"p has shape {pv.shape}, expected ({self.spec.size},)")
        if not self.effects:
            from .kinematics import ball_centres
            return ball_centres(self.desc, q, wrench, pv)
        w = _six_columns(wrench, n)
        out = np.empty((n, 3))
        chunk = 16384
        for s in range(0, n, chunk):
            e = min(s + chunk, n)
            x, y, z = self._evaluate(pv, model_inputs(q, aux, w, slice(s, e)), NUMPY_OPS)
            out[s:e, 0], out[s:e, 1], out[s:e, 2] = x, y, z
        return out

    def joint_angles(self, q: ArrayLike, wrench: ArrayLike | None = None, p: ArrayLike | None = None,
                     aux: AuxData | None = None) -> np.ndarray:
        """(N, J) the angles [rad] (lengths [m] of a prismatic joint) the joints take: the readings ``q`` with every
        effect on them applied (eccentricity, gain, harmonics, compliance under ``aux``'s torques), in the model's
        order, by the batch path's own effect code."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        n = q.shape[0]
        aux = self._check_aux(aux, n)
        inputs = model_inputs(q, aux, _six_columns(wrench, n))
        self._apply_effects(None if p is None else np.asarray(p, dtype=float), inputs, NUMPY_OPS)
        return np.column_stack([np.broadcast_to(np.asarray(c, dtype=float), (n,)) for c in inputs.q])

    def equilibrium_aux(self, q: ArrayLike, wrench: ArrayLike | None = None, p: ArrayLike | None = None,
                        temperature: ArrayLike | None = None, *, contact: bool = True, tol: float = EQUILIBRIUM_TOL,
                        max_iter: int = EQUILIBRIUM_MAX_ITER, time: ArrayLike | None = None,
                        motion: ArrayLike | None = None, capture: ArrayLike | None = None) -> AuxData:
        """The per-point inputs at the static equilibrium the arm sits in: gravity and contact torques [N m] at
        the angles ``theta`` the joints take, not at the readings ``q``:
        ``theta = F(q) + C (tau_contact(theta) - tau_gravity(theta))`` (``F``: the other effects on the readings,
        ``C``: the joint compliances of ``p``; the wrench ``wrench`` (N, 3|6) [N, N m] stays in the probe frame;
        ``contact=False``: no contact torques). The torques are Pinocchio's RNEA on the description of ``p``
        (:meth:`described`, the description's masses); ``temperature`` (N,) [°C], ``time`` (N,) [s] and ``motion``
        (N, J) (:func:`reading_motion`) and ``capture`` (N, K) (:func:`capture_columns`) where an effect needs them.

        Solved by fixed-point iteration from ``theta = q`` until ``theta`` moves less than ``tol`` [rad] (or m):
        one pass (the torques at the readings) when no compliance turns a joint, a few for a sag of a few mrad
        (each pass shrinks the error by about C dtau/dtheta, the sag's own relative change). The iteration
        converges while the arm is stable under its load (C dtau/dtheta < 1); otherwise, or after ``max_iter``
        passes, a :class:`~arm_model.errors.NumericalError`. A joint with a play closed by gravity
        (:class:`~arm_model.effects.JointBacklash`) whose gravity torque changes sign within its play has no side to
        rest on (the torque's sign flips back and forth between passes): it floats in the middle of its play, its
        gravity torque taken as nil at that point."""
        from .errors import NumericalError
        from .pinocchio_model import PinocchioArm

        q = np.atleast_2d(np.asarray(q, dtype=float))
        temp = None if temperature is None else np.asarray(temperature, dtype=float)
        stamps = None if time is None else np.asarray(time, dtype=float)
        moves = None if motion is None else np.asarray(motion, dtype=float)
        places = None if capture is None else np.asarray(capture, dtype=float)
        arm = PinocchioArm(self.described(np.zeros(self.spec.size) if p is None else p))
        w = None if wrench is None or not contact else np.atleast_2d(np.asarray(wrench, dtype=float))
        theta, step = q, np.inf
        play = self._gravity_play_joints(p)
        floating = np.zeros(q.shape, dtype=bool)
        seen: list[np.ndarray] = []
        for _ in range(max_iter):
            tau_g, tau_c = arm.torques(theta, w)
            if play.size:
                # a play closed by gravity whose torque turns within the play: the torque's sign flips back and forth
                # between passes (+, -, +) and the joint has no side to rest on; it floats, its load nil
                side = np.sign(tau_g[:, play])
                if len(seen) == 2:
                    floating[:, play] |= (side != 0) & (side == seen[0]) & (side != seen[1])
                seen = [*seen[-1:], side]
                tau_g = np.where(floating, 0.0, tau_g)
            aux = AuxData(temp, tau_g, tau_c, stamps, moves, places)
            new = self.joint_angles(q, wrench, p, aux)
            step = float(np.max(np.abs(new - theta), initial=0.0))
            theta = new
            if step <= tol:
                return aux
        raise NumericalError(f"the arm's static equilibrium under its load was not found: the joint angles still "
                             f"moved by {step:.3g} after {max_iter} passes (is a joint compliance so large that the "
                             "arm buckles under its own weight?)")

    def _gravity_play_joints(self, p: ArrayLike | None) -> np.ndarray:
        """The joints a :class:`~arm_model.effects.JointBacklash` of ``p`` turns (a play closed by gravity)."""
        from .effects import JointBacklash

        values = np.zeros(self.spec.size) if p is None else np.asarray(p, dtype=float)
        out = [i for e, sl in self._slices if isinstance(e, JointBacklash)
               for i, b in zip(e.joint_indices(self.desc), values[sl], strict=True) if b != 0.0]
        return np.array(sorted(set(out)), dtype=np.intp)

    # -- CasADi -------------------------------------------------------------------------------
    def casadi_function(self, name: str = "ball_centre") -> Any:
        """``f(q[J], w[6], aux[2 + 3J + K], p[P]) -> p_base[3]`` with aux = (temperature [°C],
        tau_gravity[J], tau_contact[J], time [s], motion[J], capture[K]) (:meth:`aux_width`, K the
        :attr:`capture_measurements`; zeros where no effect needs them).

        Built once for equal models (same description and effects; the model is immutable) and name: building
        the expression graph costs more than a calibration's evaluations of it (:func:`_casadi_function`)."""
        try:
            hash(self)
        except TypeError:           # an effect that cannot be hashed (a user's mutable one): built each time
            return self._build_casadi_function(name)
        return _casadi_function(self, name)

    def _build_casadi_function(self, name: str) -> Any:
        import casadi as ca

        j = self.desc.n_joints
        q = ca.SX.sym("q", j)
        w = ca.SX.sym("w", 6)
        k = len(self.capture_measurements)
        aux = ca.SX.sym("aux", self.aux_width(j, k))
        p = ca.SX.sym("p", self.spec.size)
        inputs = ModelInputs(q=[q[i] for i in range(j)], wrench=[w[i] for i in range(6)],
                             temperature=aux[0], tau_gravity=[aux[1 + i] for i in range(j)],
                             tau_contact=[aux[1 + j + i] for i in range(j)], time=aux[1 + 2 * j],
                             motion=[aux[2 + 2 * j + i] for i in range(j)],
                             capture=[aux[2 + 3 * j + i] for i in range(k)])
        x, y, z = self._evaluate(p, inputs, SimpleNamespace(sin=ca.sin, cos=ca.cos, sign=ca.sign))
        return ca.Function(name, [q, w, aux, p], [ca.vertcat(x, y, z)], ["q", "w", "aux", "p"], ["p_base"])

    @staticmethod
    def aux_width(n_joints: int, n_capture: int = 0) -> int:
        """The length of :meth:`casadi_function`'s aux input: temperature, J + J torques, time, J motions, K capture
        places."""
        return 2 + 3 * n_joints + n_capture

    @staticmethod
    def aux_matrix(aux: AuxData | None, n: int, n_joints: int, n_capture: int = 0) -> np.ndarray:
        """(N, :meth:`aux_width`) aux rows for :meth:`casadi_function` (zeros where absent)."""
        m = np.zeros((n, ArmModel.aux_width(n_joints, n_capture)))
        if aux is not None:
            if aux.temperature is not None:
                m[:, 0] = aux.temperature
            if aux.tau_gravity is not None:
                m[:, 1:1 + n_joints] = aux.tau_gravity
            if aux.tau_contact is not None:
                m[:, 1 + n_joints:1 + 2 * n_joints] = aux.tau_contact
            if aux.time is not None:
                m[:, 1 + 2 * n_joints] = aux.time
            if aux.motion is not None:
                m[:, 2 + 2 * n_joints:2 + 3 * n_joints] = aux.motion
            if aux.capture is not None and n_capture:
                m[:, 2 + 3 * n_joints:] = aux.capture
        return m

    # -- Pinocchio ------------------------------------------------------------------------------
    def pinocchio_ball_centre(self, q: ArrayLike, wrench: ArrayLike | None = None, p: ArrayLike | None = None,
                              aux_row: dict[str, Any] | None = None) -> np.ndarray:
        """One point through Pinocchio: the effects transform the inputs and geometry (same code),
        Pinocchio evaluates the chain of the resulting description."""
        from .pinocchio_model import PinocchioArm

        j = self.desc.n_joints
        pv = np.zeros(self.spec.size) if p is None else np.asarray(p, dtype=float)
        w = np.zeros(6)
        if wrench is not None:
            wr = np.asarray(wrench, dtype=float)
            w[: len(wr)] = wr
        aux_row = aux_row or {}
        inputs = ModelInputs(q=[float(v) for v in np.asarray(q, dtype=float)], wrench=[float(v) for v in w],
                             temperature=aux_row.get("temperature"),
                             tau_gravity=None if aux_row.get("tau_gravity") is None else list(aux_row["tau_gravity"]),
                             tau_contact=None if aux_row.get("tau_contact") is None else list(aux_row["tau_contact"]),
                             time=aux_row.get("time"),
                             motion=None if aux_row.get("motion") is None else list(aux_row["motion"]),
                             capture=None if aux_row.get("capture") is None else list(aux_row["capture"]))
        inputs.moments = lambda geom, q, i, origin: self._pinocchio_moments(geom, q, i, origin, inputs.wrench)
        geom = self._apply_effects([float(v) for v in pv], inputs, NUMPY_OPS)
        arm = PinocchioArm(self._geometry_description(geom))
        centre: np.ndarray = arm.ball_centre(np.array(inputs.q, dtype=float)[:j], np.array(inputs.wrench, dtype=float))
        return centre

    def _geometry_description(self, geom: Geometry) -> ArmDescription:
        return self.desc.with_row_table(np.array(geom.rows, dtype=float)).with_probe(
            p_last=tuple(float(v) for v in geom.p_last), bending_compliance_x=float(geom.compliance[0]),
            bending_compliance_y=float(geom.compliance[1]), axial_compliance=float(geom.compliance[2]))

    def _pinocchio_moments(self, geom: Geometry, q: Any, i: int, origin: ArrayLike,
                           wrench: Any) -> tuple[np.ndarray, np.ndarray]:
        """(M_gravity, M_contact) [N m], base frame, about ``origin``: the wrench that gravity on the links
        joint ``i`` moves, and the contact wrench at the (rigid) ball, put on them, from Pinocchio's RNEA
        (the spatial force its joint transmits, in equilibrium with them)."""
        from .pinocchio_model import PinocchioArm

        arm = PinocchioArm(self._geometry_description(geom))
        pin, model, data = arm._pin, arm.model, arm.data
        x = arm.full_q(np.array([float(v) for v in q[: self.desc.n_joints]]))
        zero = np.zeros(model.nv)
        pin.forwardKinematics(model, data, x)
        jid = model.getJointId(self.desc.joints[i].name)
        out = []
        frame = model.frames[arm.ball_id]
        parent = frame.parentJoint if hasattr(frame, "parentJoint") else frame.parent
        w = np.array([float(v) for v in wrench], dtype=float)
        for part in ("gravity", "contact"):
            if part == "gravity":
                pin.rnea(model, data, x, zero, zero)
            else:
                model.gravity.linear = np.zeros(3)
                fext = [pin.Force.Zero() for _ in range(model.njoints)]
                fext[parent] = frame.placement.act(pin.Force(w[:3], w[3:]))
                pin.rnea(model, data, x, zero, zero, fext)
            f, o_m_i = data.f[jid], data.oMi[jid]
            force = -(o_m_i.rotation @ f.linear)             # what gravity / contact put on the subtree
            moment = -(o_m_i.rotation @ f.angular) + np.cross(o_m_i.translation - np.asarray(origin, float), force)
            out.append(moment)
        return out[0], out[1]

    def described(self, p: ArrayLike) -> ArmDescription:
        """The description with the base part of ``p`` folded in (effects are not representable)."""
        return apply_params(self.desc, np.asarray(p, dtype=float)[: self.base_size])


def _six_columns(wrench: ArrayLike | None, n: int) -> np.ndarray:
    """(N, 6) wrench rows (force [N], torque [N m]; zeros where absent) of a (N, 3|6) wrench or None."""
    w = np.zeros((n, 6))
    if wrench is not None:
        wr = np.atleast_2d(np.asarray(wrench, dtype=float))
        w[:, : wr.shape[1]] = wr
    return w


def model_inputs(q: np.ndarray, aux: AuxData | None, wrench: np.ndarray | None = None, rows: slice = slice(None), *,
                 nil_load: float | None = None, time: np.ndarray | None = None,
                 motion: np.ndarray | None = None) -> ModelInputs:
    """The per-point inputs (numpy columns) the effects read, of the rows ``rows``: the readings ``q`` (N, J) [rad, m],
    the ``wrench`` (N, 6) [N, N m] (None: nil, one 0 a component), and ``aux``'s temperature, torques, time, last
    moves and capture places. The one place that builds them: the batch path (:meth:`ArmModel.ball_centres`) and,
    with its options, the prior's reading of the data (:func:`calibration.prior.prior_only`, the effects' prior
    sizes):

    - ``nil_load``: a gravity torque at most this fraction of the largest in the rows is 0, its sign rounding (a
      vertical axis holds none);
    - ``time``, ``motion``: used where ``aux`` has none (the points' own time stamps and last moves)."""
    a = AuxData() if aux is None else aux
    tau = a.tau_gravity
    if tau is not None and nil_load is not None:
        tau = np.array(tau[rows], dtype=float)
        tau[np.abs(tau) <= nil_load * np.max(np.abs(tau), initial=0.0)] = 0.0
    elif tau is not None:
        tau = tau[rows]
    t = a.time if a.time is not None else time
    m = a.motion if a.motion is not None else motion
    return ModelInputs(q=list(q[rows].T), wrench=[0.0] * 6 if wrench is None else list(wrench[rows].T),
                       temperature=None if a.temperature is None else a.temperature[rows],
                       tau_gravity=None if tau is None else list(tau.T),
                       tau_contact=None if a.tau_contact is None else list(a.tau_contact[rows].T),
                       time=None if t is None else np.asarray(t, dtype=float)[rows],
                       motion=None if m is None else list(np.asarray(m, dtype=float)[rows].T),
                       capture=None if a.capture is None else list(a.capture[rows].T))


#: models whose CasADi Function is kept (a loop compares a few models at a time, each many times)
CASADI_CACHE = 32


@lru_cache(maxsize=CASADI_CACHE)
def _casadi_function(model: ArmModel, name: str) -> Any:
    """:meth:`ArmModel.casadi_function`, built once for equal models (the least recently used dropped first)."""
    return model._build_casadi_function(name)
