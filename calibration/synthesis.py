"""Effects built from the residual's structure: when a generic structure family stays significant after the
effect library is exhausted, the effect whose signature that family describes becomes a candidate, and the
loop tests it exactly like a library candidate (screening, held-out folds, minimum improvement).

Family (:func:`calibration.diagnostics.families`) -> candidates (:mod:`arm_model.effects`):

* ``qN harmonics`` -> ``harmonics jN (h ...)``: :class:`~arm_model.effects.JointHarmonics` of joint N's own
  angle, harmonics 1..k for k = 1..4 (those already in the model, e.g. an eccentricity's 1 and 2, left
  out); the held-out data choose k (the smallest k within the parsimony margin of the best);
* ``qK harmonics on jN`` -> ``harmonics jN of qK (h ...)``: the same for joint N's angle error driven by
  joint K's angle (``JointHarmonics(source=K)``, a cross-coupling such as a cable or a counterbalance), and
  ``coupling jN by qK``: joint N's angle error linear in joint K's reading (``JointGain(source=K)``, one
  parameter: the coupling ratio of a differential wrist, a belt; over a joint's full turn a line is a
  sawtooth the low harmonics cannot follow), both joints revolute;
* ``temperature`` / ``temperature per link`` -> ``thermal growth per link`` (each link length its own coefficient,
  :class:`~arm_model.effects.ThermalGrowth` ``per_joint``; beside a common coefficient the longest link
  keeps the common one) and ``probe thermal growth`` (:class:`~arm_model.effects.ProbeThermalGrowth`);
* ``contact force`` / ``force magnitude`` -> ``probe compliance matrix``
  (:class:`~arm_model.effects.ProbeComplianceMatrix`, the terms a probe compliance in the model does not
  already hold) and ``probe compliance axes tilted`` (its xz and yz terms only: a stylus bent or mounted askew,
  two parameters where the matrix has up to six);
* ``approach direction`` -> ``approach offset`` (:class:`~arm_model.effects.ApproachOffset`);
* ``jN lateral load`` -> ``lateral compliance jN`` (:class:`~arm_model.effects.LateralCompliance`);
* ``jN gravity torque sign`` -> ``backlash jN`` (:class:`~arm_model.effects.JointBacklash`: the joint's play,
  closed to the side its gravity load pushes it);
* ``jN motion sign`` -> ``hysteresis jN`` (:class:`~arm_model.effects.JointHysteresis`: the joint's play or its
  encoder's hysteresis, closed by the direction it last turned).

Other families (time, per measurement, per artefact, a joint's gravity or contact torque) have no effect
here: they stay reported as unexplained.
"""
from __future__ import annotations

import re

import numpy as np

from arm_model.effects import (
    ApproachOffset,
    EncoderEccentricity,
    JointBacklash,
    JointGain,
    JointHarmonics,
    JointHysteresis,
    LateralCompliance,
    ProbeCompliance,
    ProbeComplianceMatrix,
    ProbeThermalGrowth,
    ThermalGrowth,
)
from arm_model.model import ArmModel

from .candidates import Candidate

__all__ = ["MAX_HARMONIC", "synthesise", "RESIDUAL"]

#: highest harmonic of a joint angle a synthesised joint-angle error holds
MAX_HARMONIC = 4
#: the terms of a probe compliance whose principal axes are turned off the probe's z axis by small angles (a bent
#: stylus, a probe mounted askew): to first order the turn couples the axial force into a lateral deflection and
#: back, ``dC_xz = -ty (c_x - c_z)``, ``dC_yz = tx (c_y - c_z)``, and leaves the diagonal and xy unchanged
_TILT_TERMS = ("xz", "yz")
#: ``Candidate.origin`` of a synthesised candidate
RESIDUAL = "residual"


def _harmonics_present(model: ArmModel, j: int, source: int | None = None) -> set[int]:
    """Harmonics of joint ``source``'s angle (None: its own) that the model already holds for joint ``j``."""
    out: set[int] = set()
    own = source is None or source == j
    for e in model.effects:
        if (own and isinstance(e, EncoderEccentricity)) or (
                isinstance(e, JointHarmonics) and (e.source in (None, j) if own else e.source == source)):
            if j in e.joint_indices(model.desc):
                out |= set(e.harmonics)
    return out


def _coupling_free(model: ArmModel, j: int, k: int) -> bool:
    """Whether a linear coupling of joint ``j``'s angle error to joint ``k``'s reading can be offered: both joints
    revolute (an angle in an angle) and no such coupling in the model yet."""
    rev = model.desc.revolute_columns
    held = any(isinstance(e, JointGain) and e.source == k and j in e.joint_indices(model.desc) for e in model.effects)
    return j in rev and k in rev and not held


def _harmonic_orders(present: set[int]):
    """Harmonics 1..k (k = 1..MAX_HARMONIC) without those ``present``, each set once."""
    seen = set()
    for k in range(1, MAX_HARMONIC + 1):
        hs = tuple(h for h in range(1, k + 1) if h not in present)
        if hs and hs not in seen:
            seen.add(hs)
            yield hs


def _length_joints(desc) -> list[int]:
    rows = desc.row_table()
    return [i for i in range(desc.n_joints) if np.any(np.abs(rows[i, list(desc.length_indices)]) > 0)]


def synthesise(family_names, model: ArmModel) -> list[Candidate]:
    """Candidates for the significant families ``family_names`` (in their order) given the current model;
    effects the model already holds are not offered again."""
    desc = model.desc
    names = {n: i for i, n in enumerate(desc.joint_names)}      # encoder columns (a mimicking joint has none)
    held = {type(e) for e in model.effects}
    out: list[Candidate] = []

    def add(name, effect, family, joint=None):
        if name not in {c.name for c in out}:
            out.append(Candidate(name, effect, family, joint, origin=RESIDUAL))

    for fam in family_names:
        m = re.fullmatch(r"q(\d+) harmonics", fam)
        mc = re.fullmatch(r"q(\d+) harmonics on (.+)", fam)
        if m:
            j = int(m.group(1)) - 1
            jn = desc.joint_names[j]
            for hs in _harmonic_orders(_harmonics_present(model, j)):
                add(f"harmonics {jn} (h {','.join(map(str, hs))})", JointHarmonics(joints=(j,), harmonics=hs),
                    "joint_harmonics", jn)
        elif mc and mc.group(2) in names:
            k, j, jn = int(mc.group(1)) - 1, names[mc.group(2)], mc.group(2)
            if _coupling_free(model, j, k):
                add(f"coupling {jn} by q{k + 1}", JointGain(joints=(j,), source=k), "joint_coupling", jn)
            for hs in _harmonic_orders(_harmonics_present(model, j, k)):
                add(f"harmonics {jn} of q{k + 1} (h {','.join(map(str, hs))})",
                    JointHarmonics(joints=(j,), source=k, harmonics=hs), "joint_harmonics", jn)
        elif fam in ("temperature", "temperature per link"):
            per_link = [e for e in model.effects if isinstance(e, ThermalGrowth) and e.per_joint]
            if not per_link:
                joints = _length_joints(desc)
                if any(isinstance(e, ThermalGrowth) and not e.per_joint for e in model.effects) and joints:
                    rows = desc.row_table()[:, list(desc.length_indices)]
                    longest = max(joints, key=lambda i: float(np.linalg.norm(rows[i])))
                    joints = [i for i in joints if i != longest]
                if joints:
                    add("thermal growth per link", ThermalGrowth(joints=tuple(joints), per_joint=True),
                        "thermal_links")
            if ProbeThermalGrowth not in held:
                add("probe thermal growth", ProbeThermalGrowth(), "probe_thermal")
        elif fam in ("contact force", "force magnitude"):
            if ProbeComplianceMatrix in held:
                continue
            terms = ["xx", "yy", "zz", "xy", "xz", "yz"]
            for e in model.effects:
                if isinstance(e, ProbeCompliance):
                    terms.remove("xx")
                    if e.anisotropic:
                        terms.remove("yy")
                    if e.axial:
                        terms.remove("zz")
            if len(terms) > len(_TILT_TERMS):
                add("probe compliance axes tilted", ProbeComplianceMatrix(terms=_TILT_TERMS), "probe_compliance_matrix")
            add("probe compliance matrix", ProbeComplianceMatrix(terms=tuple(terms)), "probe_compliance_matrix")
        elif fam == "approach direction":
            if ApproachOffset not in held:
                add("approach offset", ApproachOffset(), "approach_offset")
        elif (mb := re.fullmatch(r"(.+) (gravity torque|motion) sign", fam)) and mb.group(1) in names:
            j = names[mb.group(1)]
            kind, word, fam_key = ((JointBacklash, "backlash", "joint_backlash") if mb.group(2) == "gravity torque"
                                   else (JointHysteresis, "hysteresis", "joint_hysteresis"))
            if not any(isinstance(e, kind) and j in e.joint_indices(desc) for e in model.effects):
                add(f"{word} {mb.group(1)}", kind(joints=(j,)), fam_key, mb.group(1))
        else:
            m = re.fullmatch(r"(.+) lateral load", fam)
            if m and m.group(1) in names and not desc.coupled:    # an effect on the rows: refused on a coupled chain
                j = names[m.group(1)]
                if not any(isinstance(e, LateralCompliance) and j in e.joint_indices(desc) for e in model.effects):
                    add(f"lateral compliance {m.group(1)}", LateralCompliance(joints=(j,)), "lateral_compliance",
                        m.group(1))
    return out
