"""The Gaussian prior of :func:`calibration.calibrate.calibrate`: parameter groups, plausible sizes, bounds,
the evidence's update of each group's scale, and the state of each parameter.

Every free parameter ``p_k`` carries ``p_k ~ N(c_k, (tau_G s_k)^2)``: ``c_k`` the nominal value (the
description, or the values given), ``s_k`` its plausible error size at scale 1 (:func:`prior_spec`) and
``tau_G`` the scale of its **group** G (:func:`parameter_groups`: the joint rows' lengths, their joint
offsets, their axis angles, the tip (probe or marker) offset, the probe's compliances, and each effect's parameters
apart). The scales
are chosen by the evidence (type-II maximum likelihood, MacKay 1992): at the maximum a posteriori fit,
with ``gamma_G = sum_k in G (1 - rho_k)`` the number of the group's parameters the data determine
(``rho_k``: posterior over prior variance, :func:`variance_ratio`), the Laplace evidence is stationary in
``tau_G`` where ``tau_G^2 = sum_k in G ((p_k - c_k) / s_k)^2 / gamma_G`` (:func:`update_scales`).

With ``prior_groups="pooled"`` (:attr:`calibration.options.FitOptions.prior_groups`) the description's geometric
groups (:data:`GEOMETRY_GROUPS`: lengths, joint offsets, axis angles, the tip offset) share one fixed point, the
sums of the numerator and of ``gamma_G`` over the four: one scale for the geometry, each group still under its own
ceiling; the effects' groups keep theirs. A group the data see through few parameters (the tip's three, the offsets
of a 7-joint arm) then takes the scale the whole geometry gives instead of one its handful of parameters, pulled by
what the model lacks, set alone. Not the default: it lowers the real Panda seats' held-out spread and distance
error, and raises the held-out error of random splits of the real TALOS tracker campaign, whose offsets the evidence
puts at about ten times its lengths (docs/studies/calibration.md, "The prior's groups pooled").

An angular compliance's prior is physical, not scaled by the evidence: its size is the compliance that turns
the joint by :data:`DEFLECTION` (10 mrad, the largest plausible deflection) under the torque the data give it,
and its lower bound keeps it non-negative. Its group's scale stays at 1 (:attr:`PriorSpec.physical`): the
Laplace evidence is no guide for a group whose posterior is cut by its bound (some of its parameters held at 0,
the others' posterior far from Gaussian), and its MacKay fixed point shrinks a compliance the training poses
see only weakly to zero, leaving its signature to the geometry, which then errs where the poses reach beyond
the training range (measured in docs/studies/calibration.md).

A joint's play (:class:`arm_model.effects.JointBacklash`, :class:`~arm_model.effects.JointHysteresis`) has a physical
size too, a maximum: :data:`arm_model.effects.PLAY` (1 mrad, the largest plausible play); the evidence may shrink its
group's scale (plays the data show small), never raise it above 1 (:attr:`PriorSpec.capped`; an ordinary group's
may reach :data:`SCALE_RANGE`'s 100); a backlash is non-negative (its lower bound). A play is seen only as the
difference between the points on its two sides: where one side holds fewer than :data:`MIN_SIDE_SHARE` of the points,
or the sign is nil on every point (a joint with no gravity torque, one that never moved), the play is the joint's
offset in the data plus what a handful of points carry; where a side is met in fewer than :data:`MIN_SIDE_VISITS`
runs of the capture order, it is a step along the order, which a drift makes too (a real Panda's elbow, trained on
one placement whose gravity torque keeps one sign, fitted 17 mrad of "play" at 1 mrad: its offset, the rank test
having held the offset instead). Such a parameter is **prior only**
(:func:`prior_only`): its data's column is left out of the fit (:attr:`calibration.problem.Problem.prior_only`), so
it stays at its prior's centre with its prior's uncertainty (prior-dominated, ``rho = 1``) and that uncertainty,
uncorrelated, is carried by every propagation (a pose on the other side of the play is that uncertain). Without a
prior it is held at its given value, with that reason.

A parameter is **prior-dominated** when ``rho_k >= PRIOR_DOMINATED`` (0.5): its posterior variance is at
least half its prior's, i.e. the data's own information on it is at most the prior's (for one parameter,
``1 / u_post^2 = 1 / u_prior^2 + 1 / u_data^2``, so ``rho >= 0.5`` iff ``u_data >= u_prior``). Such a
parameter stays near its nominal value with about its prior's uncertainty, and that uncertainty is part of
the posterior covariance every propagation uses.

A parameter the data **barely see** (``rho_k >= BARELY_SEEN``, 0.9: the data's own uncertainty on it at least 3
times its prior's size) has **no say in its group's scale** (:func:`update_scales` sums over the group's other
parameters): it follows the scale the others give. The fixed point is the Laplace evidence's stationary point, a
local statement. Along a direction the data barely curve, a small systematic pull (residual structure the model
does not hold, which a long lever can mimic) moves the MAP estimate by about ``tau^2`` times the pull, the estimate
feeds the next round's scale, and the scale runs to wherever the pull is spent: the tip offset of a stylus held
parallel to a ring gauge's axis (probe z, which such a ring sees only through the stylus' tilt) went from 85 mm
to -93.6 mm, behind the wrist, on the bundled ring campaign repeated four times, its scale at the old cap of 100
(docs/calibration.md, "Ceilings, and what the data barely see").

Every group's scale also has a **ceiling** (:attr:`PriorSpec.ceiling`): no prior standard deviation wider than the
largest error the arm's own dimensions allow (:func:`limits`): the tip's place :data:`TIP_SHARE` of its distance
from the last joint's origin (the stylus), a joint row's length :data:`LENGTH_SHARE` of the chain's length, an
angle :data:`MAX_ANGLE`; never below the plausible size itself (scale 1).
"""
from __future__ import annotations

import fnmatch
import math
from dataclasses import dataclass

import numpy as np

__all__ = ["GROUP_LENGTHS", "GROUP_OFFSETS", "GROUP_ANGLES", "GROUP_TIP", "GROUP_PROBE_COMPLIANCE", "BASE_SIZES",
           "PRIOR_DOMINATED", "BARELY_SEEN", "SCALE_RANGE", "MIN_EFFECTIVE", "TIP_SHARE", "LENGTH_SHARE", "MAX_ANGLE",
           "MIN_SIDE_SHARE", "MIN_SIDE_VISITS", "NIL_LOAD", "PriorSpec", "parameter_groups", "prior_spec",
           "limits", "variance_ratio", "update_scales", "MAX_GAIN", "secant_gains", "both_sides",
           "side_visits", "unseen_side", "prior_only", "MAX_SCALE_U", "uniform_scale", "scale_step",
           "scale_precision", "GEOMETRY_GROUPS", "PRIOR_GROUPS"]

GROUP_LENGTHS = "lengths"
GROUP_OFFSETS = "joint offsets"
GROUP_ANGLES = "axis angles"
GROUP_TIP = "tip offset"
GROUP_PROBE_COMPLIANCE = "probe compliance"
#: the description's geometric groups, which ``prior_groups="pooled"`` gives one scale (:func:`update_scales`)
GEOMETRY_GROUPS = (GROUP_LENGTHS, GROUP_OFFSETS, GROUP_ANGLES, GROUP_TIP)
#: :attr:`calibration.options.FitOptions.prior_groups`: each group its own scale, or the geometric groups pooled
PRIOR_GROUPS = ("separate", "pooled")

#: plausible error size at scale 1 [SI] of a joint row's length [m] and angle [rad] (1 mm, 1 mrad: one
#: millimetre at a metre); the evidence scales each group from there
BASE_SIZES = {"m": 1e-3, "rad": 1e-3}
#: plausible size at scale 1 of an effect parameter with no size of its own, by SI unit
UNIT_SIZES = {"m": 1e-3, "rad": 1e-3, "1": 0.1, "N": 1.0, "N m": 0.1, "1/K": 1e-4, "m/N": 1e-6}
#: the largest plausible angular deflection [rad] of a joint under the RMS torque the data give it: the size of
#: an angular compliance's physical prior (its group's scale is not estimated, :attr:`PriorSpec.physical`)
DEFLECTION = 1e-2
#: the largest plausible size of an angular compliance [rad/(N m)] (a tenth of what a model file may hold)
MAX_ANGULAR_COMPLIANCE = 0.1
#: posterior/prior variance ratio from which a parameter is prior-dominated
PRIOR_DOMINATED = 0.5
#: posterior/prior variance ratio from which the data barely see a parameter (their own information on it at most
#: a ninth of the prior's: its data uncertainty at least 3 times the prior's size): it has no say in its group's
#: scale (:func:`update_scales`)
BARELY_SEEN = 0.9
#: the smallest share of the points on either side of a sign (a play's, a gravity torque's, a last move's) for the data
#: to see the sign apart from a constant: with fewer, the sign picks out a handful of points (a gross error's
#: signature), and a play is the joint's offset (:func:`prior_only`; the loop's sign families, :mod:`calibration.
#: diagnostics`)
MIN_SIDE_SHARE = 0.1
#: the fewest separate visits (runs of consecutive points, in the capture order of each measurement) of each side of a
#: play for the data to see it: a side met in one or two runs is a step or two along the capture order, which the
#: plate or the base creeping while the points are taken, or the sweep's own pose-dependent error, makes as well (a
#: real Panda's joint 3, met in 2 + 2 runs on one placement, fitted 2.2 mrad of play and spread the other placements'
#: seats over 5 mm; held, 1.5 mm)
MIN_SIDE_VISITS = 3
#: a joint's gravity torque at most this fraction of the largest one in the data (any joint, any point) is nil: its
#: sign is rounding (a vertical axis)
NIL_LOAD = 1e-9
#: range of a group's scale (times the plausible sizes)
SCALE_RANGE = (1e-2, 1e2)
#: fewest parameters the data must determine in a group (``gamma_G``) for its scale to be estimated
MIN_EFFECTIVE = 0.5
#: the largest plausible error (one standard deviation) of the tip's place on the last link, as a share of its
#: distance from the last joint's origin (a 100 mm stylus: 5 mm; a ball off by more is another stylus than the
#: description's, not a calibration)
TIP_SHARE = 0.05
#: the largest plausible error (one standard deviation) of a joint row's length, as a share of the chain's length
#: (`ArmDescription.chain_length`: a metre-long arm, 5 mm; a machined or cast link is made to a small fraction of that)
LENGTH_SHARE = 0.005
#: the largest plausible error (one standard deviation) [rad] of an angle of a joint row: an encoder's zero or an
#: axis' tilt (50 mrad, 2.9 deg; the real TALOS's offsets the evidence puts at 19 mrad)
MAX_ANGLE = 0.05


#: |cos| of the angle between an origin angle's rotation axis and the joint axis from which it is the joint's
#: offset (rotation about its own axis)
ALIGNED = math.cos(math.radians(1.0))


def _angle_group(desc, joint: int, field: str) -> str:
    """``joint offsets`` for the angle about a revolute joint's own axis (DH/MDH ``theta_offset``; the URDF
    origin angle whose axis, one of the origin's own, is the joint axis, within 1 degree), else ``axis angles``
    (the axis' tilt). A prismatic joint's zero is a length (``d``, or its origin's translation along the axis): every
    angle of its row orients the slide and the links it carries, an ``axis angle`` like a tilt."""
    row = desc.joints[joint]
    if row.prismatic:
        return GROUP_ANGLES
    if field == "theta_offset":
        return GROUP_OFFSETS
    if desc.convention != "urdf" or field not in ("origin_roll", "origin_pitch", "origin_yaw") \
            or row.axis is None or row.origin is None:
        return GROUP_ANGLES
    # an origin's angle errors turn it about its own x, y, z (arm_model.chain.row_motions): the joint axis is
    # in that frame
    axis = np.asarray(row.axis, dtype=float) / np.linalg.norm(row.axis)
    k = ("origin_roll", "origin_pitch", "origin_yaw").index(field)
    return GROUP_OFFSETS if abs(float(axis[k])) >= ALIGNED else GROUP_ANGLES


def parameter_groups(model, names) -> list[str]:
    """The prior group of each parameter ``names`` of ``model``: the joint rows' ``lengths`` [m], ``joint
    offsets`` (the angle about a joint's own axis: its zero) and ``axis angles`` (the other angles: the axis'
    tilt) [rad] (other units of a joint row: a group of their unit), the ``tip offset`` (probe.x/y/z: a
    probe's or a tracker marker's position on the last link), the ``probe compliance`` (probe.compliance_*),
    and one group a model effect (``effect <its description>``)."""
    spec = model.spec
    desc = model.desc
    effect_of = {}
    for e, sl in model.effect_slices():
        for k in range(sl.start, sl.stop):
            effect_of[k] = f"effect {e.describe()}"
    joint_of = {j.name: i for i, j in enumerate(desc.joints)}
    out = []
    for n in names:
        i = spec.index(n)
        unit = spec.units[i]
        if i in effect_of:
            out.append(effect_of[i])
        elif n.startswith("probe.compliance"):
            out.append(GROUP_PROBE_COMPLIANCE)
        elif n.startswith("probe."):
            out.append(GROUP_TIP)
        elif unit == "rad":
            jname, _, field = n.rpartition(".")
            out.append(_angle_group(desc, joint_of[jname], field) if jname in joint_of else GROUP_ANGLES)
        else:
            out.append({"m": GROUP_LENGTHS}.get(unit, f"joint rows [{unit}]"))
    return out


@dataclass(frozen=True)
class PriorSpec:
    """The prior of every parameter of a model (full-length vectors in ``model.spec`` order).

    Attributes:
        group: each parameter's group (:func:`parameter_groups`).
        size: plausible error size at scale 1 [SI] (the prior's standard deviation at ``tau = 1``).
        lower: lower bound of the parameter [SI] (``-inf``: none; a compliance: minus its nominal value).
        source: how each size was set (for the report).
        physical: the groups whose prior is physical (every parameter an angular compliance sized by the data's
            torque): the evidence leaves their scale as given (1 by default).
        limit: the largest plausible standard deviation of each parameter [SI] (:func:`limits`; ``inf``: none
            but :data:`SCALE_RANGE`).
        capped: the groups whose size is a physical maximum (every parameter a play's,
            :attr:`arm_model.effects.Effect.physical_size`): the evidence may shrink their scale, never above 1.
    """
    group: tuple
    size: np.ndarray
    lower: np.ndarray
    source: tuple
    physical: frozenset = frozenset()
    limit: np.ndarray | None = None
    capped: frozenset = frozenset()

    def ceiling(self, group: str) -> float:
        """The largest scale the evidence may give ``group``: the smallest of its parameters' ``limit / size``, at
        least 1 (a size given or set by the data is a statement the ceiling does not narrow), at most
        :data:`SCALE_RANGE`'s top; 1 for a capped group (:attr:`capped`)."""
        if group in self.capped:
            return 1.0
        if self.limit is None:
            return SCALE_RANGE[1]
        idx = [i for i, g in enumerate(self.group) if g == group]
        top = min((float(self.limit[i] / self.size[i]) for i in idx), default=math.inf)
        return min(max(top, 1.0), SCALE_RANGE[1])

    def bounded(self, group: str, scale: float) -> float:
        """``scale`` of ``group`` kept in :data:`SCALE_RANGE` and under the group's :meth:`ceiling`."""
        return float(min(max(scale, SCALE_RANGE[0]), self.ceiling(group)))

    def sizes(self, scales: dict | float) -> np.ndarray:
        """The prior's standard deviations [SI] at group ``scales`` (a dict, or one factor for every group)."""
        if not isinstance(scales, dict):
            return self.size * float(scales)
        return self.size * np.array([scales.get(g, 1.0) for g in self.group])

    def groups_of(self, indices) -> dict[str, np.ndarray]:
        """{group: the entries of ``indices`` (indices into the spec) in it}, groups in first-seen order."""
        indices = np.asarray(indices, dtype=int)
        names = [self.group[i] for i in indices]
        return {g: indices[[k for k, n in enumerate(names) if n == g]] for g in dict.fromkeys(names)}


def _torque_reference(model, data, joint: int) -> float:
    """RMS over ``data`` of the torque [N m] joint ``joint`` carries (gravity from the description's masses and
    the contact torque), 0 when the data give none."""
    aux = data.aux
    if aux is None:
        return 0.0
    t = np.zeros(len(data))
    for part in (aux.tau_gravity, aux.tau_contact):
        if part is not None:
            t = t + np.asarray(part)[:, joint]
    return float(np.sqrt(np.mean(t ** 2))) if len(t) else 0.0


def _effect_sizes(model, data) -> dict[int, tuple[float, str, str]]:
    """{spec index: (size at scale 1, source, kind)} of every effect parameter: kind "physical" (an angular
    compliance's, the evidence leaves its scale), "maximum" (a physical maximum, its scale at most 1) or ""."""
    desc = model.desc
    slices = list(model.effect_slices())
    if not slices:
        return {}
    inputs = _model_inputs(model, data)
    out = {}
    for e, sl in slices:
        defs = e.param_defs(desc)
        joints = list(e.joint_indices(desc)) if hasattr(e, "joint_indices") else []
        loads = e.gravity_loads(desc, data.points.q) if hasattr(e, "gravity_loads") and len(data) else None
        own = e.prior_sizes(desc, inputs) if len(data) else None
        for n, (k, (name, unit)) in enumerate(zip(range(sl.start, sl.stop), defs, strict=True)):
            if own is not None:
                out[k] = (own[n][0], own[n][1], "maximum" if e.physical_size else "")
            elif unit == "rad/(N m)":
                j = next((i for i in joints if name.startswith(desc.joint_names[i] + ".")), None)
                if loads is not None:           # an off-axis compliance: the moment it multiplies
                    tau = float(np.sqrt(np.mean(np.asarray(loads[n]) ** 2)))
                else:
                    tau = 0.0 if j is None else _torque_reference(model, data, j)
                size = MAX_ANGULAR_COMPLIANCE if tau <= 0 else min(DEFLECTION / tau, MAX_ANGULAR_COMPLIANCE)
                load = "torque" if loads is None else "gravity moment"
                out[k] = (size, f"{DEFLECTION * 1e3:g} mrad under the joint's RMS {load} in the data "
                                f"({tau:.3g} N m)" if tau > 0 else f"no {load} in the data", "physical")
            elif e.plausible_size is not None:
                out[k] = (float(e.plausible_size), f"the effect's {'physical' if e.physical_size else 'plausible'} "
                                                   f"size ({e.plausible_size:g} {unit})",
                          "maximum" if e.physical_size else "")
            else:
                out[k] = (UNIT_SIZES.get(unit, 1.0), f"by unit ({unit})", "")
    return out


def limits(model) -> np.ndarray:
    """The largest plausible standard deviation [SI] of each parameter's error, from the arm's own dimensions: the
    tip offset (probe.x/y/z) :data:`TIP_SHARE` of the tip's distance from the last joint's origin, a joint row's
    length :data:`LENGTH_SHARE` of the chain's length (`ArmDescription.chain_length`), a joint row's angle
    :data:`MAX_ANGLE`; each at least the length's or angle's plausible size at scale 1 (:data:`BASE_SIZES`); other
    parameters ``inf`` (their scale bounded by :data:`SCALE_RANGE` alone)."""
    spec, desc = model.spec, model.desc
    length = max(LENGTH_SHARE * desc.chain_length, BASE_SIZES["m"])
    tip = max(TIP_SHARE * float(np.linalg.norm(desc.probe.p_last)), BASE_SIZES["m"])
    out = np.full(spec.size, math.inf)
    for i, (n, unit) in enumerate(zip(spec.names, spec.units, strict=True)):
        if n in ("probe.x", "probe.y", "probe.z"):
            out[i] = tip
        elif i < model.base_size and not n.startswith("probe."):
            out[i] = {"m": length, "rad": max(MAX_ANGLE, BASE_SIZES["rad"])}.get(unit, math.inf)
    return out


def prior_spec(model, data, priors: dict | None = None) -> PriorSpec:
    """The groups, plausible sizes and bounds of every parameter of ``model`` for ``data``.

    Sizes at scale 1: a joint row's length 1 mm and angle 1 mrad (:data:`BASE_SIZES`); the tip offset
    (probe.x/y/z) 1 mm too (the tip's nominal place is known: a marker at an unknown place is a nuisance
    unknown of its own, without a prior, :mod:`arm_model.tracker`); the probe's
    compliance 10 times its nominal value (at least 1e-8 m/N); an angular compliance [rad/(N m)] the one that
    turns the joint by :data:`DEFLECTION` (its largest plausible deflection; the group is physical, its scale
    not estimated) under the RMS torque the data give it (gravity from the
    description's masses, contact torques from the forces; an off-axis compliance, the RMS moment of gravity
    about its axis that the effect's ``gravity_loads`` give; at most :data:`MAX_ANGULAR_COMPLIANCE`); another
    effect parameter the size the effect takes from the data (a drift's: :data:`arm_model.effects.DRIFT_STRAIN` over
    the data's time span), else its own plausible size (a play's physical maximum, :data:`arm_model.effects.PLAY`: its
    group's scale at most 1) or a size by unit (:data:`UNIT_SIZES`); the plays the data cannot tell
    from the joint's offset the fit leaves to this prior alone (:func:`prior_only`). ``priors``
    (names or glob patterns -> size [SI]) override. The lower bounds are the model's
    (:meth:`arm_model.model.ArmModel.lower_bounds`: a compliance cannot be negative in total, nor a backlash)."""
    spec = model.spec
    probe = model.desc.probe
    eff = _effect_sizes(model, data)
    size, lower, source = np.empty(spec.size), model.lower_bounds(), []
    for i, (n, unit) in enumerate(zip(spec.names, spec.units, strict=True)):
        hit = [v for pat, v in (priors or {}).items() if fnmatch.fnmatchcase(n, pat)]
        if hit:
            size[i], src = float(hit[0]), "given"
        elif i in eff:
            size[i], src, _ = eff[i]
        elif n.startswith("probe.compliance"):
            c = probe.axial_compliance if n.endswith("_z") else max(probe.bending_compliance_x,
                                                                    probe.bending_compliance_y)
            size[i], src = max(10.0 * c, 1e-8), "10 x the nominal probe compliance"
        elif n.startswith("probe."):
            size[i], src = BASE_SIZES["m"], "a length's plausible error (the tip's nominal place is known)"
        else:
            size[i], src = BASE_SIZES.get(unit, UNIT_SIZES.get(unit, 1.0)), f"by unit ({unit})"
        source.append(src)
    groups = tuple(parameter_groups(model, spec.names))
    kind = [eff[i][2] if i in eff and source[i] != "given" else "" for i in range(spec.size)]

    def every(what: str) -> frozenset:
        return frozenset(g for g in set(groups) if all(kind[i] == what for i in range(spec.size) if groups[i] == g))
    return PriorSpec(groups, size, lower, tuple(source), every("physical"), limits(model), every("maximum"))


def both_sides(sign) -> bool:
    """Whether at least :data:`MIN_SIDE_SHARE` of the entries of ``sign`` lie on either side of zero (the one rule
    for a sign the data can see apart from a constant)."""
    sign = np.asarray(sign)
    return bool(min(np.sum(sign > 0), np.sum(sign < 0)) >= MIN_SIDE_SHARE * len(sign))


def _model_inputs(model, data):
    """The per-point inputs an effect's :meth:`~arm_model.effects.Effect.sides` and
    :meth:`~arm_model.effects.Effect.prior_sizes` read (:func:`arm_model.model.model_inputs`): no wrench, a nil
    gravity torque (:data:`NIL_LOAD`) at 0, the points' time stamps where the data's inputs have none, and the last
    moves of :attr:`calibration.data.CalibrationData.motion` (the loop's sign families read the same)."""
    from arm_model.model import model_inputs
    return model_inputs(np.asarray(data.points.q, dtype=float), data.aux, nil_load=NIL_LOAD, time=data.points.time,
                        motion=data.motion)


def side_visits(side, measurement=None, time=None) -> tuple[int, int]:
    """(runs on the positive side, runs on the negative side) of the per-point ``side`` (-1, 0, +1): the separate
    visits of each side in the capture order of each measurement (the rows' order, or ``time`` [s] where every
    point has one); a point with side 0 neither breaks nor starts a run."""
    side = np.asarray(side, dtype=float)
    meas = np.zeros(len(side), dtype=object) if measurement is None else np.asarray(measurement, dtype=object)
    t = None if time is None else np.asarray(time, dtype=float)
    order = (np.arange(len(side)) if t is None or not np.all(np.isfinite(t))
             else np.argsort(t, kind="stable"))
    runs = [0, 0]
    for m in dict.fromkeys(meas.tolist()):
        s = side[order[meas[order] == m]]
        s = s[s != 0]
        first = np.r_[True, s[1:] != s[:-1]] if len(s) else np.zeros(0, bool)
        runs[0] += int(np.sum(first & (s > 0)))
        runs[1] += int(np.sum(first & (s < 0)))
    return runs[0], runs[1]


def unseen_side(side, points) -> str | None:
    """Why the data cannot see a play whose per-point sides are ``side`` (-1, 0, +1) on ``points`` (their
    ``measurement`` and ``time`` give the capture order), or None when they can: both sides hold
    :data:`MIN_SIDE_SHARE` of the points (:func:`both_sides`) in at least :data:`MIN_SIDE_VISITS` runs each
    (:func:`side_visits`). The one rule for a play: :func:`prior_only` and the loop's sign families
    (:mod:`calibration.diagnostics`) both ask it."""
    side = np.asarray(side, dtype=float)
    pos, neg = int(np.sum(side > 0)), int(np.sum(side < 0))
    if pos + neg == 0:
        return f"the side of its play is nil on all {len(side)} points"
    if not both_sides(side):
        return (f"{min(pos, neg)} of {len(side)} points on one side of its play (fewer than {MIN_SIDE_SHARE:.0%}): "
                "the data cannot tell it from the joint's offset")
    visits = side_visits(side, points.measurement, points.time)
    if min(visits) < MIN_SIDE_VISITS:
        return (f"its sides are met in {visits[0]} and {visits[1]} runs of the capture order (fewer than "
                f"{MIN_SIDE_VISITS} each): the data cannot tell it from a drift while the points were taken")
    return None


def prior_only(model, data) -> dict[int, str]:
    """{spec index: why} of the effect parameters the data cannot see apart from others: a play
    (:meth:`~arm_model.effects.Effect.sides`) whose sign is nil on every point (no gravity torque, no motion), whose
    points hold fewer than :data:`MIN_SIDE_SHARE` on one side (:func:`both_sides`; the joint's offset), or whose
    sides are each met in fewer than :data:`MIN_SIDE_VISITS` runs of the capture order (:func:`side_visits`; a drift
    along it)."""
    if data is None or not len(data):
        return {}
    from arm_model.chain import NUMPY_OPS
    inputs = _model_inputs(model, data)
    out = {}
    for e, sl in model.effect_slices():
        sides = e.sides(model.desc, inputs, NUMPY_OPS)
        if sides is None:
            continue
        for k, side in zip(range(sl.start, sl.stop), sides, strict=True):
            why = unseen_side(np.broadcast_to(np.asarray(side, dtype=float), (len(data),)), data.points)
            if why is not None:
                out[k] = why
    return out


def variance_ratio(post_var: np.ndarray, prior_sd: np.ndarray) -> np.ndarray:
    """``rho = u_post^2 / u_prior^2`` of each parameter: 1 where the data add nothing, 0 where they fix it."""
    return np.clip(np.asarray(post_var) / np.asarray(prior_sd) ** 2, 0.0, 1.0)


def update_scales(scales: dict, spec: PriorSpec, kept, delta: np.ndarray, rho: np.ndarray,
                  pool: tuple = ()) -> tuple[dict, dict]:
    """The evidence's fixed point of the group scales (MacKay's, see the module docstring): the scale each group's
    update gives from the current fit.

    Args:
        scales: current scale of each group.
        kept: spec indices of the estimated parameters; ``delta`` their ``p - centre`` [SI] at the maximum a
            posteriori fit, ``rho`` their posterior/prior variance ratios (:func:`variance_ratio`).
        pool: groups that share one fixed point (``prior_groups="pooled"``: :data:`GEOMETRY_GROUPS`): ``tau^2 =
            sum z^2 / sum gamma`` over the seen parameters of every group of ``pool`` (a physical group stays
            apart), each of them then at that scale under its own ceiling; a pooled group whose own data determine
            fewer than :data:`MIN_EFFECTIVE` parameters takes it too, as long as the pool's do.

    Returns ``(new scales, {group: gamma_G})``. Only the group's parameters the data see (``rho <``
    :data:`BARELY_SEEN`) enter its fixed point: one the data barely see follows the scale the others give (see the
    module docstring); a group whose data determine fewer than :data:`MIN_EFFECTIVE` parameters keeps its scale
    (its evidence is flat), and so does a physical group (:attr:`PriorSpec.physical`); every scale stays in
    :data:`SCALE_RANGE` and under its group's ceiling (:meth:`PriorSpec.bounded`; a capped group's,
    :attr:`PriorSpec.capped`, is 1). ``gamma_G`` is over every parameter of the group. The rounds of
    :func:`calibration.calibrate.calibrate` move each scale by :func:`secant_gains` times the way to this fixed
    point."""
    kept = np.asarray(kept, dtype=int)
    new, gamma, seen = dict(scales), {}, {}
    for g, idx in spec.groups_of(kept).items():
        sel = np.isin(kept, idx)
        gamma[g] = float(np.sum(1.0 - rho[sel]))
        sel &= rho < BARELY_SEEN
        if g not in spec.physical:       # (sum z^2, sum gamma) over the group's seen parameters
            seen[g] = (float(np.sum((delta[sel] / spec.size[kept[sel]]) ** 2)), float(np.sum(1.0 - rho[sel])))
    pooled = [g for g in pool if g in seen]
    if pooled:
        both = tuple(sum(seen[g][i] for g in pooled) for i in (0, 1))
        seen.update(dict.fromkeys(pooled, both))
    for g, (z2, gam) in seen.items():
        if gam >= MIN_EFFECTIVE:
            new[g] = spec.bounded(g, math.sqrt(z2 / gam))
    return new, gamma


#: the largest factor by which :func:`secant_gains` lengthens a fixed point's step
MAX_GAIN = 10.0


def secant_gains(steps: dict, last: dict, tol: float) -> dict:
    """How far (a factor of the step) to move each log scale of the fixed-point iteration ``x <- x + r(x)``
    (:func:`update_scales`), from its steps ``r`` this round and last round's ``(step r, move made)`` (``last``).
    The secant of ``r`` over the last move, ``slope = (r - r_last) / move``, is -1 for a fixed point reached in one
    step; the gain is Newton's on ``r = 0``, ``-1 / slope``, at most :data:`MAX_GAIN` (also where ``r`` does not
    shrink: a scale running to its bound, where the plain iteration creeps with ever equal steps); an iteration that
    overshoots (slope below -1) is damped by the same rule (a 2-cycle is cut at its middle). The gain is 1 (the
    plain fixed point) for a key without history, or whose step or last move is within ``tol`` (the iteration's own
    tolerance: a secant over so short a move, or a gain on so short a step, would amplify the refit's noise), and
    for a step that grew as the scale moved its way (slope above ``1 / MAX_GAIN``): no creep, but the other groups'
    moves of the same round changing this one's fixed point (the rounds are coupled), so the secant is no Newton
    step; lengthened tenfold it threw a KUKA iiwa's joint offsets from 8.5 to the floor, 0.01, in one round (its
    fixed point near 2), where the data no longer see the group and its scale stays (:func:`update_scales`), and
    the seats of a placement it never saw spread 3.6 mm instead of 0.8 (docs/studies/calibration.md, "The seat
    data set's shape on other robots"). The point where ``r = 0`` is the fixed point's own: only the number of
    rounds changes."""
    out = {}
    for key, r in steps.items():
        r_last, move = last.get(key, (0.0, 0.0))
        if abs(move) <= tol or abs(r) <= tol:
            out[key] = 1.0
            continue
        slope = (r - r_last) / move
        if slope > 1.0 / MAX_GAIN:                 # the step grew: the other groups moved this one's fixed point
            out[key] = 1.0
        else:
            out[key] = MAX_GAIN if slope >= -1.0 / MAX_GAIN else -1.0 / slope
    return out


#: the largest standard uncertainty [1] of the arm's uniform scale for the data to set it (a flat prior on the scale,
#: :func:`scale_step`): the largest plausible error of a length as a share of the chain's (:data:`LENGTH_SHARE`).
#: Data that cannot place the scale that well (seats without a certified length: about 8 %) leave it to the prior.
MAX_SCALE_U = LENGTH_SHARE


def uniform_scale(model) -> np.ndarray:
    """The direction [m] (full parameter vector, ``model.spec`` order) that scales the arm's geometry uniformly:
    each joint row's lengths (DH ``d``, ``a``; a URDF origin's ``x``, ``y``, ``z``) and the tip offset by their
    description's values, every angle and effect parameter 0. ``p + s * uniform_scale(model)`` is the arm ``1 + s``
    times as large (to first order), every point it reaches scaled about its base."""
    desc = model.desc
    spec = model.spec
    out = np.zeros(spec.size)
    table = desc.row_table()
    for i, j in enumerate(desc.joints):
        for k, f in enumerate(desc.row_fields):
            n = spec.index(f"{j.name}.{f}")
            if spec.units[n] == "m":
                out[n] = table[i, k]
    for k, axis in enumerate("xyz"):
        out[spec.index(f"probe.{axis}")] = desc.probe.p_last[k]
    return out


def scale_step(direction: np.ndarray, size: np.ndarray, delta: np.ndarray, cov: np.ndarray) -> tuple[float, float]:
    """The arm's uniform scale under a flat prior, by the evidence: ``(step, u)`` [1] of the scale ``s`` of the prior's
    centre ``c0 + s * direction``.

    With ``p ~ N(c0 + s d, diag(size^2))`` and ``s`` flat, the maximum a posteriori ``s`` (the marginal likelihood's
    maximum in ``s``, for a Gaussian posterior the same) solves ``d^T L (p(s) - c0 - s d) = 0``, ``L = diag(1 /
    size^2)``; the fit ``p(s)`` moves with the centre by ``cov L d`` (``cov`` the posterior covariance at the
    current centre), so one Newton step from the current ``s`` is ``d^T L delta / (d^T L d - d^T L cov L d)``
    (``delta`` the fit's ``p - centre``), exact for a linear model, and the denominator is the posterior precision
    of ``s``: ``u = den^-1/2`` (inf where the data do not see the direction). Vectors over the free parameters
    [SI]."""
    w, _, den = scale_precision(direction, size, cov)
    if not den > 0:
        return 0.0, math.inf
    return float(w @ delta) / den, 1.0 / math.sqrt(den)


def scale_precision(direction: np.ndarray, size: np.ndarray, cov: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """``(w, g, den)`` of the arm's scale along ``direction`` under a flat prior: ``w = L d`` (``L = diag(1 /
    size^2)``), ``g = cov w`` and the scale's posterior precision ``den = d^T L d - w^T cov w`` (the Schur complement
    of :func:`scale_step`; the covariance with the scale's uncertainty is ``cov + g g^T / den``)."""
    w = direction / size ** 2
    g = cov @ w
    return w, g, float(w @ direction - w @ g)
