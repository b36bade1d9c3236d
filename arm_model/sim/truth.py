"""The hidden truth: the true arm = nominal description + parameter errors + effects.

The truth is an :class:`arm_model.model.ArmModel` (the core's effect library) with a true parameter
vector ``p``, so the analysis side and the simulator share one physics. The core effects map
encoder readings to true joint angles, ``q_true = F(q_enc; tau)``; the simulator solves its
inverse kinematics for the *true* angles and inverts ``F`` by fixed-point iteration to write
readings. Physics the core library does not hold (force-sensor cross-talk, encoder quantisation,
probing repeatability) lives in :mod:`arm_model.sim` only.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..chain import NUMPY_OPS, ball_in_last_frame, chain_point, cross, elastic_displacement, has_stylus, probe_lever
from ..description import ArmDescription
from ..effects import (
    ApproachOffset,
    EncoderEccentricity,
    ForceSensorError,
    Geometry,
    JointCompliance,
    JointHarmonics,
    LateralCompliance,
    ModelInputs,
    ProbeComplianceMatrix,
    ProbeThermalGrowth,
    ThermalGrowth,
)
from ..errors import NumericalError
from ..model import ArmModel, AuxData
from ..params import apply_params, param_spec

__all__ = ["Truth", "build_truth", "si_key", "POSE_EFFECTS", "probe_wrench"]

#: effects whose change of the geometry depends on the pose and the wrench (applied by :meth:`Truth.pose` at
#: the true angles, not by :meth:`Truth.geometry`)
POSE_EFFECTS = (LateralCompliance, ProbeComplianceMatrix, ApproachOffset)

#: SI unit of a parameter -> key suffix used in truth.toml
_SUFFIX = {"m": "m", "rad": "rad", "m/N": "m_per_N", "rad/(N m)": "rad_per_Nm", "1/K": "per_K",
           "1": "ratio", "N": "N"}


def si_key(name: str, unit: str) -> str:
    """``("j2.d", "m") -> "j2.d_m"``: a parameter name with its SI unit as a key suffix."""
    return f"{name}_{_SUFFIX.get(unit, unit.replace('/', '_per_').replace(' ', ''))}"


def probe_wrench(force, torque, z, x) -> np.ndarray:
    """(N, 6) wrench in the probe frame from base-frame force/torque and the probe axes."""
    y = cross(z, x)
    r = np.stack([x, y, z], axis=1)           # rows: probe axes in base -> R_probe_base
    return np.concatenate([np.einsum("nij,nj->ni", r, force), np.einsum("nij,nj->ni", r, torque)], axis=1)


@dataclass(frozen=True)
class Truth:
    """The true arm.

    Attributes:
        model: nominal description + the effects that are on (core effect library).
        p: (P,) true parameter vector of ``model.spec`` (SI): base errors, then effect parameters.
        cross_talk: (3, 3) force-sensor cross-talk (simulator only): ``f_meas += K f_true``.
        force_gain, force_offset: (3,) [1], [N] sensor gain errors and offsets per probe axis
            (also in ``p`` when the force-sensor effect is on).
        settings: the effects as the campaign gave them (for the truth file).
    """
    model: ArmModel
    p: np.ndarray
    cross_talk: np.ndarray
    force_gain: np.ndarray
    force_offset: np.ndarray
    settings: dict = field(default_factory=dict)

    # -- views ------------------------------------------------------------------------------------
    @property
    def nominal(self) -> ArmDescription:
        return self.model.desc

    @property
    def values(self) -> dict[str, float]:
        """True parameters by name (SI, see ``model.spec.units``)."""
        return dict(zip(self.model.spec.names, (float(v) for v in self.p), strict=True))

    @property
    def aliases(self) -> dict[str, float]:
        """The same true quantities under the names of effects the truth does not use, for analyses
        that model them that way: the probe compliance errors as the core ``ProbeCompliance``
        parameters (``probe.dcompliance_bend`` only when isotropic)."""
        dx, dy, dz = self.p[self.model.base_size - 3: self.model.base_size]
        out = {"probe.dcompliance_x": float(dx), "probe.dcompliance_y": float(dy), "probe.dcompliance_z": float(dz)}
        if dx == dy:
            out["probe.dcompliance_bend"] = float(dx)
        return out

    @property
    def description(self) -> ArmDescription:
        """The nominal description with the true base errors folded in (no effects)."""
        return apply_params(self.nominal, self.p[: self.model.base_size])

    def effects_on(self) -> list[str]:
        out = [e.describe() for e in self.model.effects]
        dc = self.p[self.model.base_size - 3: self.model.base_size]
        if np.any(dc):
            out.append("probe_compliance (" + ("isotropic" if dc[0] == dc[1] else "anisotropic")
                       + (", axial" if dc[2] else "") + ")")
        if np.any(self.cross_talk):
            out.append("force_sensor.cross_talk (simulator only)")
        return out

    # -- geometry and poses -------------------------------------------------------------------------
    def geometry(self, temperature) -> Geometry:
        """True geometry (rows, probe point, compliance) at the temperatures ``temperature`` (N,)
        [°C]: the base errors and every effect that acts on the geometry (thermal growth, probe
        compliance), run through the core's effect code. Entries are floats or (N,) columns. Effects that
        depend on the pose (:data:`POSE_EFFECTS`) are left to :meth:`pose`."""
        from ..params import split_params

        t = np.atleast_1d(np.asarray(temperature, dtype=float))
        n, j = len(t), self.nominal.n_joints
        rows, p_last, comp = split_params(self.nominal, self.p[: self.model.base_size])
        geom = Geometry([list(r) for r in rows], list(p_last), list(comp))
        zeros = np.zeros(n)
        inputs = ModelInputs(q=[zeros] * j, wrench=[zeros] * 6, temperature=t,
                             tau_gravity=[zeros] * j, tau_contact=[zeros] * j)
        for e, sl in self.model.effect_slices():
            if not isinstance(e, POSE_EFFECTS):
                e.apply(self.nominal, [float(v) for v in self.p[sl]], inputs, geom, NUMPY_OPS)
        return geom

    def _pose_geometry(self, q, geom: Geometry, wrench) -> Geometry:
        """``geom`` with the pose-dependent effects (:data:`POSE_EFFECTS`) applied at the true angles ``q``
        (N, J) and the true ``wrench`` (N, 6), in the model's order (a copy). Their derivative (a micrometre shift's) is
        left out of the inverse kinematics' Newton steps (:meth:`pose_jacobian`), which only slows convergence
        negligibly."""
        pose_effects = [(e, sl) for e, sl in self.model.effect_slices() if isinstance(e, POSE_EFFECTS)]
        if not pose_effects:
            return geom
        out = Geometry([list(r) for r in geom.rows], list(geom.p_last), list(geom.compliance))
        inputs = ModelInputs(q=list(np.asarray(q).T), wrench=list(np.asarray(wrench).T))
        for e, sl in pose_effects:
            e.apply(self.nominal, [float(v) for v in self.p[sl]], inputs, out, NUMPY_OPS)
        return out

    def pose(self, q, geom: Geometry, wrench=None):
        """Ball centre and flange axes at the TRUE joint angles ``q`` (N, J) [rad] with a fixed
        ``wrench`` (N, 6) (probe frame).

        Returns (ball (N, 3) [m], z axis (N, 3), x axis (N, 3)) in the base frame; the axes are
        those of the probe frame (undeflected). The effects that depend on the pose (:data:`POSE_EFFECTS`)
        move the ball when a ``wrench`` is given (without one, the ball is neither deflected nor moved).
        """
        d = self.nominal
        q = np.asarray(q)
        n = q.shape[0]
        if wrench is not None:
            geom = self._pose_geometry(q, geom, wrench)
        rot, lever = d.probe.rotation, d.probe.lever
        if wrench is None or not has_stylus(lever):        # no stylus: nothing bends
            qe = (0.0, 0.0, 0.0)
        else:
            qe = elastic_displacement(geom.p_last, geom.compliance, list(np.asarray(wrench).T),
                                      probe_lever(geom.p_last, rot, lever))
        bx, by, bz = (np.broadcast_to(c, (n,)) for c in ball_in_last_frame(geom.p_last, qe, NUMPY_OPS, rot, lever))
        # one pass of the chain for four points: ball, origin, origin + probe z, origin + probe x
        zero = np.zeros(n)
        rm = np.eye(3) if rot is None else np.array(rot)
        pts = tuple(np.concatenate([b, zero, zero + rm[k, 2], zero + rm[k, 0]]) for k, b in enumerate((bx, by, bz)))
        rows = [[np.tile(v, 4) if isinstance(v, np.ndarray) else v for v in r] for r in geom.rows]
        x, y, z = chain_point(d.convention, rows, list(np.tile(q, (4, 1)).T), pts, NUMPY_OPS, d.chain_joints)
        p = np.column_stack([x, y, z]).reshape(4, n, 3)
        return p[0], p[2] - p[1], p[3] - p[1]

    def pose_jacobian(self, q, geom: Geometry, wrench=None, load=None):
        """:meth:`pose` and its exact Jacobians with respect to the true joint angles ``q`` (N, J) [rad]
        (:func:`arm_model.jacobian.joint_screws`: one forward pass, the wrench held fixed; the shift of the
        pose-dependent effects, :data:`POSE_EFFECTS`, is in the ball, its own derivative is not).

        ``wrench``: (N, 6) fixed probe-frame wrench, or ``load``: (force (N, 3) [N], torque (N, 3) [N m])
        in the base frame, rotated into the probe frame of this pose. Returns (ball (N, 3) [m],
        z (N, 3), x (N, 3), d ball/dq (N, 3, J) [m/rad], dz/dq, dx/dq (N, 3, J) [1/rad], wrench (N, 6)).
        """
        from ..jacobian import direction_jacobian, joint_screws, point_jacobian

        d = self.nominal
        q = np.asarray(q, dtype=float)
        n = q.shape[0]
        rot, lever = d.probe.rotation, d.probe.lever
        r, o, u, c = joint_screws(d.convention, geom.rows, q, d.chain_joints)
        rm = np.eye(3) if rot is None else np.array(rot, dtype=float)
        z, x = r @ rm[:, 2], r @ rm[:, 0]
        if load is not None:
            wrench = probe_wrench(load[0], load[1], z, x)
        if wrench is None or not has_stylus(lever):
            qe = (0.0, 0.0, 0.0)
        else:
            geom = self._pose_geometry(q, geom, wrench)      # their own derivative left out, as in pose
            qe = elastic_displacement(geom.p_last, geom.compliance, list(np.asarray(wrench).T),
                                      probe_lever(geom.p_last, rot, lever))
        b = np.column_stack([np.broadcast_to(v, (n,))
                             for v in ball_in_last_frame(geom.p_last, qe, NUMPY_OPS, rot, lever)])
        ball = o + np.einsum("nij,nj->ni", r, b)
        w = np.zeros((n, 6)) if wrench is None else np.asarray(wrench, dtype=float)
        jn, nq = d.chain_joints, d.n_joints
        return (ball, z, x, point_jacobian(u, c, ball, jn, nq), direction_jacobian(u, z, jn, nq),
                direction_jacobian(u, x, jn, nq), w)

    def rotation(self, q, temperature) -> np.ndarray:
        """(N, 3, 3) rotation R_base_probe (columns: probe x, y, z in the base frame) at true angles."""
        _, z, x = self.pose(q, self.geometry(temperature))
        y = np.cross(z, x)
        return np.stack([x, y, z], axis=2)

    # -- joint readings -----------------------------------------------------------------------------
    def aux(self, temperature, tau_gravity=None, tau_contact=None) -> AuxData:
        n = len(temperature)
        j = self.nominal.n_joints
        return AuxData(np.asarray(temperature, float),
                       np.zeros((n, j)) if tau_gravity is None else tau_gravity,
                       np.zeros((n, j)) if tau_contact is None else tau_contact)

    def true_angles(self, q_enc, aux: AuxData) -> np.ndarray:
        """The core's forward map of the readings: q_true = F(q_enc; temperature, tau) (N, J) [rad]."""
        q_enc = np.atleast_2d(np.asarray(q_enc, dtype=float))
        n, j = q_enc.shape
        rows = [list(r) for r in self.nominal.row_table()]
        geom = Geometry(rows, list(self.nominal.probe.p_last), list(self.nominal.probe.compliance))
        inputs = ModelInputs(q=list(q_enc.T), wrench=[np.zeros(n)] * 6, temperature=aux.temperature,
                             tau_gravity=None if aux.tau_gravity is None else list(aux.tau_gravity.T),
                             tau_contact=None if aux.tau_contact is None else list(aux.tau_contact.T))
        for e, sl in self.model.effect_slices():
            if not isinstance(e, POSE_EFFECTS):         # they move the ball, not the joints
                e.apply(self.nominal, [float(v) for v in self.p[sl]], inputs, geom, NUMPY_OPS)
        return np.column_stack([np.broadcast_to(np.asarray(c, dtype=float), (n,)) for c in inputs.q])

    def encoder_readings(self, q_true, aux: AuxData, tol: float = 1e-13, max_iter: int = 100) -> np.ndarray:
        """Invert :meth:`true_angles`: readings q_enc with F(q_enc) = q_true to ``tol`` [rad]
        (fixed-point iteration; the result is checked by re-applying the forward map)."""
        q_true = np.atleast_2d(np.asarray(q_true, dtype=float))
        q = q_true.copy()
        for _ in range(max_iter):
            err = self.true_angles(q, aux) - q_true
            if np.max(np.abs(err), initial=0.0) < tol:
                return q
            q = q - err
        worst = float(np.max(np.abs(self.true_angles(q, aux) - q_true)))
        raise NumericalError(f"encoder-reading inversion did not converge: {worst:.3g} rad after {max_iter} "
                             "iterations (are the eccentricity or joint-compliance parameters too large?)")

    def torques(self, q_true, wrench) -> tuple[np.ndarray, np.ndarray]:
        """Physical (tau_gravity, tau_contact) (N, J) [N m] at the true angles, through Pinocchio on the
        true description (signs of :mod:`arm_model.effects`)."""
        from ..pinocchio_model import PinocchioArm

        return PinocchioArm(self.description).torques(q_true, wrench)

    def needs_torques(self) -> bool:
        return any(isinstance(e, JointCompliance) for e in self.model.effects)

    # -- the force sensor -------------------------------------------------------------------------
    def sensor_reading(self, force) -> np.ndarray:
        """Noise-free reading (N, 3) [N] of a true force (N, 3) [N], probe frame:
        ``(1 + gain) f + offset + cross_talk f``."""
        f = np.asarray(force, dtype=float)
        return f * (1.0 + self.force_gain) + self.force_offset + f @ self.cross_talk.T


def _random_base(rng, desc: ArmDescription, t: dict) -> np.ndarray:
    spec = param_spec(desc)
    p = np.zeros(spec.size)
    m, rows = len(desc.row_fields), len(desc.joints)
    for i in range(rows):
        for k, unit in enumerate(spec.units[m * i: m * (i + 1)]):
            sigma = t["length_error"] if unit == "m" else t["angle_error"]
            p[m * i + k] = rng.normal(0.0, sigma)
    for k in range(3):
        p[m * rows + k] = rng.normal(0.0, t["probe_error"])
    for name, value in t["errors"].items():
        p[spec.index(name)] = value
    return p


def build_truth(desc: ArmDescription, t: dict, rng: np.random.Generator, sensor: str = "xyz") -> Truth:
    """The true arm from a campaign's ``truth`` section (SI, see :mod:`arm_model.sim.campaign`):
    random base errors of the given sizes (explicit ``errors`` override them); a true probe
    compliance sets the base parameters ``probe.compliance_x/_y/_z`` (true minus declared); then each
    effect that is on, in a fixed order: eccentricity, joint harmonics, joint compliance, thermal growth,
    force sensor (on the axes the ``sensor`` measures: x and z for the two-channel one), then the effects
    that depend on the pose (:data:`POSE_EFFECTS`): lateral compliance, the probe compliance's coupling
    terms (core ``ProbeComplianceMatrix``, off-diagonal), approach offset."""
    p_base = _random_base(rng, desc, t)
    effects, values = [], []
    settings = {}
    if t["eccentricity"]:
        rows = sorted(t["eccentricity"], key=lambda r: r["index"])
        effects.append(EncoderEccentricity(joints=tuple(r["index"] for r in rows), harmonics=(1, 2)))
        for r in rows:   # a sin(h q + phi) = a sin(phi) cos(h q) + a cos(phi) sin(h q)
            for a, phi in ((r["amplitude"], r["phase"]), (r["amplitude2"], r["phase2"])):
                values += [a * np.sin(phi), a * np.cos(phi)]
        settings["eccentricity"] = [{k: r[k] for k in ("joint", "amplitude", "phase", "amplitude2", "phase2")}
                                    for r in rows]
    for r in t.get("harmonics", ()):
        effects.append(JointHarmonics(joints=(r["index"],), source=r["source"], harmonics=(r["harmonic"],)))
        values += [r["amplitude"] * np.sin(r["phase"]), r["amplitude"] * np.cos(r["phase"])]
        settings.setdefault("harmonics", []).append(
            {"joint": desc.joint_names[r["index"]], "of": desc.joint_names[r["index"] if r["source"] is None
                                                                           else r["source"]],
             "harmonic": r["harmonic"], "amplitude": r["amplitude"], "phase": r["phase"]})
    jc = t["joint_compliance"]
    if jc is not None:
        effects.append(JointCompliance(joints=jc["indices"], gravity=jc["gravity"], contact=jc["contact"]))
        values += [1.0 / k for k in jc["stiffness"]]
        settings["joint_compliance"] = {"joints": [desc.joint_names[i] for i in jc["indices"]],
                                        "stiffness": list(jc["stiffness"]), "gravity": jc["gravity"],
                                        "contact": jc["contact"]}
    th = t["thermal"]
    if th is not None:
        per_joint = len(set(th["alpha"])) > 1
        idx = th["indices"]
        effects.append(ThermalGrowth(joints=None if idx == tuple(range(desc.n_joints)) else idx,
                                     per_joint=per_joint))
        values += list(th["alpha"]) if per_joint else [th["alpha"][0]]
        settings["thermal"] = {"joints": [desc.joint_names[i] for i in idx], "alpha": list(th["alpha"])}
        if th.get("probe_alpha"):
            effects.append(ProbeThermalGrowth())
            values.append(th["probe_alpha"])
            settings["thermal"]["probe_alpha"] = th["probe_alpha"]  # type: ignore[call-overload]
    pc = t["probe_compliance"]
    if pc is not None:
        declared = desc.probe.compliance
        cx = pc["bending_x"] if pc["bending_x"] is not None else pc["bending"]
        cy = pc["bending_y"] if pc["bending_y"] is not None else pc["bending"]
        cx = declared[0] if cx is None else cx
        cy = declared[1] if cy is None else cy
        cz = declared[2] if pc["axial"] is None else pc["axial"]
        # the base parameters already hold the probe compliance errors: no extra effect is needed
        spec = param_spec(desc)
        for name, true, decl in zip(("probe.compliance_x", "probe.compliance_y", "probe.compliance_z"),
                                    (cx, cy, cz), declared, strict=True):
            p_base[spec.index(name)] = true - decl
        settings["probe_compliance"] = {"bending_x": cx, "bending_y": cy, "axial": cz}
    fs = t["force_sensor"]
    gain, offset, cross = np.zeros(3), np.zeros(3), np.zeros((3, 3))
    if fs is not None:
        gain, offset, cross = np.array(fs["gain"]), np.array(fs["offset"]), np.array(fs["cross_talk"])
        if np.any(gain) or np.any(offset):
            axes = (0, 2) if sensor == "two-channel" else (0, 1, 2)
            effects.append(ForceSensorError(axes=axes, offsets=True))
            values += [gain[a] for a in axes] + [offset[a] for a in axes]
        settings["force_sensor"] = {"gain": gain.tolist(), "offset": offset.tolist(),
                                    "cross_talk": cross.tolist()}
    # effects that depend on the pose and the wrench, last (they see the true angles and force)
    lc = t.get("lateral_compliance")
    if lc is not None:
        effects.append(LateralCompliance(joints=lc["indices"], gravity=lc["gravity"], contact=lc["contact"]))
        for kx, ky in zip(lc["stiffness_x"], lc["stiffness_y"], strict=True):
            values += [0.0 if kx is None else 1.0 / kx, 0.0 if ky is None else 1.0 / ky]
        settings["lateral_compliance"] = {"joints": [desc.joint_names[i] for i in lc["indices"]],
                                          "stiffness_x": [k for k in lc["stiffness_x"] if k is not None],
                                          "stiffness_y": [k for k in lc["stiffness_y"] if k is not None],
                                          "gravity": lc["gravity"], "contact": lc["contact"]}
    if pc is not None and any(pc.get(f"coupling_{a}") for a in ("xy", "xz", "yz")):
        terms = tuple(a for a in ("xy", "xz", "yz") if pc.get(f"coupling_{a}"))
        effects.append(ProbeComplianceMatrix(terms=terms))
        values += [pc[f"coupling_{a}"] for a in terms]
        settings["probe_compliance"].update({f"coupling_{a}": pc[f"coupling_{a}"] for a in terms})  # type: ignore[attr-defined]
    ap = t.get("approach_offset")
    if ap is not None:
        effects.append(ApproachOffset())
        values += [ap[f"d{a}_u{b}"] for a in "xyz" for b in "xyz"]
        settings["approach_offset"] = {f"d{a}_u{b}": ap[f"d{a}_u{b}"] for a in "xyz" for b in "xyz"
                                       if ap[f"d{a}_u{b}"]}
    model = ArmModel(desc, tuple(effects))
    p = np.concatenate([p_base, np.array(values, dtype=float)])
    assert p.shape == (model.spec.size,)
    return Truth(model, p, cross, gain, offset, settings)
