"""Kinematic calibration in CasADi: artefact residuals, identifiability, uncertainty, validation, studies.

Typical use::

    from arm_model import load_description, read_points, read_artefacts
    from arm_model.model import ArmModel
    from calibration import make_data, split_holdout, calibrate, FitOptions, Weights

    model = ArmModel(load_description("aacmm7"))          # effects optional
    data = make_data(read_points("points.csv", 7), read_artefacts("artefacts.toml"), model,
                     reference=read_points("points-ref.csv", 7))        # tracker points optional
    train, test = split_holdout(data, 0.2, seed=0)                      # by measurement
    res = calibrate(model, train, FitOptions(free=("j*", "probe.x", "probe.y", "probe.z"),
                                             weights=Weights(probe=5e-6, reference=10e-6)))
    res.p, res.free, res.u, res.corr, res.fixed, res.status            # by name, SI
    res.compare(test)                                                   # nominal vs calibrated, held out
    res.predict(test)                                                   # residuals on other data

API for the close-the-loop work (issue 7):

* :func:`calibrate` ``(model, data, FitOptions(free=None, values=None, start=None, weights=...)) ->``
  :class:`CalibrationResult` (a variant of a fit: ``dataclasses.replace(options, ...)``): ``p`` (full
  vector of ``model.spec``), ``free``, ``cov``, ``u``, ``corr``, ``s0``, ``status``, ``iterations``, ``fixed``
  (:class:`FixedParameter` with the named
  combination the data cannot see), ``identifiability`` / ``identifiability_final``
  (:class:`Identifiability`), ``residuals`` (per point: ``point`` index, ``kind``, ``instance``,
  ``value`` [m], ``vector`` (n, 3) [m] base frame, ``standardized``, ``measurement``, ``feature``,
  ``line``), ``instances`` (per artefact instance: kind, point indices, RMS, fitted geometry),
  ``distances``, ``outliers``; ``predict(data)``, ``validate(data)``, ``compare(data)``,
  ``equivalent(p_true)``, ``described()``, ``to_dict()``.
* Any :class:`arm_model.model.ArmModel` with effects works: their parameters are in ``model.spec``
  and :func:`make_data` attaches the aux inputs they need.
* :class:`Problem` (residual structure, exact CasADi Jacobians) and :func:`levenberg_marquardt`
  for custom fits; :func:`identify` (which parameters the data identify: rank with the base frame's
  rigid motions projected out, then practical resolution against :func:`prior_scales`);
  :func:`validate` / :func:`before_after` for ASME B89.4.22 figures of any p.
* Studies (:mod:`calibration.study`): Monte Carlo over simulated campaigns, pose-set choice by the
  observability index O1; small campaigns from a known true model: the simulator's fast path,
  :mod:`arm_model.sim.quick`.

Command line: ``aacmm calibrate`` and ``aacmm study {montecarlo, poses}``. Reference:
docs/calibration.md.
"""
from .calibrate import (
                        CalibrationResult,
                        FixedParameter,
                        Outlier,
                        calibrate,
                        default_free,
                        display_unit,
                        identify,
                        resolve_parameters,
                        rigid_gauge,
)
from .candidates import Candidate, library_candidates
from .data import CalibrationData, Weights, make_data, merge_points, split_holdout
from .diagnostics import remaining_structure, residual_space, screen_candidates, structure_tests
from .identifiability import (
                        DEFAULT_RANK_TOL,
                        PRIOR_SCALES,
                        Combination,
                        Identifiability,
                        analyse,
                        prior_scales,
                        reduced_jacobian,
                        weakly_determined,
)
from .loop import LoopResult, LoopSettings, close_loop
from .loop_report import before_after_text, write_loop_report
from .options import FitOptions
from .problem import Problem
from .solver import LMResult, blas_threads, levenberg_marquardt
from .tracking import fit_tracker
from .validation import FIGURES, Validation, before_after, validate

__all__ = [
    "calibrate", "FitOptions", "CalibrationResult", "FixedParameter", "Outlier", "default_free", "resolve_parameters",
    "rigid_gauge", "display_unit", "identify",
    "CalibrationData", "Weights", "make_data", "merge_points", "split_holdout", "fit_tracker",
    "Identifiability", "Combination", "analyse", "reduced_jacobian", "DEFAULT_RANK_TOL", "prior_scales",
    "weakly_determined", "PRIOR_SCALES",
    "Problem", "levenberg_marquardt", "LMResult", "blas_threads",
    "Validation", "validate", "before_after", "FIGURES",
    "close_loop", "LoopSettings", "LoopResult", "Candidate", "library_candidates", "residual_space",
    "screen_candidates", "structure_tests", "remaining_structure", "write_loop_report", "before_after_text",
]
