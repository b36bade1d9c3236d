"""Held-out evaluation: the figures of the before/after table on points a model was not fitted to (whole
measurements, or poses predicted against their feature as fitted on its other poses), from their residual rows
(:func:`calibration.validation.heldout_residuals`)."""
from __future__ import annotations

import numpy as np

from arm_model import InputError
from arm_model.model import ArmModel

from ..data import CalibrationData, Weights
from ..validation import (
    BOOTSTRAP_SAMPLES,
    FIGURES,
    bootstrap,
    heldout_residuals,
    resamples,
    validate,
    validate_poses,
)

__all__ = ["heldout_residuals", "heldout_figures", "bootstrap_rows"]


def heldout_figures(model: ArmModel, p, data: CalibrationData, weights: Weights, reference: str = "fit",
                    train=None, seed: int = 0, stated: Weights | None = None, cov: tuple | None = None,
                    tracker=None) -> dict:
    """Figures of ``(model, p)`` on held-out data [um], each a prediction as ``calibrate``'s held-out figures are
    (:func:`heldout_residuals` with ``train``, the poses of the training features, or ``tracker``, the training
    fit's instrument frames and marker offsets: :func:`calibration.tracking.as_predicted`): RMS and
    max |residual| over the artefact rows (each row a residual component: a sphere/ring/plane distance, a
    seat coordinate, a length error; the reference-instrument rows only when there is nothing else, since
    their noise is the instrument's), the same per kind, the weighted RMS of all rows, and the standard
    test figures (:data:`calibration.validation.FIGURES`) of the held-out points; ``seed``: the seed of the
    bootstrap of their standard uncertainties. For the loop's judgement of the test set
    (:func:`calibration.loop.verdict.heldout_check`): ``chi2`` (the sum of the squared weighted residuals),
    ``nuisance`` (the unknowns solved on the held-out rows), ``propagated`` (with ``cov``, the fitted parameters'
    (names, covariance): the variance their uncertainty adds to the held-out rows, summed,
    :func:`~calibration.validation.heldout_residuals`) and, with ``stated``, ``rms_over_stated`` and
    ``chi2_stated``: the RMS and the sum of squares of the rows each over its stated uncertainty, over the
    ``rows_stated`` rows whose group has one (not the lengths, whose uncertainty is each artefact's);
    ``sigmas_stated``: whether the user stated each of those (False: one is a default,
    :meth:`~calibration.data.Weights.stated_sigma_of`, which the sentences then call so). ``held``: the nuisance
    unknowns held at the training fit's values. The standard figures of held-out poses (``train``) are their
    distances from the training features (``pose_rms``, ``pose_max``: :func:`~calibration.validation.validate_poses`,
    as ``calibrate --holdout-by pose`` gives them); those of whole measurements hold the reference points predicted
    with ``tracker`` (``reference_rms_predicted``, ``reference_max_predicted``) instead of after a best fit on
    them."""
    h = heldout_residuals(model, p, data, weights, reference, train, cov, tracker)
    e = h["e"]
    art = h["kind"] != "reference"
    head = e[art] if art.any() else e
    out = {"rms_um": float(np.sqrt(np.mean(head ** 2))) * 1e6, "max_um": float(np.max(np.abs(head))) * 1e6,
           "headline_rows": ("reference points" if not art.any() else "artefact points and lengths"
                             if (h["kind"] == "length").any() else "artefact points"),
           "rms_weighted": float(np.sqrt(np.mean(h["r"] ** 2))), "rows": int(len(e)),
           "chi2": float(np.sum(h["r"] ** 2)), "nuisance": int(h["nuisance"]), "held": int(h["held"]),
           "propagated": h["propagated"],
           "rms_over_stated": None,
           "chi2_stated": None, "rows_stated": 0}
    if stated is not None:
        sig = np.array([stated.sigma_of(k) or np.nan for k in h["kind"]])
        ok = np.isfinite(sig) & (sig > 0)
        if ok.any():
            z2 = (e[ok] / sig[ok]) ** 2
            out.update(rms_over_stated=float(np.sqrt(np.mean(z2))), chi2_stated=float(np.sum(z2)),
                       rows_stated=int(ok.sum()),
                       sigmas_stated=all(stated.stated_sigma_of(k) for k in set(h["kind"][ok].tolist())))
    by_kind: dict[str, dict] = {}
    out["by_kind"] = by_kind
    for k in dict.fromkeys(h["kind"].tolist()):
        ek = e[h["kind"] == k]
        by_kind[k] = {"rows": int(len(ek)), "rms_um": float(np.sqrt(np.mean(ek ** 2))) * 1e6,
                             "max_um": float(np.max(np.abs(ek))) * 1e6}
    u = bootstrap_rows(head, h["measurement"][art] if art.any() else h["measurement"], seed=seed)
    out["u_rms_um"], out["u_max_um"] = (None, None) if u is None else (u[0] * 1e6, u[1] * 1e6)
    if train is not None:
        val = validate_poses(model, p, data, train, weights, reference)
    else:
        try:
            val = validate(model, p, data, weights, reference, tracker)
        except InputError:                # a test instance with too few points for its own fit
            val = None
    summary, u_std = ({}, {}) if val is None else (val.summary(), bootstrap(val, seed=seed))
    if "reference_rms_predicted" in summary:     # the frames refitted on the held-out points: not a prediction
        summary = {k: v for k, v in summary.items() if k not in ("reference_rms", "reference_max")}
    out["standard"] = {k: summary[k] * FIGURES[k][2] for k in FIGURES if k in summary}
    out["u_standard"] = {k: None if u_std.get(k) is None else u_std[k] * FIGURES[k][2] for k in out["standard"]}
    return out


def bootstrap_rows(e: np.ndarray, measurement: np.ndarray, samples: int = BOOTSTRAP_SAMPLES, seed: int = 0):
    """Standard uncertainties [m] of the RMS and the max |e| of residual rows, by the bootstrap of
    :func:`calibration.validation.bootstrap` (whole measurements resampled with replacement); None
    with fewer than two measurements."""
    groups = [e[measurement == m] for m in dict.fromkeys(measurement.tolist())]
    if len(groups) < 2:
        return None
    rms, mx = np.empty(samples), np.empty(samples)
    for k, idx in enumerate(resamples(len(groups), samples, seed)):
        x = np.concatenate([groups[i] for i in idx])
        rms[k], mx[k] = np.sqrt(np.mean(x ** 2)), np.max(np.abs(x))
    return float(rms.std(ddof=1)), float(mx.std(ddof=1))


# ---------------------------------------------------------------------------------------------------

