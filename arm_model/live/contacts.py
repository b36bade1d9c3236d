"""Contacts in a sample stream: from the force (a threshold with hysteresis and a minimum dwell) or from
the arm's button (the trigger), and the force peak of each (:func:`arm_model.peaks.contact_peak`).

Force (the default). The force is first smoothed (an exponential moving average of each channel, time
constant ``smooth``, 5 ms) and its baseline removed (the sensor's reading without contact: a slow moving
average, time constant ``baseline``, 2 s, of the samples out of contact, which follows a zero offset
and its drift). The first 0.1 s of the stream set the zero and the noise and start no contact (start
the stream with the probe free; a first reading of 1 N or more is taken as a contact, the zero then
0 until it ends). A contact starts at the first sample where this smoothed, zeroed force ``|F|`` reaches
``on`` and ends at the first sample where it falls below ``off`` (< ``on``); it gives a point only if the
force (zeroed, not smoothed) stayed at or above ``on`` for ``dwell`` in all, else it is a bump (counted, no
point). The defaults (0.1 N, 0.05 N, 20 ms) find an operator's lightest touches, 0.15 N, over a sensor
noise of a few hundredths of a newton: the smoothing divides a white noise by about 3, so a noise of
0.03 N per channel puts ``on`` about 10 standard deviations above zero and ``off`` 5; a sensor offset
is followed by the baseline. The thresholds are raised (never lowered) to 8 and 4 times the smoothed
noise that the samples out of contact show (estimated at the end of the warm-up, then every
:data:`NOISE_EVERY` of them), so a noisier
sensor does not make contacts of its noise.

The point of a contact is at its force peak on the raw readings: the sample of largest ``|F|`` (the
paper's extraction, :func:`arm_model.peaks.contact_peak`), the same sample ``aacmm ring --signals`` would
take.

Trigger: a contact lasts while the trigger column is not 0 (the button held), whatever the force; its
point is at the force peak inside it (the first sample without a force sensor).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ..peaks import contact_peak, signal_noise
from .samples import Sample, SampleBlock

__all__ = ["ContactOptions", "Contact", "ContactDetector", "CONTACT_SOURCES", "NOISE_EVERY", "NOISE_ON", "NOISE_OFF"]

CONTACT_SOURCES = ("force", "trigger")
#: the first reading is taken as the sensor's zero when its magnitude is below this [N] (start with the probe
#: free); a larger one is taken as a contact, the zero then staying 0 until the first contact ends
FIRST_ZERO_N = 1.0
#: samples out of contact between two estimates of the noise (the first at the end of the warm-up), and
#: the fewest an estimate takes
NOISE_EVERY, NOISE_LEAST = 1000, 20
#: the first samples, while the probe is free, only set the sensor's zero and noise [s]
WARMUP_S = 0.1
#: the thresholds are at least these many times the smoothed force's noise
NOISE_ON, NOISE_OFF = 8.0, 4.0


@dataclass(frozen=True)
class ContactOptions:
    """How contacts are found (see the module doc).

    Attributes:
        on: [N] zeroed, smoothed force magnitude that starts a contact.
        off: [N] below it the contact ends (0 < off < on).
        dwell: [s] how long the zeroed force must stay at or above ``on`` for a point.
        source: "force" or "trigger".
        smooth: [s] time constant of the smoothing.
        baseline: [s] time constant of the baseline (0: the force is not zeroed).
    """
    on: float = 0.1
    off: float = 0.05
    dwell: float = 0.02
    source: str = "force"
    smooth: float = 0.005
    baseline: float = 2.0

    def __post_init__(self):
        for name in ("on", "off", "dwell", "smooth", "baseline"):
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
        bumps: contacts that did not hold the force for the dwell (no point).
        count: contacts returned.
        on, off: the thresholds in force [N] (the options', raised to the noise when it demands).
        noise: the smoothed force's noise [N] last estimated (its largest channel; None before).
        raw_noise: (3,) the sensor's noise per channel [N] last estimated (None before).
    """

    def __init__(self, options: ContactOptions):
        self.options = options
        self._by_force = options.source == "force"
        self.on, self.off = options.on, options.off
        self._buf: _Samples | None = None   # samples of the open contact
        self._mags: list = []
        self._lines: list = []
        self._held = 0.0                    # time the zeroed force stayed >= on in the open contact [s]
        self._fs = None                     # smoothed force (3 channels) [N]
        self._base = [0.0, 0.0, 0.0]        # baseline [N]
        self._t = None
        self._dt = 0.0
        self._a_smooth, self._a_base = 1.0, 0.0
        self._known: dict = {}              # interval [s] -> the factors of the moving averages
        self._n_base = 1
        self._warm: float | None = None     # the start of the warm-up, while it lasts
        self._idle: list = []               # smoothed-minus-baseline x of samples out of contact
        self.noise: float | None = None
        self.raw_noise = None
        self.bumps = 0
        self.count = 0
        #: when :meth:`feed_rows` came to the row that ended the last contact it closed [s, ``time.perf_counter``]
        self.closed_at = 0.0

    @property
    def in_contact(self) -> bool:
        return self._buf is not None

    @property
    def level(self) -> float:
        """The zeroed, smoothed force magnitude of the last sample [N]."""
        if self._fs is None:
            return 0.0
        b = self._base
        return math.sqrt((self._fs[0] - b[0]) ** 2 + (self._fs[1] - b[1]) ** 2 + (self._fs[2] - b[2]) ** 2)

    def feed(self, s: Sample, magnitude: float, line: int | None = None) -> Contact | None:
        """One sample and its raw force magnitude [N] (0 without a force sensor); the contact it ends, if
        any."""
        if self._by_force:
            level, raw = self._smooth(s)
            if self._warm is not None and s.t - self._warm < WARMUP_S:
                self._follow(s)         # the first samples set the zero and the noise
                return None
            if self._warm is not None:
                self._warm = None
                self._noise(self._idle)
            inside = level >= self.off
            starts = level >= self.on
        else:
            inside = starts = bool(s.trigger)
            raw = 0.0
        buf = self._buf
        if buf is None:
            if starts:
                self._buf, self._mags, self._lines = _Samples(s), [magnitude], [line]
                self._held = 0.0
                self._hold(raw, s.t)
            elif self._by_force:
                self._follow(s)
            return None
        if inside:
            buf.add(s)
            self._mags.append(magnitude)
            self._lines.append(line)
            self._hold(raw, s.t)
            return None
        return self._close(s.t)

    def _smooth(self, s: Sample) -> tuple[float, float]:
        """Update the smoothed force; (smoothed, raw) zeroed magnitudes [N]."""
        w, b = s.wrench, self._base
        if w is None:
            return 0.0, 0.0
        fs = self._fs
        if fs is None:
            fs = self._fs = [w[0], w[1], w[2]]
            if self.options.baseline > 0 and math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]) < FIRST_ZERO_N:
                b[:] = fs                   # the probe free at the start: the zero and the noise first
                self._warm = s.t
        else:
            dt = s.t - self._t
            if dt != self._dt:              # the factors of this interval (mostly the last one's)
                self._alphas(dt)
            a = self._a_smooth
            fs[0] += a * (w[0] - fs[0])
            fs[1] += a * (w[1] - fs[1])
            fs[2] += a * (w[2] - fs[2])
        self._t = s.t
        dx, dy, dz = fs[0] - b[0], fs[1] - b[1], fs[2] - b[2]
        rx, ry, rz = w[0] - b[0], w[1] - b[1], w[2] - b[2]
        return math.sqrt(dx * dx + dy * dy + dz * dz), math.sqrt(rx * rx + ry * ry + rz * rz)

    def _alphas(self, dt: float) -> None:
        """The moving averages' factors for an interval ``dt`` [s] (remembered: the intervals of a stream's time
        stamps take a few values, which their rounding makes differ from one sample to the next)."""
        self._dt = dt
        known = self._known.get(dt)
        if known is None:
            o = self.options
            known = (1.0 - math.exp(-dt / o.smooth) if o.smooth > 0 else 1.0,
                     1.0 - math.exp(-dt / o.baseline) if o.baseline > 0 else 0.0)
            if len(self._known) >= _KNOWN_DT:
                self._known.clear()
            self._known[dt] = known
        self._a_smooth, self._a_base = known

    def _hold(self, raw: float, t: float) -> None:
        if raw >= self.on:
            self._held += self._dt if self._by_force else 0.0

    def _follow(self, s: Sample) -> None:
        """Out of contact: the baseline follows the smoothed force; every :data:`NOISE_EVERY` samples the
        thresholds are checked against the noise."""
        fs, b = self._fs, self._base
        if fs is None:
            return
        if self.options.baseline > 0:
            self._n_base += 1           # the mean of the samples so far, until the time constant takes over
            a = max(1.0 / self._n_base, self._a_base)
            b[0] += a * (fs[0] - b[0])
            b[1] += a * (fs[1] - b[1])
            b[2] += a * (fs[2] - b[2])
        idle = self._idle
        idle.append(s.wrench)
        if len(idle) >= NOISE_EVERY:
            self._noise(idle)
            idle.clear()

    def _noise(self, idle: list) -> None:
        """The sensor's noise per channel [N] (:func:`arm_model.peaks.signal_noise` of the raw readings out of
        contact), the smoothed force's (the largest channel's, through the moving average) and the
        thresholds raised to it."""
        if len(idle) < NOISE_LEAST:
            return
        x = np.array(idle, float)[:, :3]
        self.raw_noise = np.array([signal_noise(x[:, k]) for k in range(3)])
        a = self._a_smooth
        self.noise = float(self.raw_noise.max() * math.sqrt(a / (2.0 - a)))  # type: ignore[attr-defined]
        self.on = max(self.options.on, NOISE_ON * self.noise)
        self.off = max(self.options.off, NOISE_OFF * self.noise, 0.0)
        if self.off >= self.on:
            self.off = 0.5 * self.on

    def finish(self) -> Contact | None:
        """The stream ended: the open contact, if any, ends at its last sample."""
        if self._buf is None:
            return None
        return self._close(self._buf.last_t)

    def shift(self, dt: float) -> None:
        """The stream's clock jumped: move the detector's times by ``dt`` [s] so that the next sample follows
        the last one by a nominal interval (its smoothing, baseline and warm-up go on across the jump)."""
        if self._t is not None:
            self._t += dt
        if self._warm is not None:
            self._warm += dt

    def _close(self, end: float) -> Contact | None:
        buf, mags, lines = self._buf, self._mags, self._lines
        assert buf is not None, "closed only while a contact is open"
        self._buf, self._mags, self._lines = None, [], []
        if self._by_force and self._held < self.options.dwell:
            self.bumps += 1
            return None
        k = contact_peak(mags) if self._by_force or any(mags) else 0
        self.count += 1
        return Contact(self.count, buf.first_t, end, len(buf), buf[k], mags[k], lines[k])

    # -- samples that came together ---------------------------------------------------------------
    def ready(self, has_force: bool) -> bool:
        """True when :meth:`feed_rows` may take the next samples (the warm-up and the first reading are taken one
        by one)."""
        return not self._by_force or not has_force or (self._fs is not None and self._warm is None)

    def feed_rows(self, rows: SampleBlock, a: int, b: int, changes: list) -> tuple[int, Contact | None]:
        """Rows ``a`` to ``b - 1`` of ``rows`` (samples on the stream's clock, after :meth:`ready`), as :meth:`feed`
        on each in turn (the same arithmetic in the same order, so the same contacts, peaks and thresholds); stops
        after the first row that ends a contact with a point: (the next row, the contact), else (b, None).
        ``changes`` gets each row at which a contact opens or ends (the rows after it are in, or out);
        :attr:`closed_at` the moment it came to the row that ended the contact (its peak is found after it)."""
        if not self._by_force:
            return self._trigger_rows(rows, a, b, changes)
        if rows.wrench is None:             # no force sensor: no contact, nothing followed
            return b, None
        t, fx, fy, fz = rows.t, rows.fx, rows.fy, rows.fz
        fs, base = self._fs, self._base
        assert fs is not None and fx is not None and fy is not None and fz is not None
        f0, f1, f2 = fs
        b0, b1, b2 = base
        tp, dtp, a_s, a_b = self._t, self._dt, self._a_smooth, self._a_base
        on, off, held_t, n_base = self.on, self.off, self._held, self._n_base
        zero, idle, buf, known = self.options.baseline > 0, self._idle, self._buf, self._known
        opened = a if buf is not None else None             # the first row of this call in the open contact
        free = a                                            # the first row out of contact not yet in ``idle``
        n_idle = len(idle)
        k, found = a, None
        while k < b:
            tk = t[k]
            dt = tk - tp
            if dt != dtp:
                factors = known.get(dt)
                if factors is None:
                    self._alphas(dt)
                    factors = self._a_smooth, self._a_base
                dtp, (a_s, a_b) = dt, factors
            x, y, z = fx[k], fy[k], fz[k]
            f0 += a_s * (x - f0)
            f1 += a_s * (y - f1)
            f2 += a_s * (z - f2)
            tp = tk
            d0, d1, d2 = f0 - b0, f1 - b1, f2 - b2
            level = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            if opened is None:
                if level >= on:                             # a contact opens
                    idle += rows.wrench_rows(free, k)
                    opened, held_t = k, 0.0
                    changes.append(k)
                    buf = self._buf = _Samples()
                    self._mags, self._lines = [], []
                else:
                    if zero:
                        n_base += 1
                        a_f = 1.0 / n_base                  # max(1 / n, a_b)
                        if a_f < a_b:
                            a_f = a_b
                        b0 += a_f * (f0 - b0)
                        b1 += a_f * (f1 - b1)
                        b2 += a_f * (f2 - b2)
                    n_idle += 1
                    k += 1
                    if n_idle >= NOISE_EVERY:
                        idle += rows.wrench_rows(free, k)
                        free, n_idle = k, 0
                        self._a_smooth = a_s                # the factor of the last interval, as feed leaves it
                        self._noise(idle)
                        idle.clear()
                        on, off = self.on, self.off
                    continue
            elif level < off:                               # it ends here
                self._keep(rows, opened, k)
                changes.append(k)
                opened = None
                self._t, self._held, self._fs[:], self._base[:] = tp, held_t, (f0, f1, f2), (b0, b1, b2)
                self._n_base, self._dt, self._a_smooth, self._a_base = n_base, dtp, a_s, a_b
                self.closed_at = time.perf_counter()
                found = self._close(tk)
                k += 1
                free, n_idle = k, len(idle)
                if found is not None:
                    break
                buf = None
                continue
            r0, r1, r2 = x - b0, y - b1, z - b2
            if math.sqrt(r0 * r0 + r1 * r1 + r2 * r2) >= on:
                held_t += dtp
            k += 1
        if opened is not None:
            self._keep(rows, opened, k)
        elif found is None:
            idle += rows.wrench_rows(free, k)
        self._t, self._held, self._n_base = tp, held_t, n_base
        self._dt, self._a_smooth, self._a_base = dtp, a_s, a_b
        self._fs[:], self._base[:] = (f0, f1, f2), (b0, b1, b2)
        return k, found

    def _keep(self, rows: SampleBlock, a: int, b: int) -> None:
        """Rows ``a`` to ``b - 1`` are in the open contact."""
        assert self._buf is not None
        self._buf.add_rows(rows, a, b)
        self._mags.extend(rows.mags[a:b])
        self._lines.extend(rows.lines[a:b])

    def _trigger_rows(self, rows: SampleBlock, a: int, b: int, changes: list) -> tuple[int, Contact | None]:
        """:meth:`feed_rows` for contacts from the trigger: a contact lasts while it is held."""
        pressed = rows.pressed
        if pressed is None:                 # no trigger column: never pressed
            return b, None
        k = a
        while k < b:
            state = self._buf is not None
            flips = np.flatnonzero(pressed[k:b] != state)
            if not len(flips):
                if state:
                    self._keep(rows, k, b)
                return b, None
            at = k + int(flips[0])
            changes.append(at)
            if not state:                   # pressed at ``at``: a contact opens with it
                self._buf, self._mags, self._lines, self._held = _Samples(), [], [], 0.0
                self._keep(rows, at, at + 1)
                k = at + 1
                continue
            self._keep(rows, k, at)         # released at ``at``: the contact ends there
            self.closed_at = time.perf_counter()
            found = self._close(rows.t[at])
            k = at + 1
            if found is not None:
                return k, found
        return b, None


#: intervals whose factors a detector remembers (a stream with jittered time stamps may have many)
_KNOWN_DT = 4096


class _Samples:
    """The samples of the open contact: :class:`Sample` objects pushed one by one, or rows of :class:`SampleBlock`
    kept by reference (the one sample a point needs is made when it is asked for)."""

    def __init__(self, first: Sample | None = None):
        self._parts: list = []              # (rows or None, first row, end row, Sample or None)
        self._n = 0
        if first is not None:
            self.add(first)

    def add(self, s: Sample) -> None:
        self._parts.append((None, 0, 1, s))
        self._n += 1

    def add_rows(self, rows: SampleBlock, a: int, b: int) -> None:
        if b > a:
            self._parts.append((rows, a, b, None))
            self._n += b - a

    def __len__(self) -> int:
        return self._n

    def __getitem__(self, k: int) -> Sample:
        for rows, a, b, s in self._parts:
            if k < b - a:
                return s if rows is None else rows.sample(a + k)
            k -= b - a
        raise IndexError(k)

    @property
    def first_t(self) -> float:
        rows, a, _, s = self._parts[0]
        return s.t if rows is None else rows.t[a]

    @property
    def last_t(self) -> float:
        rows, _, b, s = self._parts[-1]
        return s.t if rows is None else rows.t[b - 1]
