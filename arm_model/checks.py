"""Input warnings: values a command uses but that lie outside what the arm declares (one place).

- ``over_force``: a contact force beyond the probe's calibrated range (``max_force_N`` of the
  description). Such points are used and flagged, never dropped.
- ``joint_limits``: an encoder angle beyond the joint's declared limits (``lower_deg``/``upper_deg``).

Every command that reads points logs these at WARNING (``warning: ...`` on standard error) and, when it writes a summary
and a report, lists them there too (``"warnings"`` of summary.json, a "Warnings" section of report.html).
"""
from __future__ import annotations

import html
import logging
import math
from dataclasses import dataclass

import numpy as np

__all__ = ["InputWarning", "over_force_warning", "joint_limit_warning", "JointLimitTally", "point_warnings",
           "log_warnings", "warnings_html", "LIMIT_TOLERANCE_RAD", "limit_bounds"]

log = logging.getLogger(__name__)

#: how far beyond a declared joint limit an angle may read before it is reported [rad] (1e-6 deg:
#: below every encoder's resolution, above the rounding of a file written in degrees)
LIMIT_TOLERANCE_RAD = 1e-6 * np.pi / 180.0
#: the same for a prismatic joint [m]: a nanometre
LIMIT_TOLERANCE_M = 1e-9
_SHOWN = 10


@dataclass(frozen=True)
class InputWarning:
    """``kind`` ("over_force", "joint_limits"), the ``message``, the ``file`` and the 1-based ``lines``
    of the rows concerned (all of them), and ``count``."""
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
    return f"{joint.lower * factor:.4g} to {joint.upper * factor:.4g} {unit}"


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


class JointLimitTally:
    """:func:`joint_limit_warning` over the blocks of one file read block by block (``aacmm tip`` on
    millions of rows): one warning for the whole file."""

    def __init__(self, desc, file: str):
        self.desc, self.file = desc, file
        self.per_joint = np.zeros(desc.n_joints, np.int64)
        self.lines = []

    def add(self, q, lines) -> None:
        q = np.atleast_2d(np.asarray(q, float))
        out = _beyond_limits(self.desc, q)
        self.per_joint[: q.shape[1]] += out.sum(axis=0)
        self.lines.append(np.asarray(lines)[out.any(axis=1)])

    def warning(self) -> InputWarning | None:
        lines = np.concatenate(self.lines) if self.lines else np.empty(0, np.int64)
        return _joint_limit_message(self.desc, self.per_joint, lines, self.file)


def point_warnings(desc, points, force=None) -> list[InputWarning]:
    """Both checks on a :class:`~arm_model.io.PointSet` (``force``: the (N, 3) forces the command
    uses, default the file's own force columns)."""
    lines = points.lines if points.lines is not None else np.arange(1, len(points) + 1)
    out = [joint_limit_warning(desc, points.q, lines, points.path),
           over_force_warning(points.force if force is None else force, lines, desc.probe.max_force,
                              points.path)]
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
