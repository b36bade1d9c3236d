"""A live measurement session: samples in, contacts, corrected points with their uncertainty, events and
feature fits out (docs/live.md).

    from arm_model.live import Session
    with Session("aacmm7", "out/session-1") as session:        # the folder: the record (optional)
        for t, q, wrench in my_sdk_stream():                    # [s], (J,) [rad], (3,) or (6,) [N, N m]
            for item in session.push(t, q, wrench):
                print(item)                                     # Contact, LivePoint, Event, FeatureFit

Each contact gives one point at its force peak (:mod:`arm_model.live.contacts`), computed by the code of
``aacmm tip`` (:func:`arm_model.commands.tip_centres`, every effect of a model file applied) and its
uncertainty by :func:`arm_model.uncertainty.propagate`, so ``aacmm tip points.csv --arm ARM
--uncertainty`` on the session's ``points.csv`` writes the session's ``tips.csv`` byte for byte, a model with a
joint's hysteresis included: each point's last moves, read from the samples (:mod:`arm_model.live.motion`), are
recorded with it (``q1_move_sign`` ...).
"""
from __future__ import annotations

import math
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..checks import limit_bounds
from ..csv_io import format_row
from ..errors import InputError
from ..io import Feature, PointSet, id_problem, move_columns
from ..uncertainty import InputUncertainty
from .contacts import Contact, ContactDetector, ContactOptions
from .features import FeatureFit, FeatureTracker
from .motion import BAND_SIGMAS, BAND_STEPS, NOISE_SAMPLES, LastMove
from .plan import SessionPlan
from .record import FILES, SessionRecord
from .samples import Sample, SampleBlock, SampleLayout, checked_value, sample_header

__all__ = ["Session", "LivePoint", "Event", "EVENT_KINDS", "PERIOD_SAMPLES", "GAP_FACTOR", "LIMIT_MARGIN_RAD",
           "JUMP_PERIODS", "JUMP_GAPS", "JUMP_BACK_PERIODS", "JUMP_CONFIRM", "BLOCK_LEAST",
           "TIP_COLUMNS", "CONTACT_COLUMNS", "EVENT_COLUMNS", "FEATURE_COLUMNS", "points_columns"]

#: the kinds of :class:`Event`
EVENT_KINDS = ("over_force", "joint_limit", "dropped", "late", "time_jump", "clock_jump", "bad_line", "bump", "plan",
               "end", "rate")
#: intervals from which the nominal sample period is estimated (their median), unless given
PERIOD_SAMPLES = 16
#: a gap longer than this many nominal periods holds dropped samples
GAP_FACTOR = 1.5
#: a time stamp this many nominal periods after the previous one (or :data:`JUMP_GAPS` times the widest interval
#: taken so far, if more), or :data:`JUMP_BACK_PERIODS` before it, is off the stream's clock: one bad time stamp
#: (skipped) if the next sample continues the old clock, a clock jump if :data:`JUMP_CONFIRM` samples in a row
#: continue the new one. Less far back, a sample is late (out of order: skipped) if the next sample continues the
#: old clock, and a clock jump back as above if the next ones keep its own
JUMP_PERIODS, JUMP_GAPS, JUMP_BACK_PERIODS = 1000, 10, 100
#: samples in a row (the first off the old clock included) that make a jump of the time stamps a new clock
JUMP_CONFIRM = 4
#: the nominal sample rates a session takes [Hz]: a sample every 1000 s to a million a second (beyond, a gap of a
#: millisecond counted 1e305 dropped samples, and a rate of 5e-324 Hz made the period infinite)
RATE_HZ_RANGE = (1e-3, 1e6)
#: the fewest samples in a row that :meth:`Session.push_block` takes by array operations (fewer: one by one, which
#: costs less than the arrays' set-up)
BLOCK_LEAST = 16
#: a joint back inside its limits by this much re-arms its joint-limit event [rad] (0.05 deg)
LIMIT_MARGIN_RAD = math.radians(0.05)


@dataclass(frozen=True)
class Event:
    """Something the operator must know, as it happens: ``time`` [s] (the sample's), ``kind`` (one of
    :data:`EVENT_KINDS`), ``message`` and ``count`` (dropped samples: how many)."""
    time: float
    kind: str
    message: str
    count: int = 1

    def __str__(self) -> str:       # before the first sample there is no time: a dash, never "nan"
        when = f"{self.time:10.3f}" if math.isfinite(self.time) else f"{'-':>10}"
        return f"[{when} s] {self.kind}: {self.message}"


@dataclass(frozen=True)
class LivePoint:
    """The point of a contact. Lengths in metres, base frame.

    Attributes:
        index: 1-based (the contact's); contact: the :class:`Contact`; measurement, feature: its ids.
        rigid, corrected: (3,) ball centres (``aacmm tip``'s); deflection: corrected - rigid.
        u: (3,) standard uncertainties of ``corrected``; cov: (3, 3) its covariance.
        over_force: |F| at the peak beyond the probe's range; beyond_limits: joints beyond their limits.
        row: the row of ``tips.csv`` (``aacmm tip``'s columns); latency: seconds from the start of the
        ``push`` of the sample that ended the contact to the point.
    """
    index: int
    contact: Contact
    measurement: str
    feature: str
    rigid: np.ndarray
    corrected: np.ndarray
    u: np.ndarray
    cov: np.ndarray
    over_force: bool
    beyond_limits: tuple
    row: dict
    latency: float

    @property
    def deflection(self) -> np.ndarray:
        return self.corrected - self.rigid

    def __str__(self) -> str:
        c, u = self.corrected * 1e3, self.u * 1e6
        return (f"point {self.index}{' ' + self.feature if self.feature else ''}: ({c[0]:.4f}, {c[1]:.4f}, "
                f"{c[2]:.4f}) mm, u ({u[0]:.1f}, {u[1]:.1f}, {u[2]:.1f}) um, |F| {self.contact.peak_force:.2f} N, "
                f"deflection {np.linalg.norm(self.deflection) * 1e6:.1f} um"
                + (" OVER-FORCE" if self.over_force else ""))


class Session:
    """A live session on one arm (see the module doc and docs/live.md).

    Args:
        arm: an :class:`~arm_model.model_file.Arm`, a description, or what ``--arm`` takes (a shipped
            arm's name, a description or model file).
        folder: the session folder (a new or empty folder; None: nothing recorded).
        plan: a :class:`~arm_model.live.plan.SessionPlan` (features in order), or None (free points;
            :meth:`begin_feature` adds features ad hoc).
        contact: :class:`~arm_model.live.contacts.ContactOptions`.
        inputs: the input uncertainties (None: the arm's own, :meth:`~arm_model.model_file.Arm.input_uncertainty`,
            as ``aacmm tip`` takes them: its model file's probing scatter and model discrepancy included).
        measurement: the points' measurement id (default: the plan's, else the folder's name, else "live").
        rate: the nominal sample rate [Hz] (None: estimated from the first intervals), in :data:`RATE_HZ_RANGE`.
        layout: the stream's :class:`~arm_model.live.samples.SampleLayout` (its header is recorded and
            raw lines are recorded as received); None: samples pushed from Python, recorded in SI.
        inputs_files: files the session reads (never written over); status: more ``session.json`` keys (a
            ``reproduce`` command, on points.csv, is null there until the first point writes points.csv).
    """

    def __init__(self, arm: Any, folder: str | Path | None = None, *, plan: SessionPlan | None = None,
                 contact: ContactOptions = ContactOptions(), inputs: InputUncertainty | None = None,
                 measurement: str | None = None, rate: float | None = None, layout: SampleLayout | None = None,
                 inputs_files: Iterable = (), status: dict | None = None):
        from ..model_file import Arm, load_model, parameters_of
        if not isinstance(arm, Arm):
            arm = Arm(arm) if hasattr(arm, "joints") else load_model(arm, None)
        self.arm, self.desc = arm, arm.desc
        self.model, self.p = arm.model, arm.p
        self.parameters = parameters_of(arm)
        self.max_force = float(self.desc.probe.max_force)
        self.contact_options = contact
        self._detector = ContactDetector(contact)
        self._force_kind = None if layout is None else layout.force_kind
        if layout is not None:      # a column an effect needs, missing from the header: refused before any file exists
            arm.check_columns({"time_s", *(("temperature_C",) if layout.has_temperature else ())}, "stream",
                              layout.path, layout.header_line)
        self.inputs = inputs
        # the arm's own inputs (its model discrepancy read once, here), with and without a force sensor
        self._default_inputs = None if inputs is not None else {f: arm.input_uncertainty(f) for f in (True, False)}
        self._propagators: dict = {}        # with and without a measured wrench: uncertainty.Propagator, made once
        # each joint's last move before a contact, from the samples: a JointHysteresis effect needs it, and the record
        # keeps it (points.csv's q1_move_sign ...: what the points file alone cannot give a later fit); the band from
        # the encoder's step (its uncertainty is step / sqrt(12)) and the readings' noise in contact
        self._moves = (LastMove(self.input_uncertainty(True).encoder * math.sqrt(12.0))
                       if "motion" in self.model.needs() or folder is not None else None)
        if plan is not None and not isinstance(plan, SessionPlan):
            raise TypeError(f"plan must be a SessionPlan (arm_model.live.read_plan(path)) or None, got "
                            f"{type(plan).__name__}")
        self.plan = plan or SessionPlan()
        self.measurement = (measurement if measurement is not None else
                            self.plan.measurement or (Path(folder).name if folder else "live"))
        if id_problem(self.measurement):       # it is written on every point: the points file must read it back
            source = ("--measurement" if measurement is not None else
                      "the plan's 'measurement'" if self.plan.measurement else "the session folder's name")
            raise InputError(f"the measurement id ({source}) {id_problem(self.measurement)}", None, None,
                             "key 'measurement'")
        npar = 0 if self.parameters is None else len(self.parameters.names)
        self.tracker = FeatureTracker(self.plan, self.desc.probe.ball_diameter, npar)
        if rate is not None and not RATE_HZ_RANGE[0] <= rate <= RATE_HZ_RANGE[1]:
            raise ValueError(f"rate: the nominal sample rate must be in [{RATE_HZ_RANGE[0]:g}, "
                             f"{RATE_HZ_RANGE[1]:g}] Hz, got {rate!r}")
        self._period = None if rate is None else 1.0 / float(rate)
        # the first intervals of the time stamps, to check a stated rate against (None: no rate, or checked)
        self._rate_seen: list | None = None if rate is None else []
        self._gap_limit = -math.inf if rate is None else GAP_FACTOR * self._period  # type: ignore[operator]  # learning: every interval
        self._first_gaps: list = []
        self._widest = 0.0                  # the widest interval taken beyond the gap limit [s]
        self._jump_limit = self._jump_back = math.inf               # [s] ahead, back: set with the period
        if self._period is not None:
            self._clock_bounds(self._period)
        self._held: list = []               # (sample, raw, line) off the old clock, until the next ones tell
        self._bounds = [(i, lo, hi) for i, (lo, hi) in enumerate(limit_bounds(self.desc))
                        if math.isfinite(lo) or math.isfinite(hi)]
        self._beyond: set = set()
        self._over = False
        self._last_t: float | None = None
        self._t_push = 0.0
        self.latest: Sample | None = None
        self.latest_magnitude = 0.0
        self.counts = dict.fromkeys(("samples", "contacts", "points", "bumps", "over_force", "joint_limit",
                                     "dropped", "late", "time_jumps", "clock_jumps", "bad_lines"), 0)
        self.points: list[LivePoint] = []
        self.events: list[Event] = []
        self.layout = layout
        # points.csv and tips.csv come with the first point (a header alone is no points file: `tip` refuses it), and
        # with them status's ``reproduce`` (a command on points.csv): null in session.json until then
        status = dict(status or {})
        self._reproduce = status.pop("reproduce", None)
        if self._reproduce is not None:
            status["reproduce"] = None
        self._point_files: dict[str, str] = {}
        self.record = None if folder is None else SessionRecord(folder, inputs_files, self._status(status))
        if self.record is not None and self.plan.entries:
            self.record.write_file("artefacts", self.plan.artefacts_text())
        if layout is not None:
            self._open_record(layout)

    # -- samples in -----------------------------------------------------------------------------
    def push(self, t: float, q: Sequence[float], wrench: Sequence[float] | None = None, trigger: bool | None = None,
             temperature: float | None = None) -> tuple:
        """One sample: time ``t`` [s], joint angles ``q`` (J,) [rad], the wrench of the part on the ball
        (3,) [N] or (6,) [N, N m] in the probe frame (None: no force sensor), the trigger (the button
        held) and the temperature [°C] when the stream has them. Returns what it brought, in order:
        :class:`Event`, :class:`~arm_model.live.contacts.Contact`, :class:`LivePoint`,
        :class:`~arm_model.live.features.FeatureFit` (mostly nothing)."""
        if len(q) != self.desc.n_joints:
            raise ValueError(f"q must have {self.desc.n_joints} angles, got {len(q)}")
        q = tuple(checked_value(x, kind, f"q[{k}]") for k, (x, kind) in enumerate(zip(q, self.desc.joint_quantities,
                                                                                      strict=True)))
        w = None
        if wrench is not None:
            if len(wrench) not in (3, 6):
                raise ValueError(f"wrench must be 3 or 6 finite numbers, got {wrench!r}")
            w = tuple(checked_value(x, "force" if k < 3 else "torque", f"wrench[{k}]") for k, x in enumerate(wrench))
            w = w + (0.0, 0.0, 0.0) if len(w) == 3 else w
        if trigger is not None and not isinstance(trigger, (bool, np.bool_)):
            raise TypeError(f"trigger must be True, False or None, got {trigger!r}")
        s = Sample(checked_value(t, "time", "t"), q, w, None if trigger is None else bool(trigger),
                   None if temperature is None else checked_value(temperature, "temperature", "temperature"))
        if self.layout is None:
            self._layout_from(s, wrench)
        return self.push_sample(s, self._sample_text(s))

    def push_sample(self, s: Sample, raw: str | None = None, line: int | None = None) -> tuple:
        """One :class:`~arm_model.live.samples.Sample` (SI); ``raw``: its text as received (recorded
        verbatim), ``line``: its line in the stream."""
        detector = self._detector
        was_in = detector.in_contact
        if was_in:                          # this sample may end the contact: the latency starts here
            self._t_push = time.perf_counter()
        t = s.t
        last = self._last_t
        out = ()
        if last is not None:
            if self._held or not 0.0 < t - last <= self._jump_limit:     # behind, or far ahead: held
                return self._off_clock(s, raw, line)
            if t - last > self._gap_limit:
                out = self._gap(last, t)
            if self._rate_seen is not None:
                out = out + self._check_rate(t - last, t)
        self._last_t = t
        self.counts["samples"] += 1
        self.latest = s
        rec = self.record
        if rec is not None:
            if raw is not None:
                self._samples_buf.append(raw + "\n")
            if time.monotonic() >= rec.next_flush:
                rec.flush(self._progress())
        w = s.wrench
        m = 0.0 if w is None else math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
        self.latest_magnitude = m
        if m > self.max_force or self._over:
            out = out + self._watch_force(s, m)
        if self._bounds:
            q = s.q
            for i, lo, hi in self._bounds:
                x = q[i]
                if x < lo or x > hi:
                    out = out + self._watch_joints(s)
                    break
            else:
                if self._beyond:
                    out = out + self._watch_joints(s)
        moves = self._moves
        if moves is not None:
            if was_in:
                moves.held(s.q)
            else:
                moves.free(s.q)
        contact = detector.feed(s, m, line)
        if contact is not None:
            out = out + self._on_contact(contact)
        elif was_in and not detector.in_contact:
            self.counts["bumps"] = detector.bumps
        return out

    def push_block(self, block: SampleBlock, start: int = 0, end: int | None = None) -> tuple:
        """Samples that came together (:meth:`~arm_model.live.samples.SampleLayout.parse_block` of lines read at
        once; rows ``start`` to ``end - 1`` of ``block``, default all): what :meth:`push_sample` on each in turn
        brings, and the same state and files after it. The samples that a clock, a gap, a force beyond the probe's
        range or a joint limit concerns, the first ones (the period or the check of a stated rate, the sensor's zero
        and noise), those held off the clock and runs of fewer than :data:`BLOCK_LEAST` go through
        :meth:`push_sample`; the others are taken by
        array operations and one loop for the moving averages, which must go sample by sample (the same operations
        in the same order: the same numbers). A point's latency counts from the moment the session takes up the
        sample that ends its contact, as for a sample pushed alone (the joints' moves of the block's samples before
        it, followed by array operations once the contact's end is known, count in it: tens of µs)."""
        if self.layout is None:
            raise ValueError("push_block needs the session's sample layout (a stream's header)")
        out: list = []
        k, end = start, block.n if end is None else end
        masks = block.masks if isinstance(block.masks, _BlockMasks) and block.masks.session is self else None
        while k < end:
            stop = k
            if end - k >= BLOCK_LEAST:
                if masks is None:
                    masks = block.masks = _BlockMasks(self, block)
                stop = min(masks.quiet_until(k), end)
            if stop - k >= BLOCK_LEAST:
                out += self._push_rows(block, k, stop)
                k = stop
            else:
                for i in range(k, max(stop, k + 1)):
                    out += self.push_sample(block.sample(i), block.texts[i], block.lines[i])
                k = max(stop, k + 1)
        rec = self.record
        if rec is not None and time.monotonic() >= rec.next_flush:
            rec.flush(self._progress())
        return tuple(out)

    def _push_rows(self, block: SampleBlock, a: int, b: int) -> list:
        """Rows ``a`` to ``b - 1`` of ``block``: on the stream's clock, no gap, no force beyond the range, no joint
        leaving or coming back inside its limits (:class:`_BlockMasks`), the detector past its first samples."""
        detector, moves, rec = self._detector, self._moves, self.record
        out: list = []
        k = a
        while k < b:
            was_in = detector.in_contact
            changes: list = []
            nxt, contact = detector.feed_rows(block, k, b, changes)
            self.counts["samples"] += nxt - k
            self._last_t = block.t[nxt - 1]
            if moves is not None:
                held = np.full(nxt - k, was_in)
                for c in changes:                           # the rows after a change are in (out of) contact
                    held[c - k + 1:] = not held[c - k]
                last = nxt - 1 if contact is not None else nxt
                moves.follow(block.q[k:last], held[:last - k])   # (with a contact: counted in its point's latency)
            if contact is not None:     # from the row that ended it: its peak, its moves, its record, the point
                self._t_push = detector.closed_at
                if moves is not None:
                    moves.follow(block.q[nxt - 1:nxt], held[-1:])
            if rec is not None:
                self._samples_buf.append("\n".join(block.texts[k:nxt]) + "\n")
            if changes:
                self.counts["bumps"] = detector.bumps
            if contact is not None:
                self.latest, self.latest_magnitude = block.sample(nxt - 1), block.mags[nxt - 1]
                out += self._on_contact(contact)
            k = nxt
        self.latest, self.latest_magnitude = block.sample(b - 1), block.mags[b - 1]
        return out

    def _late(self, s: Sample, raw: str | None, last: float) -> tuple:
        self.counts["late"] += 1
        if self.record is not None and raw is not None:
            self._samples_buf.append(raw + "\n")
        return (self._event(s.t, "late", f"a sample at t = {s.t!r} s after one at {last!r} s: out of order or "
                                         "repeated, skipped"),)

    def _off_clock(self, s: Sample, raw: str | None, line: int | None) -> tuple:
        """A time stamp not after the last sample taken, or far after it (beyond :data:`JUMP_PERIODS` nominal
        periods, or :data:`JUMP_GAPS` widest intervals), or one after such: held until the next samples tell
        whether it was one late sample or bad time stamp (they continue the old clock: it is skipped) or the clock
        jumped, ahead or back by any amount (:data:`JUMP_CONFIRM` in a row continue the new one: the session
        follows it)."""
        held, last, lim = self._held, self._last_t, self._jump_limit
        assert last is not None, "off the clock only once a sample was taken"
        if not held:
            held.append((s, raw, line))
            return ()
        if 0.0 < s.t - last <= lim:                 # back on the old clock: what was held was late or bad
            return self._drop_held("the next sample continues the old clock") + self.push_sample(s, raw, line)
        if 0.0 < s.t - held[-1][0].t <= lim:        # on the new clock
            held.append((s, raw, line))
            return self._clock_jump() if len(held) >= JUMP_CONFIRM else ()
        out = self._drop_held("the next sample is on neither clock")
        self._held.append((s, raw, line))
        return out

    def _drop_held(self, why: str) -> tuple:
        """The samples held off the clock are late (behind the last sample taken by at most
        :data:`JUMP_BACK_PERIODS` periods: out of order, or repeated) or bad time stamps: counted, recorded in
        ``samples.csv``, skipped."""
        held, self._held = self._held, []
        out = ()
        last = self._last_t
        assert last is not None, "held only once a sample was taken"
        for s, raw, line in held:
            if -self._jump_back <= s.t - last <= 0.0:
                out = out + self._late(s, raw, last)
                continue
            self.counts["time_jumps"] += 1
            if self.record is not None and raw is not None:
                self._samples_buf.append(raw + "\n")
            where = "a sample" if line is None else f"line {line}: a sample"
            out = out + (self._event(s.t, "time_jump", f"{where} at t = {s.t!r} s, {s.t - self._last_t:+.6g} s from "
                                                       f"the stream's clock (at {self._last_t!r} s, bounds "
                                                       f"-{self._jump_back:.4g} / +{self._jump_limit:.4g} s) and "
                                                       f"{why}: a bad time stamp, "
                                                       "skipped"),)
        return out

    def _clock_jump(self) -> tuple:
        """:data:`JUMP_CONFIRM` samples in a row on a new clock: said once, the open contact ends at its last
        sample before the jump (its point, if it held long enough), and the session follows the new clock."""
        held, self._held = self._held, []
        last, (first, _, line) = self._last_t, held[0]
        assert last is not None, "a jump needs a clock to jump from"
        self.counts["clock_jumps"] += 1
        where = "" if line is None else f"line {line}: "
        out: tuple = (self._event(first.t, "clock_jump", f"{where}the time stamps jumped by {first.t - last:+.6g} s "
                                                         f"(from {last!r} to {first.t!r} s) and {len(held)} samples "
                                                         "in a row continue from there: the stream's clock was reset "
                                                         "(or no sample came for that long); the session follows "
                                                         "the new clock"),)
        detector = self._detector
        if detector.in_contact:
            contact = detector.finish()
            self.counts["bumps"] = detector.bumps
            said = (f"its point is taken at its peak before the jump (contact {contact.index})" if contact else
                    "it had not held the force long enough for a point (a bump)")
            out = out + (self._event(last, "clock_jump", f"a contact was open at the clock jump: it ends at its last "
                                                         f"sample before it; {said}"),)
            if contact is not None:
                self._t_push = time.perf_counter()
                out = out + self._on_contact(contact)
        detector.shift(first.t - last - (self._period or 0.0))
        self._last_t = None
        for s, raw, line in held:
            out = out + self.push_sample(s, raw, line)
        return out

    def bad_line(self, error: Exception, raw: str | None = None) -> Event:
        """Count a line of the stream that is not a sample (its :class:`~arm_model.InputError`): it is
        recorded in ``events.csv`` and skipped (never in ``samples.csv``)."""
        self.counts["bad_lines"] += 1
        return self._event(self._last_t if self._last_t is not None else math.nan, "bad_line", str(error))

    def begin_feature(self, id: str, kind: str, diameter: float | None = None, points: int | None = None,
                      u_diameter: float | None = None, form_error: float | None = None) -> None:
        """Start an ad hoc feature now: the next ``points`` points (None: until the next one) belong to
        it. ``diameter``, ``u_diameter``, ``form_error`` [m]: its certificate, if any."""
        from ..io import FEATURE_KINDS
        if kind not in FEATURE_KINDS:
            raise ValueError(f"kind must be one of {', '.join(FEATURE_KINDS)}, got {kind!r}")
        if kind in ("ring", "cylinder", "sphere") and diameter is None:
            raise ValueError(f"a {kind} needs its diameter")
        values = {k: v for k, v in (("diameter", diameter), ("u_diameter", u_diameter),
                                    ("form_error", form_error)) if v is not None}
        self.tracker.begin(Feature(id, kind, diameter, u_diameter, form_error, values), points)

    def tick(self) -> None:
        """Flush the record when it is due (call it when no sample came for a while)."""
        if self.record is not None and not self.record.closed and time.monotonic() >= self.record.next_flush:
            self.record.flush(self._progress())

    # -- what it found -------------------------------------------------------------------------
    @property
    def fits(self) -> dict[str, FeatureFit]:
        """The latest fit of every feature (and certified distance) by id."""
        return self.tracker.fits

    @property
    def in_contact(self) -> bool:
        return self._detector.in_contact

    def thresholds(self) -> dict:
        """The contact thresholds in force [N] (``on``, ``off``: the options', raised to the noise when it
        demands) and ``noise``, the smoothed force's noise [N] (None before it is estimated)."""
        d = self._detector
        return {"on": d.on, "off": d.off, "noise": d.noise}

    def noise(self) -> np.ndarray | None:
        """(3,) the force sensor's noise per channel [N] from the samples out of contact
        (:func:`arm_model.peaks.signal_noise`, as the contact detector last estimated it), or None before."""
        return self._detector.raw_noise

    def close(self, status: str = "complete", message: str = "the stream ended") -> tuple:
        """End the session: the open contact, if any, gives its point; the record is flushed and closed
        with ``status`` (``complete``, ``interrupted``, ``terminated``, ``stopped``) and ``message``."""
        out = self._drop_held("the stream ended before it was followed by a new clock") if self._held else ()
        if self.record is None or not self.record.closed:
            self._t_push = time.perf_counter()
            contact = self._detector.finish()
            if contact is not None:
                out = (self._event(contact.end, "end", f"the stream ended during contact {contact.index}: its point "
                                                       "is taken at its peak so far"),) + self._on_contact(contact)
        self.counts["bumps"] = self._detector.bumps
        if self.record is not None and not self.record.closed:
            self.record.close(status, message, self._progress())
        return out

    def __enter__(self) -> Session:
        return self

    def __exit__(self, exc_type: type | None, exc: BaseException | None, tb: object) -> None:
        if exc_type is None:
            self.close()
        elif issubclass(exc_type, KeyboardInterrupt):
            self.close("interrupted", "interrupted (Ctrl-C)")
        else:
            self.close("stopped", f"stopped by an error: {exc_type.__name__}: {exc}")

    # -- inside ---------------------------------------------------------------------------------
    def _event(self, t: float, kind: str, message: str, count: int = 1) -> Event:
        ev = Event(t, kind, message, count)
        self.events.append(ev)
        if self.record is not None:
            self.record.append("events", _csv_line([_num(t), kind, count, message]))
        return ev

    def _check_rate(self, interval: float, t: float) -> tuple:
        """The stated rate against the time stamps: once :data:`PERIOD_SAMPLES` intervals on the clock are in, a
        ``rate`` event when their median is more than :data:`GAP_FACTOR` times the stated period or less than the
        period over it (every sample counted with dropped ones, or a dropped sample unseen), giving both figures.
        ``interval`` [s]: the next one, up to the sample at ``t`` (until then the samples go one by one:
        :meth:`_BlockMasks.quiet_until`)."""
        seen = self._rate_seen
        assert seen is not None and self._period is not None, "a rate to check"
        seen.append(float(interval))
        if len(seen) < PERIOD_SAMPLES:
            return ()
        self._rate_seen = None
        median, period = float(np.median(seen[:PERIOD_SAMPLES])), self._period
        if period / GAP_FACTOR <= median <= GAP_FACTOR * period:
            return ()
        return (self._event(t, "rate", f"the stated rate (--rate-Hz) {1.0 / period:.6g} Hz, a sample every "
                                       f"{period * 1e3:.4g} ms, contradicts the time stamps: the median of their first "
                                       f"{PERIOD_SAMPLES} intervals is {median * 1e3:.4g} ms ({1.0 / median:.6g} Hz); "
                                       "dropped samples are counted against the stated rate (give the stream's rate, "
                                       "or leave --rate-Hz out to learn it from the time stamps)"),)

    def _clock_bounds(self, period: float) -> None:
        """How far a time stamp may be from the last one taken, ahead and back, and stay on the stream's clock [s]."""
        self._jump_limit = max(JUMP_PERIODS * period, JUMP_GAPS * self._widest)
        self._jump_back = JUMP_BACK_PERIODS * period

    def _gap(self, last: float, t: float) -> tuple:
        """Dropped samples between ``last`` and ``t``: the gap against the nominal period (estimated from
        the first :data:`PERIOD_SAMPLES` intervals, which are then checked too)."""
        if self._period is None:
            self._first_gaps.append((last, t))
            if len(self._first_gaps) < PERIOD_SAMPLES:
                if len(self._first_gaps) >= 3:      # provisional bounds for jumps while the period is learnt
                    self._clock_bounds(float(np.median([b - a for a, b in self._first_gaps])))
                return ()
            self._period = float(np.median([b - a for a, b in self._first_gaps]))
            self._gap_limit = GAP_FACTOR * self._period
            self._clock_bounds(self._period)
            gaps, self._first_gaps = self._first_gaps, []
            return tuple(e for a, b in gaps for e in self._gap(a, b))
        if t - last > self._widest:
            self._widest = t - last
            self._clock_bounds(self._period)
        n = int(round((t - last) / self._period)) - 1
        if n < 1:
            return ()
        self.counts["dropped"] += n
        return (self._event(t, "dropped", f"{n} sample(s) missing between t = {last!r} and {t!r} s (nominal "
                                          f"period {self._period * 1e3:.4g} ms)", n),)

    def _watch_force(self, s: Sample, m: float) -> tuple:
        """Over-force: one event a contact (re-armed once the contact, or bump, has ended)."""
        if m > self.max_force:
            if not self._over:
                self._over = True
                self.counts["over_force"] += 1
                ev = self._event(s.t, "over_force", f"|F| = {m:.3f} N beyond the probe's calibrated range "
                                                    f"({self.max_force:g} N)")
                if self.record is not None:
                    self.record.flush()
                return (ev,)
        elif not self._detector.in_contact:
            self._over = False
        return ()

    def _watch_joints(self, s: Sample) -> tuple:
        """Joint limits: one event each time a joint leaves its limits (re-armed once it is back inside by
        :data:`LIMIT_MARGIN_RAD`)."""
        out = ()
        for i, lo, hi in self._bounds:
            x = s.q[i]
            if x < lo or x > hi:
                if i not in self._beyond:
                    self._beyond.add(i)
                    self.counts["joint_limit"] += 1
                    j = self.desc.joints[i]
                    out = out + (self._event(s.t, "joint_limit", f"{j.name} at {math.degrees(x):.4f} deg, beyond "
                                                                 f"its limits {math.degrees(lo):.4f} to "
                                                                 f"{math.degrees(hi):.4f} deg"),)
            elif i in self._beyond and lo + LIMIT_MARGIN_RAD <= x <= hi - LIMIT_MARGIN_RAD:
                self._beyond.discard(i)
        return out

    def _point_set(self, c: Contact, feature: str) -> PointSet:
        s = c.peak
        w = s.wrench
        kind = self._force_kind if w is not None else None
        torque = None
        if w is not None and self.layout is not None and self.layout.has_torque:
            torque = np.array([w[3:]])
        return PointSet(path=FILES["points"], measurement=np.array([self.measurement]), feature=np.array([feature]),
                        q=np.array([s.q]), force=None if w is None else np.array([w[:3]]), torque=torque,
                        force_kind=kind or ("xyz" if w is not None else None),
                        temperature=None if s.temperature is None else np.array([s.temperature]),
                        time=np.array([s.t]), lines=np.array([self.counts["points"] + 2]),
                        motion=None if self._moves is None else self._moves.motion())

    def input_uncertainty(self, force: bool) -> InputUncertainty:
        """The input uncertainties of a point with (``force``) or without a measured wrench: the ``inputs``
        given, else the arm's own (:meth:`~arm_model.model_file.Arm.input_uncertainty`, its model file's
        probing scatter and model discrepancy included, read once when the session starts)."""
        if self._default_inputs is None:
            assert self.inputs is not None     # set together in __init__: one of the two is None
            return self.inputs
        return self._default_inputs[bool(force)]

    def _on_contact(self, c: Contact) -> tuple:
        """The point of contact ``c``: ``aacmm tip``'s centres and uncertainty, recorded, then the fits."""
        from ..commands import tip_centres, tip_table
        from ..uncertainty import Propagator
        from ..uncertainty_cli import u_columns
        feature = self.tracker.current
        ps = self._point_set(c, feature)  # with the sign of each joint's last move before the contact
        centres = tip_centres(self.arm, ps)
        row = tip_table(self.arm, ps, centres)
        force = ps.wrench is not None
        if force not in self._propagators:
            self._propagators[force] = Propagator(self.model, self.parameters, self.input_uncertainty(force))
        prop = self._propagators[force](self.p, ps.q, ps.wrench, self.arm.aux(ps), threads=1, systematic=True)
        row.update(u_columns(prop))
        beyond = tuple(self.desc.joints[i].name for i, lo, hi in self._bounds if not lo <= c.peak.q[i] <= hi)
        point = LivePoint(c.index, c, self.measurement, feature, centres[0][0], centres[1][0], prop.u[0],
                          prop.cov[0], bool(row["over_force"][0]), beyond, row, time.perf_counter() - self._t_push)
        if self._moves is not None:       # then the band from the readings held in this contact (for the next moves;
            self._moves.settle()          # after the point: a median of 5000 x J differences, 0.3-0.7 ms)
        self.points.append(point)
        self.counts["contacts"] += 1
        self.counts["points"] += 1
        self._record_point(point, ps)
        assert prop.systematic is not None, "propagated with systematic=True"
        fits = tuple(self.tracker.add(feature, point.corrected, prop.cov[0], prop.systematic[0]))
        if self.record is not None:
            for fit in fits:
                r = fit.row(point.index)
                self.record.append("features", _csv_line(r.values()))
            self.record.flush()
        return (c, point) + fits

    def _record_point(self, point: LivePoint, ps: PointSet) -> None:
        rec = self.record
        if rec is None:
            return
        if self.counts["points"] == 1:      # the first point: its files, and the command that reproduces them
            for role, header in self._point_files.items():
                rec.open(role, header)
            if self._reproduce is not None:
                rec.status["reproduce"] = self._reproduce
        rec.append("points", format_row({k: v[0] for k, v in _points_values(ps).items()}, "%.17g"))
        rec.append("tips", format_row({k: v[0] for k, v in point.row.items()}, "%.6f"))
        c = point.contact
        rec.append("contacts", _csv_line([c.index, point.measurement, point.feature, _num(c.start), _num(c.peak.t),
                                          _num(c.end), c.samples, f"{c.peak_force:.6f}", int(point.over_force),
                                          " ".join(point.beyond_limits), "" if c.line is None else c.line,
                                          f"{point.latency * 1e3:.3f}"]))

    def _progress(self) -> dict:
        noise = self.noise()
        return {"counts": dict(self.counts), "last_sample_time_s": self._last_t,
                "force_noise_N": None if noise is None else [round(float(v), 6) for v in noise],
                "thresholds_N": self.thresholds(), "last_move": self._last_move_status()}

    def _last_move_status(self) -> dict | None:
        """How the joints' last moves are read (docs/live.md, "The last move of each joint"): the rule's constants
        and, per joint, its encoder step and the dead band the next point's moves are read with (SI: rad, m for a
        prismatic joint); None when they are not followed."""
        moves = self._moves
        if moves is None:
            return None
        joints = []
        for name, kind, step, band in zip(self.desc.joint_names, self.desc.joint_quantities, moves.encoder_steps,
                                          moves.band, strict=True):
            unit = "m" if kind == "length" else "rad"
            joints.append({"joint": name, f"encoder_step_{unit}": step, f"dead_band_{unit}": band})
        return {"band_steps": BAND_STEPS, "band_sigmas": BAND_SIGMAS, "noise_samples": NOISE_SAMPLES,
                "joints": joints}

    def _status(self, extra: dict | None) -> dict:
        from ..shipped import version
        c = self.contact_options
        return {"aacmm_version": version(), "arm": self.desc.name, "measurement": self.measurement,
                "contact": {"source": c.source, "on_N": c.on, "off_N": c.off, "dwell_s": c.dwell,
                            "smooth_s": c.smooth, "baseline_s": c.baseline},
                "max_force_N": self.max_force, "files": dict(FILES), **(extra or {})}

    def _open_record(self, layout: SampleLayout) -> None:
        """Create the record's files once the stream's columns are known, each with its header (points.csv and
        tips.csv with the first point: a file of a header alone is not a points file)."""
        rec = self.record
        if rec is None:
            return
        rec.open("samples", ",".join(layout.header))
        self._samples_buf = rec.queue("samples")
        rec.open("events", ",".join(EVENT_COLUMNS))
        self._point_files = {"points": ",".join(points_columns(self.desc.n_joints, layout, self._moves is not None)),
                             "tips": ",".join(TIP_COLUMNS)}
        rec.open("contacts", ",".join(CONTACT_COLUMNS))
        rec.open("features", ",".join(FEATURE_COLUMNS))
        rec.flush()

    def _layout_from(self, s: Sample, wrench: Sequence[float] | None) -> None:
        """The first sample pushed from Python sets the recorded columns (SI)."""
        torque = wrench is not None and len(wrench) == 6
        header = sample_header(self.desc.n_joints, "xyz" if s.wrench is not None else None, torque,
                               s.trigger is not None, s.temperature is not None)
        self.layout = SampleLayout(header, self.desc.n_joints, "<python>")
        self._force_kind = self.layout.force_kind
        self._open_record(self.layout)

    def _sample_text(self, s: Sample) -> str:
        lay = self.layout
        if (s.wrench is not None) != (lay.force_kind is not None) or (s.trigger is not None) != lay.has_trigger \
                or (s.temperature is not None) != lay.has_temperature:
            raise ValueError("every sample pushed must have the same parts (wrench, trigger, temperature) as the first")
        v = [s.t, *s.q]
        if s.wrench is not None:
            v += s.wrench[:6] if lay.has_torque else s.wrench[:3]
        if s.temperature is not None:
            v.append(s.temperature)
        text = ",".join(map(repr, v))
        return text if s.trigger is None else f"{text},{int(s.trigger)}"


class _BlockMasks:
    """Which rows of a :class:`~arm_model.live.samples.SampleBlock` :meth:`Session.push_block` takes by array
    operations: a row is *quiet* when :meth:`Session.push_sample` would find it on the stream's clock (after the row
    before it by more than 0 and at most the gap limit), its force within the probe's range with no over-force
    armed, no joint leaving its limits nor coming back inside one that left them, and the contact detector past its
    first samples. The masks are made again when the session's limits or joints beyond them change."""

    def __init__(self, session: Session, block: SampleBlock):
        self.session, self.block = session, block
        self._key: tuple | None = None
        self._loud: np.ndarray = np.zeros(0, int)
        t = block.t_arr
        self._dt = np.empty(block.n)
        self._dt[1:] = t[1:] - t[:-1]
        self._dt[0] = np.nan
        over = block.mags_arr > session.max_force
        bounds = session._bounds
        if bounds:
            idx = [i for i, _, _ in bounds]
            lo = np.array([lo for _, lo, _ in bounds])
            hi = np.array([hi for _, _, hi in bounds])
            q = block.q[:, idx]
            self._out = (q < lo) | (q > hi)                                           # beyond its limits
            self._inside = (lo + LIMIT_MARGIN_RAD <= q) & (q <= hi - LIMIT_MARGIN_RAD)   # back inside, re-armed
            self._bound_joints = idx
        else:
            self._out = self._inside = np.zeros((block.n, 0), bool)
            self._bound_joints = []
        self._over = over

    def quiet_until(self, k: int) -> int:
        """The first row from ``k`` on that is not quiet (``k`` itself when it is not; the block's length when
        every one is)."""
        s = self.session
        if (s._held or s._last_t is None or s._over or not math.isfinite(s._gap_limit)
                or s._rate_seen is not None or not s._detector.ready(self.block.wrench is not None)):
            return k
        dt = self.block.t[k] - s._last_t
        if not 0.0 < dt <= s._gap_limit or dt > s._jump_limit:
            return k
        key = (s._gap_limit, s._jump_limit, frozenset(s._beyond))
        if key != self._key:
            self._key = key
            loud = self._over.copy()
            loud[1:] |= ~((self._dt[1:] > 0.0) & (self._dt[1:] <= s._gap_limit) & (self._dt[1:] <= s._jump_limit))
            beyond = np.array([i in s._beyond for i in self._bound_joints], bool)
            loud |= (self._out & ~beyond).any(axis=1) | (self._inside & beyond).any(axis=1)
            self._loud = np.flatnonzero(loud)
        at = int(np.searchsorted(self._loud, k))
        if at < len(self._loud) and self._loud[at] == k:
            return k
        return int(self._loud[at]) if at < len(self._loud) else self.block.n


#: columns of ``contacts.csv``
CONTACT_COLUMNS = ("contact", "measurement", "feature", "start_s", "peak_s", "end_s", "samples", "peak_force_N",
                   "over_force", "beyond_limits", "line", "latency_ms")
#: columns of ``events.csv``
EVENT_COLUMNS = ("time_s", "kind", "count", "message")
#: columns of ``features.csv``
FEATURE_COLUMNS = ("point", "feature", "kind", "points", "size_mm", "u_size_mm", "certified_mm", "deviation_mm",
                   "agrees", "form_mm", "u_form_mm", "note")


#: columns of ``tips.csv``: those of ``aacmm tip --uncertainty`` (docs/formats.md §7)
TIP_COLUMNS = ("measurement", "feature", "x_rigid_mm", "y_rigid_mm", "z_rigid_mm", "x_mm", "y_mm", "z_mm",
               "dx_um", "dy_um", "dz_um", "deflection_um", "over_force", "u_x_mm", "u_y_mm", "u_z_mm")


def points_columns(n_joints: int, layout: SampleLayout, moves: bool = True) -> list[str]:
    """The columns of a session's ``points.csv`` (docs/formats.md §3) for a stream of ``layout``: the
    angles in rad and the forces in N, torques in N m, so that each value is the sample's exactly; with ``moves``,
    each joint's last move read from the samples (``q1_move_sign`` ...)."""
    cols = ["measurement", "feature"] + [f"q{j + 1}_rad" for j in range(n_joints)]
    cols += {"xyz": ["fx_N", "fy_N", "fz_N"], "two-channel": ["f_bend_N", "f_axial_N"]}.get(layout.force_kind, [])
    cols += ["mx_Nm", "my_Nm", "mz_Nm"] if layout.has_torque else []
    cols += ["temperature_C"] if layout.has_temperature else []
    return cols + ["time_s"] + (move_columns(n_joints) if moves else [])


def _points_values(ps: PointSet) -> dict:
    """The points-format columns of a one-row point set (SI units: exact values of the samples)."""
    cols = {"measurement": ps.measurement, "feature": ps.feature}
    for j in range(ps.q.shape[1]):
        cols[f"q{j + 1}_rad"] = ps.q[:, j]
    if ps.force is not None:
        if ps.force_kind == "two-channel":
            cols["f_bend_N"], cols["f_axial_N"] = ps.force[:, 0], ps.force[:, 2]
        else:
            cols["fx_N"], cols["fy_N"], cols["fz_N"] = ps.force.T
    if ps.torque is not None:
        cols["mx_Nm"], cols["my_Nm"], cols["mz_Nm"] = ps.torque.T
    if ps.temperature is not None:
        cols["temperature_C"] = ps.temperature
    cols["time_s"] = ps.time
    if ps.motion is not None:
        cols.update(zip(move_columns(ps.n_joints), ps.motion.astype(int).T, strict=True))
    return cols


def _num(x: float) -> str:
    return "" if x is None or not math.isfinite(x) else repr(float(x))


def _csv_line(values: Iterable) -> str:
    import csv
    import io
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerow(list(values))
    return buf.getvalue()
