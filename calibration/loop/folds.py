"""The folds of the held-out decisions: the outer test set put aside (:func:`outer_split`) and the folds of the
design set the candidates are cross-validated on (:class:`Folds`, :func:`choose_folds`), with whether their
test can reach its level."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from arm_model import InputError

from ..data import CalibrationData, split_holdout, split_poses, spread
from ..diagnostics import measurement_folds, measurement_groups, pose_folds
from .settings import STABILITY_RULE, LoopSettings, wilcoxon_units_needed

__all__ = ["Folds", "outer_split", "spread_measurements", "check_fold_by", "choose_folds"]




@dataclass(frozen=True)
class Folds:
    """The folds of the design set for the held-out decisions.

    Attributes:
        by: "measurement" (whole measurements held out) or "pose" (poses inside each feature, predicted
            against the feature's centre fitted on its other poses).
        k: number of folds.
        assign: measurement id -> fold (by measurement), or the fold of every design point (-1: never held).
        per_pose: by measurement, the units of the paired test are the held-out poses (each against its
            held-out measurement's own centre) instead of whole measurements: with few measurements (one
            plate at a few placements) the test can still reach its level.
        n_poses: held-out poses over all folds (by measurement with ``per_pose``).
    """
    by: str
    k: int
    assign: object
    per_pose: bool = False
    n_poses: int = 0

    @property
    def units(self) -> int:
        """Held-out units of the paired test: measurements, or poses."""
        if self.by == "pose":
            return int(np.sum(np.asarray(self.assign) >= 0))
        return self.n_poses if self.per_pose else len(self.assign)

    @property
    def unit_name(self) -> str:
        return "measurements" if self.by == "measurement" and not self.per_pose else "poses"



def outer_split(data: CalibrationData, settings: LoopSettings):
    """(design, test, "measurement" | "pose", the test rows of ``data`` (N,) bool): the measurements
    ``settings.holdout`` if named, else a share ``test_fraction`` of the measurements
    (:func:`spread_measurements`), else, with too few measurements for that, the same share of the poses of
    every feature (:func:`calibration.data.split_poses`). No seed: the test set is a function of the data, so
    the loop's verdict on the same data is the same."""
    ids = list(settings.holdout) or spread_measurements(data, settings.test_fraction)
    if ids:
        design, test = split_holdout(data, ids)
        return design, test, "measurement", np.isin(data.points.measurement, test.measurements())
    held = split_poses(data, settings.test_fraction)
    if not held.any():
        raise InputError(f"the test set is empty: {len(data.measurements())} measurement(s) and no feature has "
                         "enough poses to hold some out; give more measurements or name a test measurement "
                         "(--holdout ID)", data.points.path, None, "measurement")
    return data.select(~held), data.select(held), "pose", held


def spread_measurements(data: CalibrationData, fraction: float) -> list[str]:
    """A share ``fraction`` of the measurements of each group that touches the same feature kinds
    (:func:`calibration.diagnostics.measurement_groups`, ids sorted), at evenly spaced ranks
    (:func:`calibration.data.spread`); every group keeps one measurement at least. Empty when no group has
    enough measurements to give one."""
    out = []
    for members in measurement_groups(data):
        k = min(int(round(fraction * len(members))), len(members) - 1)
        out += [members[i] for i in spread(len(members), k)] if k > 0 else []
    return out


def check_fold_by(design: CalibrationData, settings: LoopSettings) -> None:
    """Folds of whole measurements (``fold_by="measurement"``) need at least 2 design measurements: an
    :class:`InputError` otherwise, said before any fit (the design set is the data less the outer test set,
    :func:`outer_split`)."""
    n_meas = len(design.measurements())
    if settings.fold_by == "measurement" and n_meas < 2:
        raise InputError(f"--fold-by measurement: {n_meas} design measurement(s) (the measurements the outer test set "
                         "leaves): folds of whole measurements need at least 2; fold by pose (--fold-by pose), or "
                         "give more measurements", design.points.path, None, "measurement")


def choose_folds(design: CalibrationData, settings: LoopSettings) -> tuple[Folds, dict]:
    """The folds of the decisions and, decided before any test runs, whether the held-out test can reach
    its level with them (a one-sided Wilcoxon test over n units cannot go below p = 1/2^n). A stage tests at most
    ``cv_top`` of the library's candidates and, when nothing passed and effects are built from the residual,
    ``cv_top`` of those: the level is the one the last of them is held to, ``alpha / (2 cv_top)``. (With
    ``alpha / cv_top`` a robot's 9 design placements of a seat bar were said to reach it, and the coupling built
    from the residual then failed at p = 1/2^9 = 0.002 >= 0.0017 with every placement better:
    scripts/robot_hidden_study.py, ``coupling``.)"""
    tests = settings.cv_top * (2 if settings.synthesise else 1)
    level = settings.alpha / tests
    need = wilcoxon_units_needed(settings.alpha, tests)
    n_meas = len(design.measurements())
    by = settings.fold_by
    if by == "auto":
        by = "measurement" if n_meas >= 2 else "pose"
    if by == "measurement":
        check_fold_by(design, settings)
        k = min(settings.folds, n_meas)          # said in the note when fewer than asked
        assign = measurement_folds(design, k)
        per_pose = settings.fold_by == "auto" and n_meas < need
        n_poses = int(sum(np.sum(design.points.feature[design.points.measurement == m] != "") for m in assign))
        folds = Folds("measurement", k, assign, per_pose, n_poses)
    else:
        folds = Folds("pose", settings.folds, pose_folds(design, settings.folds, settings.pose_folds == "blocked"))
        if folds.units < folds.k:
            raise InputError(f"--folds {folds.k}: the design set has {folds.units} poses that can be held out (a "
                             "feature keeps the poses its own fit needs); give at most that many folds by pose")
    n = folds.units
    smallest = 0.5 ** n if n else 1.0
    ok = smallest < level
    power = {"fold_by": folds.by, "pose_folds": settings.pose_folds if folds.by == "pose" else None,
             "folds": folds.k, "units": n, "unit": folds.unit_name, "needed": need,
             "smallest_p": smallest, "level": level, "can_reach": ok, "stability_rule": STABILITY_RULE}
    why = "" if folds.k == settings.folds else f" (--folds {settings.folds}: only {n_meas} design measurements)"
    if folds.by == "pose" and settings.fold_by == "auto":
        why = f" (only {n_meas} design measurement: whole measurements cannot be held out)"
    if folds.by == "pose" and settings.pose_folds == "blocked":
        why += ", blocks of the joint space"
    elif folds.per_pose:
        why += (f", {folds.k} of {n_meas} measurements held out in turn, the test over their poses (each against "
               f"its measurement's own centre: {n_meas} measurements are too few units)")
    if ok:
        power["note"] = (f"decisions: {folds.k} folds by {by}{why}; one-sided Wilcoxon over {n} {folds.unit_name} "
                         f"(smallest possible p = 1/2^{n} < {level:.2g} = alpha / {tests} candidates), and "
                         f"{STABILITY_RULE}")
    else:
        fix = ("more measurements, or folds by pose (--fold-by pose)" if by == "measurement"
               else "more poses on each feature, or more measurements")
        power["note"] = (f"WARNING: the held-out test cannot reach its level with these data: one-sided Wilcoxon "
                         f"over {n} {folds.unit_name} has smallest p = 1/2^{n} = {smallest:.3g} >= "
                         f"{level:.2g} = alpha {settings.alpha:g} / {tests} candidates; it needs at least {need} "
                         f"{folds.unit_name} (n >= log2({tests} / {settings.alpha:g})): {fix}, or a larger "
                         f"--alpha or a smaller --cv-top. No effect can be added.")
    return folds, power

