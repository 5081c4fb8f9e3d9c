"""Is this sensor still a sensor?  The scan-by-scan judgement that lets a verdict
fall when the data behind it is not data.

Pure code, no I/O and no clock: :meth:`IntegrityWatch.push` takes each calibrated
scan (its time on the sensor's clock, its forces with NaN where a reading was
invalid, and its raw values) and returns the sensor-fault bits of that moment
(:data:`~eskin_industrial.frames.SENSOR_FAULTS`):

- ``DEAD_TAXELS``: the detector replaces an invalid reading (an open line, a short,
  NaN) by the taxel's last good value; that is a guess, and it is allowed for at
  most ``hold_s`` per taxel and for at most ``hold_share`` of the taxels at once.
  Past either limit the frame is made up, not measured.
- ``FROZEN``: the raw scans have been identical, every taxel to the bit, for longer
  than ``frozen_s``.  A live piezoresistive array never repeats 25 readings exactly
  for half a second; a hung node repeating its last buffer does.
- ``RATE``: the median interval of the last :data:`RATE_WINDOW` scans, on the
  sensor's own timestamps, is more than ``rate_tolerance`` times away from the rate
  the detector assumes (its windows and lags are counted in samples of that rate).

The per-scan cost on a healthy sensor is one flag test, one comparison of the raw
scan's bytes with the last one's and a list write; the median is taken once every
:data:`RATE_WINDOW` scans.  (At 1 kHz these are the bridge's per-scan budget: an
``np.array_equal``, a copy and a numpy ring cost a tenth of the loop's scan.)
"""

from __future__ import annotations

import math
import statistics

import numpy as np

from ..frames import FrameFlag

_DEAD, _FROZEN, _RATE = int(FrameFlag.DEAD_TAXELS), int(FrameFlag.FROZEN), int(FrameFlag.RATE)

#: Scan intervals behind one rate judgement (and scans between two judgements).
RATE_WINDOW = 32


class IntegrityWatch:
    """The sensor-fault bits of one node's scans, one scan at a time."""

    def __init__(self, taxels: int, rate_hz: float, *, hold_s: float, hold_share: float, frozen_s: float,
                 rate_tolerance: float) -> None:
        self.n = taxels
        self.rate_hz = rate_hz
        self.hold_s = hold_s
        #: at most this many taxels may be held at once
        self.max_held = int(math.floor(hold_share * taxels + 1e-9))
        self.frozen_s = frozen_s
        self.rate_tolerance = rate_tolerance
        self._invalid_since = np.full(taxels, np.nan)  # NaN: the taxel reads
        self._any_invalid = False
        self._prev_raw: bytes | None = None  # the last distinct raw scan, its bytes
        self._same_since = math.nan  # time of the first scan of the identical run
        self._last_t = math.nan
        self._intervals = [0.0] * RATE_WINDOW
        self._k = 0
        self._filled = 0
        self._rate_bad = False
        self.fault = 0  #: the bits of the newest scan

    def push(self, t: float, forces: np.ndarray, raw: np.ndarray, invalid: bool) -> int:
        """The fault bits after this scan.  ``invalid``: the frame carries INVALID (some
        force is NaN); the per-taxel work is done only then, or while a run lasts."""
        fault = 0
        last = self._last_t
        if invalid or self._any_invalid:
            fault |= self._held(t, forces)
        if self.frozen_s > 0:
            fault |= self._frozen(t, raw, last)
        if self.rate_tolerance > 0:
            fault |= self._rate(t, last)
        if not t <= last:  # (a time that goes back or repeats is the detector's to refuse)
            self._last_t = t
        self.fault = fault
        return fault

    def _held(self, t: float, forces: np.ndarray) -> int:
        bad = ~np.isfinite(forces)
        since = self._invalid_since
        since[~bad] = np.nan
        fresh = bad & np.isnan(since)
        since[fresh] = t
        held = int(bad.sum())
        self._any_invalid = held > 0
        if held > self.max_held:
            return _DEAD
        # (NaN - t is NaN, and NaN > hold_s is False: a reading taxel never counts)
        if held and bool((t - since[bad] > self.hold_s).any()):
            return _DEAD
        return 0

    def _frozen(self, t: float, raw: np.ndarray, last: float) -> int:
        # identical to the bit: the bytes (of the same dtype, so the same length for
        # the same shape); a hung node repeats its buffer exactly, NaN included
        now = raw.tobytes()
        if now == self._prev_raw:
            if math.isnan(self._same_since):
                # the run began with the scan before, the first of the identical ones
                self._same_since = last if math.isfinite(last) else t
            return _FROZEN if t - self._same_since > self.frozen_s else 0
        self._prev_raw = now
        self._same_since = math.nan
        return 0

    def _rate(self, t: float, last: float) -> int:
        if not (math.isfinite(last) and t > last):
            return _RATE if self._rate_bad else 0
        self._intervals[self._k] = t - last
        self._k = (self._k + 1) % RATE_WINDOW
        self._filled += 1
        if self._filled >= RATE_WINDOW and self._k == 0:
            rate = 1.0 / statistics.median(self._intervals)
            tol = self.rate_tolerance
            self._rate_bad = not self.rate_hz / tol <= rate <= self.rate_hz * tol
        return _RATE if self._rate_bad else 0
