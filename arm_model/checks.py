"""Input warnings: values a command uses but that lie outside what the arm declares (one place).

- ``over_force``: a contact force beyond the probe's calibrated range (``max_force_N`` of the
  description). Such points are used and flagged, never dropped.
- ``joint_limits``: an encoder angle beyond the joint's declared limits (``lower_deg``/``upper_deg``).
- ``angle_units``: every angle of every revolute joint, in every row, within +-2 pi degrees (6.28 deg): what a file
  whose angles were written in radians under its ``_deg`` columns looks like (no measuring pose keeps the whole arm
  that straight). The angles are used as degrees, as the columns say.
- ``duplicate_rows``: rows that repeat an earlier reading exactly (measurement, feature and every reading of the
  pose, the time and temperature aside: :func:`repeated_readings`): a copy says nothing its first did not, and
  counted as one more independent observation it would narrow every uncertainty and the evidence's prior scales
  as if the point had been measured again (a file written twice, a logger that wrote one reading several times).
  A fit counts each reading once.

Every command that reads points logs these at WARNING (``warning: ...`` on standard error) and, when it writes a summary
and a report, lists them there too (``"warnings"`` of summary.json, a "Warnings" section of report.html).
"""
from __future__ import annotations

import html
import logging
import math
from dataclasses import dataclass

import numpy as np

__all__ = ["InputWarning", "over_force_warning", "joint_limit_warning", "radians_warning", "JointLimitTally",
           "repeated_readings", "duplicate_rows_warning", "point_warnings",
           "log_warnings", "warnings_html", "LIMIT_TOLERANCE_RAD", "limit_bounds"]

log = logging.getLogger(__name__)

#: how far beyond a declared joint limit an angle may read before it is reported [rad] (1e-6 deg:
#: below every encoder's resolution, above the rounding of a file written in degrees)
LIMIT_TOLERANCE_RAD = 1e-6 * np.pi / 180.0
#: the same for a prismatic joint [m]: a nanometre
LIMIT_TOLERANCE_M = 1e-9
#: every revolute reading of a file within +-this [rad] (2 pi degrees: radians read as degrees) is warned
RADIAN_LIKE_RAD = math.radians(2.0 * math.pi)
_SHOWN = 10


@dataclass(frozen=True)
class InputWarning:
    """``kind`` ("over_force", "joint_limits", "angle_units", "duplicate_rows"), the ``message``, the ``file`` and
    the 1-based ``lines`` of the rows concerned (all of them), and ``count``."""
    kind: str
    message: str
    file: str
    lines: tuple

    @property
    def count(self) -> int:
        return len(self.lines)

    def as_dict(self) -> dict:
        return {"kind": self.kind, "message": self.message, "file": self.file, "count": self.count,
                "lines": [int(v) for v in self.lines]}


def _lines_text(lines) -> str:
    shown = ", ".join(str(int(v)) for v in lines[:_SHOWN])
    return f"line{'s' if len(lines) > 1 else ''} {shown}" + (" ..." if len(lines) > _SHOWN else "")


def over_force_warning(force, lines, max_force: float, file: str) -> InputWarning | None:
    """A warning for the rows whose force magnitude [N] exceeds ``max_force`` [N], or None.

    Args:
        force: (N, 3) forces [N] (from the points file's columns or the force signals' peaks).
        lines: (N,) the rows' lines in ``file``.
    """
    if force is None or len(force) == 0:
        return None
    mag = np.linalg.norm(np.asarray(force, float), axis=1)
    over = np.flatnonzero(mag > max_force)
    if not len(over):
        return None
    lines = tuple(int(v) for v in np.asarray(lines)[over])
    return InputWarning(
        "over_force",
        f"{len(over)} point(s) with a force over the probe's calibrated range ({max_force:g} N; largest "
        f"{mag[over].max():.3g} N): used and flagged, not dropped; {file} {_lines_text(lines)}",
        file, lines)


def limit_bounds(desc) -> list[tuple[float, float]]:
    """Per joint, the (lowest, highest) angle [rad] read without a joint-limit warning: the declared
    limits widened by :data:`LIMIT_TOLERANCE_RAD` (-inf, inf where a joint declares none)."""
    return [(-math.inf if j.lower is None else j.lower - LIMIT_TOLERANCE_RAD,
             math.inf if j.upper is None else j.upper + LIMIT_TOLERANCE_RAD) for j in desc.joints]


def _beyond_limits(desc, q) -> np.ndarray:
    """(N, J) True where an encoder reading (an angle [rad], a prismatic joint's position [m]) lies beyond
    its joint's declared limits."""
    out = np.zeros(q.shape, bool)
    for j, joint in enumerate(desc.encoders[: q.shape[1]]):
        tol = LIMIT_TOLERANCE_M if joint.prismatic else LIMIT_TOLERANCE_RAD
        if joint.lower is not None:
            out[:, j] |= q[:, j] < joint.lower - tol
        if joint.upper is not None:
            out[:, j] |= q[:, j] > joint.upper + tol
    return out


def _limits_text(joint) -> str:
    unit, factor = ("mm", 1e3) if joint.prismatic else ("deg", 180.0 / np.pi)
    # + 0.0: a limit of -0.0 (a description written "-0") reads "0", not "-0"
    return f"{joint.lower * factor + 0.0:.4g} to {joint.upper * factor + 0.0:.4g} {unit}"


def _joint_limit_message(desc, per_joint, lines, file: str) -> InputWarning | None:
    if not len(lines):
        return None
    names = []
    for joint, count in zip(desc.encoders, per_joint, strict=True):
        if count:
            names.append(f"{joint.name} ({int(count)}, limits {_limits_text(joint)})"
                         if joint.lower is not None and joint.upper is not None else f"{joint.name} ({int(count)})")
    lines = tuple(np.asarray(lines).tolist())
    return InputWarning(
        "joint_limits",
        f"{len(lines)} point(s) with a joint reading beyond the arm's declared limits: "
        f"{', '.join(names)}; used all the same (check the arm description or the encoder zero); "
        f"{file} {_lines_text(lines)}", file, lines)


def joint_limit_warning(desc, q, lines, file: str) -> InputWarning | None:
    """A warning for the rows with an encoder angle beyond its joint's declared limits, or None."""
    q = np.atleast_2d(np.asarray(q, float))
    if q.size == 0:
        return None
    out = _beyond_limits(desc, q)
    return _joint_limit_message(desc, out.sum(axis=0), np.asarray(lines)[out.any(axis=1)], file)


#: the fewest rows a file's angles are judged on (one pose near the straight arm is a pose)
_RADIAN_ROWS = 3


def _largest_revolute(desc, q, units) -> float:
    """The largest |reading| [rad] of the revolute encoders in ``q`` (N, J) written in degrees (``units``: each
    column's unit as the file wrote it); -1 when there is none."""
    cols = [j for j, joint in enumerate(desc.encoders[: q.shape[1]])
            if not joint.prismatic and units is not None and j < len(units) and units[j] == "deg"]
    return float(np.max(np.abs(q[:, cols]))) if cols and q.size else -1.0


def _radians_message(largest: float, lines, file: str) -> InputWarning | None:
    if len(lines) < _RADIAN_ROWS or not 0.0 <= largest <= RADIAN_LIKE_RAD:
        return None
    lines = tuple(np.asarray(lines).tolist())
    return InputWarning(
        "angle_units",
        f"every angle of every revolute joint, in all {len(lines)} point(s), lies within "
        f"+-{math.degrees(RADIAN_LIKE_RAD):.2f} deg (largest |angle| {math.degrees(largest):.3g} deg): were the "
        f"angles written in radians? The angle columns (_deg) are degrees and are used as such; {file} "
        f"{_lines_text(lines)}", file, lines)


def radians_warning(desc, q, lines, file: str, units) -> InputWarning | None:
    """A warning when every revolute encoder reading written in degrees (``units``: each joint column's unit, as
    :attr:`~arm_model.io.PointSet.q_units`) lies within :data:`RADIAN_LIKE_RAD` in at least 3 rows (angles written
    in radians in a degree column), or None."""
    q = np.atleast_2d(np.asarray(q, float))
    return _radians_message(_largest_revolute(desc, q, units), lines, file)


class JointLimitTally:
    """:func:`joint_limit_warning` and :func:`radians_warning` over the blocks of one file read block by block
    (``aacmm tip`` on millions of rows): one warning each for the whole file. The lines of a radian-like file are
    kept only while every block read is radian-like."""

    def __init__(self, desc, file: str):
        self.desc, self.file = desc, file
        self.per_joint = np.zeros(desc.n_joints, np.int64)
        self.lines = []
        self.largest = -1.0                 # the largest revolute |reading| so far [rad]
        self.radian_lines = []

    def add(self, q, lines, units=None) -> None:
        """Take in a block's readings ``q`` [rad or m], its rows' ``lines`` and its joint columns' ``units``."""
        q = np.atleast_2d(np.asarray(q, float))
        out = _beyond_limits(self.desc, q)
        self.per_joint[: q.shape[1]] += out.sum(axis=0)
        self.lines.append(np.asarray(lines)[out.any(axis=1)])
        self._radian_like(_largest_revolute(self.desc, q, units), [np.asarray(lines)])

    def merge(self, other: JointLimitTally) -> None:
        """Take in the tally of another part of the same file."""
        self.per_joint += other.per_joint
        self.lines += other.lines
        self._radian_like(other.largest, other.radian_lines)

    def _radian_like(self, largest: float, radian_lines: list) -> None:
        self.largest = max(self.largest, largest)
        self.radian_lines = self.radian_lines + radian_lines if self.largest <= RADIAN_LIKE_RAD else []

    def warning(self) -> InputWarning | None:
        lines = np.concatenate(self.lines) if self.lines else np.empty(0, np.int64)
        return _joint_limit_message(self.desc, self.per_joint, lines, self.file)

    def warnings(self) -> list[InputWarning]:
        """The joint-limit and the angle-unit warnings of the file (those that apply)."""
        lines = np.sort(np.concatenate(self.radian_lines)) if self.radian_lines else np.empty(0, np.int64)
        return [w for w in (self.warning(), _radians_message(self.largest, lines, self.file)) if w is not None]


def repeated_readings(points, labels=()) -> np.ndarray:
    """(N,) for each row of ``points`` (a :class:`~arm_model.io.PointSet`) the index of the earlier row it repeats, -1
    for none: the same measurement, feature and session (and ``labels``: further (N,) arrays that must agree) and,
    bit for bit, the same pose: joints, forces, torques, reference coordinates and move signs. The time and the
    temperature may differ (a logger that wrote one reading several times stamps each copy anew; the temperature is
    the room's, not the pose's). A copy says nothing the first did not (its errors are the first's), so a fit counts
    each reading once (:class:`calibration.problem.Problem`)."""
    n = len(points.q)
    cols = [np.asarray(a, float).reshape(n, -1) for a in (points.q, points.force, points.torque, points.ref,
                                                        points.motion) if a is not None]
    values = np.ascontiguousarray(np.hstack(cols))
    session = points.session if points.session is not None else np.full(n, "")
    first: dict = {}
    out = np.full(n, -1)
    for i in range(n):
        key = (str(points.measurement[i]), str(points.feature[i]), str(session[i]),
               *(str(lab[i]) for lab in labels), values[i].tobytes())
        out[i] = first.setdefault(key, i)
    out[out == np.arange(n)] = -1
    return out


def duplicate_rows_warning(points, lines, file: str) -> InputWarning | None:
    """A warning for the rows of ``points`` (a :class:`~arm_model.io.PointSet`) that repeat an earlier reading
    (:func:`repeated_readings`), or None. ``lines``: the rows' lines in ``file`` (those of the copies are
    reported)."""
    copies = np.flatnonzero(repeated_readings(points) >= 0)
    if not len(copies):
        return None
    rows = tuple(int(v) for v in np.asarray(lines)[copies])
    return InputWarning(
        "duplicate_rows",
        f"{len(rows)} row(s) repeat an earlier reading exactly (measurement, feature, joints, force and every "
        f"reading of the pose; the time and temperature may differ): a copy says nothing its first did not (its "
        f"errors are the first's), so a fit counts each reading once, as one observation (remove the copies if the "
        f"file holds rows twice; articulate again to measure a pose again); {file} {_lines_text(rows)}", file, rows)


def point_warnings(desc, points, force=None) -> list[InputWarning]:
    """The four checks on a :class:`~arm_model.io.PointSet` (``force``: the (N, 3) forces the command
    uses, default the file's own force columns)."""
    lines = points.lines if points.lines is not None else np.arange(1, len(points) + 1)
    out = [joint_limit_warning(desc, points.q, lines, points.path),
           radians_warning(desc, points.q, lines, points.path, points.q_units),
           over_force_warning(points.force if force is None else force, lines, desc.probe.max_force,
                              points.path),
           duplicate_rows_warning(points, lines, points.path)]
    return [w for w in out if w is not None]


def log_warnings(warnings, logger: logging.Logger | None = None) -> None:
    """Each warning logged at WARNING (``warning: <message>`` on standard error under ``aacmm``; shown
    with ``--quiet`` too)."""
    for w in warnings:
        (logger or log).warning(w.message)


def warnings_html(warnings) -> str:
    """A "Warnings" section of a report (empty text when there are none); ``warnings`` are
    :class:`InputWarning` or their :meth:`~InputWarning.as_dict`."""
    if not warnings:
        return ""
    items = "".join(f"<li>{html.escape(w['message'] if isinstance(w, dict) else w.message)}</li>"
                    for w in warnings)
    return f"<h2>Warnings</h2><ul class='warnings'>{items}</ul>"
