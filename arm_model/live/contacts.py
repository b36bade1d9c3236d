"""Contacts in a sample stream: from the force (a threshold with hysteresis and a minimum dwell) or from
the arm's button (the trigger), and the force peak of each (:func:`arm_model.peaks.contact_peak`).

Force (the default): a contact starts at the first sample whose force magnitude ``|F|`` reaches
``on`` and ends at the first sample below ``off`` (< ``on``); a contact shorter than ``dwell`` (from its
start to its end) is a bump, not a touch, and is counted but gives no point. The defaults (0.25 N,
0.15 N, 20 ms) find an operator's light touch of 0.5 N over a sensor noise of a few hundredths of a
newton: a noise of 0.03 N per channel puts ``on`` 8 standard deviations above zero and ``off`` 5, and
a noise sample never lasts 20 ms.

Trigger: a contact lasts while the trigger column is not 0 (the button held), whatever the force; its
point is at the force peak inside it (the first sample without a force sensor).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from ..peaks import contact_peak
from .samples import Sample

__all__ = ["ContactOptions", "Contact", "ContactDetector", "CONTACT_SOURCES"]

CONTACT_SOURCES = ("force", "trigger")


@dataclass(frozen=True)
class ContactOptions:
    """How contacts are found (see the module doc).

    Attributes:
        on: [N] force magnitude that starts a contact.
        off: [N] below it the contact ends (0 < off < on).
        dwell: [s] the shortest contact that gives a point.
        source: "force" or "trigger".
    """
    on: float = 0.25
    off: float = 0.15
    dwell: float = 0.02
    source: str = "force"

    def __post_init__(self):
        for name in ("on", "off", "dwell"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
                raise ValueError(f"{name} must be a finite number >= 0, got {v!r}")
        if not 0 < self.off < self.on:
            raise ValueError(f"the thresholds must satisfy 0 < off < on, got on {self.on:g} N, off {self.off:g} N")
        if self.source not in CONTACT_SOURCES:
            raise ValueError(f"source must be one of {', '.join(CONTACT_SOURCES)}, got {self.source!r}")


@dataclass(frozen=True)
class Contact:
    """One contact: ``index`` (1-based, points and contacts share it), ``start`` and ``end`` [s] (the
    first sample in it and the first after it, or the last one when the stream ended in contact),
    ``samples`` in it, its ``peak`` sample (:class:`~arm_model.live.samples.Sample`, the point's), the
    force magnitude there (``peak_force`` [N]) and ``line``: the stream line of the peak (None from
    Python)."""
    index: int
    start: float
    end: float
    samples: int
    peak: Sample
    peak_force: float
    line: int | None = None

    @property
    def duration(self) -> float:
        return self.end - self.start


class ContactDetector:
    """Feeds on samples one at a time (:meth:`feed`) and returns each contact when it ends.

    Attributes:
        options: :class:`ContactOptions`.
        bumps: contacts shorter than the dwell (no point).
        count: contacts returned.
    """

    def __init__(self, options: ContactOptions):
        self.options = options
        self._by_force = options.source == "force"
        self._on, self._off, self._dwell = options.on, options.off, options.dwell
        self._buf: list | None = None       # samples of the open contact
        self._mags: list = []
        self._lines: list = []
        self.bumps = 0
        self.count = 0

    @property
    def in_contact(self) -> bool:
        return self._buf is not None

    def feed(self, s: Sample, magnitude: float, line: int | None = None) -> Contact | None:
        """One sample and its force magnitude [N] (0 without a force sensor); the contact it ends, if any."""
        buf = self._buf
        inside = magnitude >= self._off if self._by_force else bool(s.trigger)
        if buf is None:
            if (magnitude >= self._on) if self._by_force else inside:
                self._buf, self._mags, self._lines = [s], [magnitude], [line]
            return None
        if inside:
            buf.append(s)
            self._mags.append(magnitude)
            self._lines.append(line)
            return None
        return self._close(s.t)

    def finish(self) -> Contact | None:
        """The stream ended: the open contact, if any, ends at its last sample."""
        if self._buf is None:
            return None
        return self._close(self._buf[-1].t)

    def _close(self, end: float) -> Contact | None:
        buf, mags, lines = self._buf, self._mags, self._lines
        self._buf, self._mags, self._lines = None, [], []
        if self._by_force and end - buf[0].t < self._dwell:
            self.bumps += 1
            return None
        k = contact_peak(mags) if self._by_force or any(mags) else 0
        self.count += 1
        return Contact(self.count, buf[0].t, end, len(buf), buf[k], mags[k], lines[k])
