"""The direction each joint last turned before a contact, from the sample stream itself (docs/live.md, "The
last move of each joint").

A model with a :class:`~arm_model.effects.JointHysteresis` effect needs, per point, the sign of each joint's last
move onto it (its ``motion`` input). ``aacmm tip`` and the calibration take it from the point captured before
(:func:`arm_model.model.reading_motion`); a live session has every sample between two points, so it follows each
joint's readings out of contact with a dead band: a joint's move is the direction it travels, and it turns only
once its reading came back from the far end of that travel by more than the band (a play operator), so that the
encoder's noise and a reading flickering between two steps never turn it. The band of joint j is the larger of

* :data:`BAND_STEPS` steps of its encoder (the resolution the session's input uncertainties hold: the
  description's ``encoder_resolution_deg`` or ``--encoder-resolution-deg``), and
* :data:`BAND_SIGMAS` times the noise of its reading while the probe is held against the part (the samples in
  contact: the operator holds still), estimated from their differences sample to sample, robustly (the median
  absolute difference), after each contact from the last :data:`NOISE_SAMPLES` of them.

The samples in contact do not move the joints' directions: the sign of a point is that of the last move before
its contact began.
"""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

__all__ = ["LastMove", "BAND_STEPS", "BAND_SIGMAS", "NOISE_SAMPLES", "NOISE_LEAST"]

#: the dead band is at least this many encoder steps (a reading flickering between two steps moves by one)
BAND_STEPS = 3.0
#: ... and at least this many standard deviations of a joint's reading noise (white noise held still for 10^5
#: samples spans about +-4.4 sigma)
BAND_SIGMAS = 10.0
#: the samples in contact (their differences) the noise is estimated from: the latest ones
NOISE_SAMPLES = 5000
#: the fewest differences an estimate takes
NOISE_LEAST = 20
#: the standard deviation of a normal variable over the median of its absolute value
_MAD_TO_SIGMA = 1.482602218505602


class LastMove:
    """The sign (-1, 0, +1) of each joint's last move in a stream of readings (see the module doc).

    Args:
        steps: (J,) each joint's encoder step [rad] ([m] for a prismatic joint; 0: not known).
    """

    def __init__(self, steps: Sequence[float]):
        #: (J,) each joint's encoder step [rad] ([m])
        self.encoder_steps = [float(s) for s in steps]
        #: (J,) the least dead band of each joint: :data:`BAND_STEPS` steps [rad] ([m])
        self.steps = [BAND_STEPS * s for s in self.encoder_steps]
        #: (J,) the dead band of each joint [rad] ([m])
        self.band = list(self.steps)
        #: (J,) the sign of each joint's last move (0: it has not moved beyond its band yet)
        self.sign = [0.0] * len(self.steps)
        self._end: list[float] | None = None         # the far end of each joint's current travel
        self._held: Sequence[float] | None = None    # the last reading in contact
        # the latest NOISE_SAMPLES differences in contact, a ring (their median does not depend on the order)
        self._diffs = np.zeros((NOISE_SAMPLES, len(self.steps)))
        self._n_diffs = 0                            # differences written so far

    def free(self, q: Sequence[float]) -> None:
        """A sample out of contact: readings ``q`` (J,)."""
        self._held = None
        end = self._end
        if end is None:
            self._end = list(q)
            return
        sign, band = self.sign, self.band
        for j, x in enumerate(q):
            s, e = sign[j], end[j]
            if (s > 0 and x > e) or (s < 0 and x < e):        # further the same way
                end[j] = x
            elif x - e > band[j]:
                sign[j], end[j] = 1.0, x
            elif e - x > band[j]:
                sign[j], end[j] = -1.0, x

    def held(self, q: Sequence[float]) -> None:
        """A sample in contact: its readings' differences from the sample before it (the noise)."""
        if self._held is not None:
            self._diffs[self._n_diffs % NOISE_SAMPLES] = [abs(a - b) for a, b in zip(q, self._held, strict=True)]
            self._n_diffs += 1
        self._held = q

    def follow(self, q: np.ndarray, held: np.ndarray) -> None:
        """Samples in a row at once: readings ``q`` (n, J), ``held`` (n,) True for a sample in contact; the same
        state as :meth:`held` and :meth:`free` on each in turn (the same comparisons on the same numbers)."""
        if not len(q):
            return
        prev = np.empty_like(q)
        prev[1:] = q[:-1]
        inner = np.empty(len(q), bool)
        inner[1:] = held[:-1]
        inner[0] = self._held is not None
        if inner[0]:
            prev[0] = self._held
        pairs = held & inner                        # held after a held one: a difference
        self._ring(np.abs(q[pairs] - prev[pairs]))
        self._held = q[-1].tolist() if held[-1] else None
        free = q[~held]
        if len(free) and self._end is None:
            self._end = free[0].tolist()
            free = free[1:]
        if len(free):
            self._free_rows(free)

    def _ring(self, d: np.ndarray) -> None:
        """Write differences (k, J) into the ring of the latest :data:`NOISE_SAMPLES`, in order."""
        d = d[-NOISE_SAMPLES:]
        at = (self._n_diffs + np.arange(len(d))) % NOISE_SAMPLES
        self._diffs[at] = d
        self._n_diffs += len(d)

    def _free_rows(self, x: np.ndarray) -> None:
        """:meth:`free` on each row of ``x`` (n, J) in turn, by array operations: a joint travelling up keeps the
        running maximum as its end and turns at the first reading more than its band below it (down: the running
        minimum, above it; not moved yet: the first reading beyond the band either side of its start)."""
        sign, end, band = self.sign, self._end, self.band
        assert end is not None, "the first free reading sets the ends"
        todo = [(j, 0) for j in range(x.shape[1])]
        while todo:
            nxt = []
            for j, a in todo:
                col, s, e = x[a:, j], sign[j], end[j]
                if s > 0:
                    run = np.maximum.accumulate(np.maximum(col, e))
                    beyond = run - col > band[j]
                elif s < 0:
                    run = np.minimum.accumulate(np.minimum(col, e))
                    beyond = col - run > band[j]
                else:
                    beyond = np.abs(col - e) > band[j]
                k = int(np.argmax(beyond)) if len(col) else 0
                if not len(col) or not beyond[k]:
                    if s != 0 and len(col):
                        end[j] = float(run[-1])
                    continue
                xk = float(col[k])
                sign[j] = (1.0 if xk - e > band[j] else -1.0) if s == 0 else -s
                end[j] = xk
                if a + k + 1 < len(x):
                    nxt.append((j, a + k + 1))
            todo = nxt

    def settle(self) -> None:
        """After a contact: the band from the noise of the readings held so far (:data:`BAND_SIGMAS`)."""
        n = min(self._n_diffs, NOISE_SAMPLES)
        if n < NOISE_LEAST:
            return
        sigma = np.median(self._diffs[:n], axis=0) * _MAD_TO_SIGMA / math.sqrt(2.0)
        self.band = [max(s, BAND_SIGMAS * float(n)) for s, n in zip(self.steps, sigma, strict=True)]

    def motion(self) -> np.ndarray:
        """(1, J) the sign of each joint's last move, as :func:`arm_model.model.points_motion` takes it."""
        return np.array([self.sign])
