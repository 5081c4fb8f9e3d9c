"""Per-frame input hygiene shared by every streaming detector: the frame-by-frame
form of :func:`~eskin_industrial.detect.regularize.regularize`.

A subclass implements ``_reset(flags)`` (start over: warm-up again) and
``_step(t, forces, flags, out)`` (one clean, regular frame; append any updates to
``out``).  :meth:`FrameHygiene.push` drops frames whose time does not advance or
is not a time at all (:func:`time_verdicts`), replaces non-finite values by the
taxel's last good one, clips negatives and forces past :data:`FORCE_LIMIT_N`, fills
short gaps by holding the previous frame and resets after long ones.

The two limits keep every later sum, square and ratio a finite float whatever a file
or a bus delivers; the input paths clamp at the profile's ``full_scale_n`` first
(:func:`~eskin_industrial.calibration.full_scale`), so on real input they never bite.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from ..frames import FrameFlag

_DUP = int(FrameFlag.DUPLICATE)
_INVALID = int(FrameFlag.INVALID)
_NEG = int(FrameFlag.NEGATIVE)
_GAP = int(FrameFlag.GAP_BEFORE)
_FILLED = int(FrameFlag.FILLED)
_RESET = int(FrameFlag.RESET)
_SAT = int(FrameFlag.SATURATED)

#: Largest force a taxel may carry into the detector (N); beyond, it is clipped and
#: the frame flagged SATURATED.  No tactile taxel reads a meganewton, and with it the
#: squares of a sum over 10,000 taxels stay far inside a float's range.
FORCE_LIMIT_N = 1e6
# the reductions without numpy's Python wrapper (``a.min()`` adds a frame a call)
_MIN = np.minimum.reduce
_MAX = np.maximum.reduce
#: A time must lie strictly within +-1e10 s (year 2286 as a Unix time) to be one: past
#: it, a float64 no longer resolves a microsecond, and a single absurd time would
#: otherwise hold back every frame after it as "not after the previous one".
TIME_LIMIT_S = 1e10

#: Why a frame was refused for its time (:func:`time_verdicts`); 0: kept.
TIME_KEPT, TIME_NOT_A_TIME, TIME_REPEATED, TIME_BACKWARD = 0, 1, 2, 3
#: Names of the refusals, as counters and in the ``detect`` summary.
TIME_FAULTS = {TIME_NOT_A_TIME: "not_a_time", TIME_REPEATED: "repeated_time", TIME_BACKWARD: "backward_time"}


def time_verdicts(t: np.ndarray) -> np.ndarray:
    """Per frame, whether its time is kept (0) or why it is refused: not a time
    (non-finite, or not within +-TIME_LIMIT_S), the same as the newest kept time, or
    before it (a backward jump: every frame until time passes the newest kept one).
    The one rule the stream (:meth:`FrameHygiene.push`) and the batch code apply."""
    t = np.asarray(t, dtype=np.float64)
    if t.size and -TIME_LIMIT_S < t[0] and t[-1] < TIME_LIMIT_S and (np.diff(t) > 0).all():
        return np.zeros(t.shape, np.int8)  # the usual recording: every time after the one before
    ok = np.abs(t) < TIME_LIMIT_S  # False for NaN
    # the newest kept time before each frame: a time that is none counts as -inf, so
    # it never becomes it (NaN would: a first frame with no time left NaN as the
    # newest, and the next, a good time, was then refused as backward)
    newest = np.full(t.shape, -np.inf)
    if t.size > 1:
        newest[1:] = np.maximum.accumulate(np.where(ok, t, -np.inf)[:-1])
    out = np.full(t.shape, TIME_BACKWARD, np.int8)
    out[t > newest] = TIME_KEPT
    out[t == newest] = TIME_REPEATED
    out[~ok] = TIME_NOT_A_TIME
    return out


#: A recording whose timestamps show a rate more than this factor away from the
#: expected one (``--rate``, else the profile's ``rate_hz``) is refused: its times are
#: in another unit (ms, us) or are no clock at all.
RATE_TOLERANCE = 10.0


def rate_problem(t: np.ndarray, expected_hz: float, what: str = "") -> str | None:
    """Why the timestamps ``t`` cannot be a recording at ``expected_hz`` (None: they
    can): no two kept times differ, or their median rate lies outside
    [expected / RATE_TOLERANCE, expected x RATE_TOLERANCE].  ``what`` names where the
    expected rate comes from, for the message."""
    t = np.asarray(t, dtype=np.float64)
    if t.size < 2:
        return None
    kept = t[time_verdicts(t) == TIME_KEPT]
    if kept.size < 2:
        return f"the timestamps never advance ({t.size} frames, {kept.size} usable distinct time)"
    rate = 1.0 / float(np.median(np.diff(kept)))
    lo, hi = expected_hz / RATE_TOLERANCE, expected_hz * RATE_TOLERANCE
    # Inclusive, up to the rounding of times written in decimal: 1 ms steps of a 1 kHz
    # recording give 1000.0000001 Hz, which is 1000 Hz.
    if not lo * (1 - _RATE_SLACK) <= rate <= hi * (1 + _RATE_SLACK):
        return (f"the timestamps show {_outside(rate, lo, hi)} Hz, implausible for {what or 'a rate of'} "
                f"{expected_hz:g} Hz (accepted: {lo:g} to {hi:g} Hz); are the times in seconds?")
    return None


#: The relative slack of :func:`rate_problem`'s bounds (times in a CSV carry about 9
#: significant digits).
_RATE_SLACK = 1e-6


def _outside(rate: float, lo: float, hi: float) -> str:
    """``rate`` with as many digits as it takes to read outside [lo, hi] (a message
    must not say "1000 Hz ... accepted: 10 to 1000 Hz")."""
    for digits in range(4, 17):
        shown = f"{rate:.{digits}g}"
        if not lo <= float(shown) <= hi:
            return shown
    return repr(rate)


class FrameHygiene:
    n: int  #: taxels

    def __init__(self, n: int, rate_hz: float, max_fill: int) -> None:
        self.n = n
        self._rate = rate_hz
        self._max_fill = max_fill
        # sensor-level memory, kept across resets
        self._last_t = -TIME_LIMIT_S
        self._last_good = np.zeros(n)
        self._pending = 0
        self._prev_frame: np.ndarray | None = None
        self.dropped = 0
        #: frames refused for their time, by :data:`TIME_FAULTS` name (sum: ``dropped``)
        self.time_faults = dict.fromkeys(TIME_FAULTS.values(), 0)

    def _reset(self, flags: int) -> None:
        raise NotImplementedError

    def _step(self, t: float, f: np.ndarray, flags: int, out: list[Any]) -> None:
        raise NotImplementedError

    def push(self, t: float, forces: np.ndarray, flags: int = 0) -> list[Any]:
        """Feed one frame; returns the updates it completes (usually none or one;
        more only when a gap was filled)."""
        if not self._last_t < t < TIME_LIMIT_S:  # repeated, backward, NaN or absurd
            self._refuse(t)
            return []
        flags |= self._pending
        self._pending = 0
        f = np.asarray(forces, dtype=np.float64)
        if f.shape != (self.n,):
            raise ValueError(f"expected {self.n} taxel forces, got shape {f.shape}")
        # two reductions decide the common case (NaN fails both comparisons)
        if not (_MIN(f) >= 0.0 and _MAX(f) <= FORCE_LIMIT_N):
            f, flags = self._clean(f, flags)
        else:
            self._last_good = f
        out: list[Any] = []
        last_t = self._last_t
        self._last_t = t
        if self._prev_frame is not None:
            # (at most 2e10 s times the rate: a float that int() takes whole)
            missing = max(int(np.rint((t - last_t) * self._rate)) - 1, 0)
            if missing > self._max_fill:
                self._reset(0)
                flags |= _GAP | _RESET
            elif missing:
                flags |= _GAP
                prev = self._prev_frame
                for m in range(1, missing + 1):
                    self._step(last_t + m / self._rate, prev, _FILLED, out)
        self._prev_frame = f
        self._step(t, f, flags, out)
        return out

    def _refuse(self, t: float) -> None:
        self.dropped += 1
        self._pending |= _DUP
        if not abs(t) < TIME_LIMIT_S:
            kind = TIME_NOT_A_TIME
        else:
            kind = TIME_REPEATED if t == self._last_t else TIME_BACKWARD
        self.time_faults[TIME_FAULTS[kind]] += 1

    def _clean(self, f: np.ndarray, flags: int) -> tuple[np.ndarray, int]:
        """A frame with a non-finite, negative or huge force, made fit (the rare path)."""
        finite = np.isfinite(f)
        if not finite.all():
            f = np.where(finite, f, self._last_good)
            flags |= _INVALID
        if f.max() > FORCE_LIMIT_N:
            f = np.minimum(f, FORCE_LIMIT_N)
            flags |= _SAT
        self._last_good = f
        if f.min() < 0.0:
            f = np.maximum(f, 0.0)
            flags |= _NEG
        return f, flags


def feed(push: Callable[[float, np.ndarray, int], list[Any]], t: np.ndarray, forces: np.ndarray,
         flags: np.ndarray | None = None) -> list[Any]:
    """Push a chunk of frames in order through ``push``; all the updates they complete."""
    out: list[Any] = []
    fl = np.zeros(len(t), np.int64) if flags is None else flags
    for i, ti in enumerate(np.asarray(t, dtype=np.float64).tolist()):
        out.extend(push(ti, forces[i], int(fl[i])))
    return out
