"""Make a recording fit for the detector: the batch form of what the stream does
frame by frame (see :class:`~eskin_industrial.detect.stream.IndicatorStream`).

1. A frame whose timestamp is not after every earlier kept one (duplicate, out of
   order) or is no time (NaN, infinite, beyond +-1e10 s) is dropped
   (:func:`~.hygiene.time_verdicts`); the next kept frame carries DUPLICATE.
2. A force beyond :data:`~.hygiene.FORCE_LIMIT_N` is clipped to it, flag SATURATED;
   a non-finite force is replaced by that taxel's last finite value (0 before any),
   flag INVALID; a negative force becomes 0, flag NEGATIVE.
3. A gap of ``m`` missing periods (``m = round(dt * rate) - 1``) is filled with ``m``
   copies of the previous frame (flag FILLED) when ``m <= max_fill``, so that the lag
   and window stay in time; a longer gap starts a new segment (flag RESET).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .hygiene import _DUP, _FILLED, _GAP, _INVALID, _NEG, _RESET, _SAT, FORCE_LIMIT_N, TIME_KEPT, time_verdicts


@dataclass(frozen=True)
class Regularized:
    t: np.ndarray  #: (K,) strictly increasing
    forces: np.ndarray  #: (K, n) finite, >= 0
    flags: np.ndarray  #: (K,) int64
    segments: list[tuple[int, int]]  #: [start, stop) of each run without a reset
    dropped: int  #: frames dropped for their timestamp


def forward_fill_rows(values: np.ndarray, ok: np.ndarray, initial: np.ndarray) -> np.ndarray:
    """Replace rows (or elements) where ``ok`` is False by the last ok one, column-wise.

    ``values`` (K, n) or (K,), ``ok`` of the same shape; before any ok value,
    ``initial`` (broadcast to one row).
    """
    k = values.shape[0]
    index = np.arange(k).reshape((k,) + (1,) * (values.ndim - 1))
    last = np.where(ok, index, -1)
    np.maximum.accumulate(last, axis=0, out=last)
    taken = np.take_along_axis(values, np.maximum(last, 0), axis=0)
    return np.where(last >= 0, taken, initial)


def regularize(t: np.ndarray, forces: np.ndarray, rate_hz: float, max_fill: int, flags: np.ndarray | None = None) -> Regularized:
    t = np.asarray(t, dtype=np.float64)
    forces = np.asarray(forces, dtype=np.float64)
    if forces.ndim != 2 or forces.shape[0] != t.shape[0]:
        raise ValueError(f"expected forces of shape (len(t), taxels), got {forces.shape} for {t.shape[0]} timestamps")
    flags = np.zeros(t.shape[0], np.int64) if flags is None else np.asarray(flags, dtype=np.int64).copy()

    # 1. drop frames whose time does not advance, or is no time
    keep = time_verdicts(t) == TIME_KEPT
    keep_idx = np.flatnonzero(keep)
    dropped_idx = np.flatnonzero(~keep)
    if dropped_idx.size and keep_idx.size:
        nxt = np.searchsorted(keep_idx, dropped_idx)
        nxt = nxt[nxt < keep_idx.size]
        np.bitwise_or.at(flags, keep_idx[nxt], _DUP)
    t, forces, flags = t[keep_idx], forces[keep_idx], flags[keep_idx]

    # 2. sanitize values
    given = forces
    finite = np.isfinite(forces)
    if not finite.all():
        flags |= np.where(finite.all(axis=1), 0, _INVALID)
        forces = forward_fill_rows(forces, finite, np.zeros(forces.shape[1]))
    if forces.size and forces.max() > FORCE_LIMIT_N:  # rare: one reduction decides
        # flagged where a finite force was past the limit (a held copy of one, as the
        # stream holds the clipped value, is not), then clipped everywhere
        flags |= np.where((finite & (given > FORCE_LIMIT_N)).any(axis=1), _SAT, 0)
        forces = np.minimum(forces, FORCE_LIMIT_N)
    negative = forces < 0
    if negative.any():
        flags |= np.where(negative.any(axis=1), _NEG, 0)
        forces = np.maximum(forces, 0.0)

    # 3. gaps: fill short ones, cut segments at long ones
    k = t.shape[0]
    missing = np.zeros(k, np.int64)
    if k > 1:
        # (clipped before the cast: a gap of 2e10 s at a high rate overflows an int64)
        steps = np.minimum(np.rint(np.diff(t) * rate_hz), max_fill + 2.0)
        missing[1:] = np.maximum(steps.astype(np.int64) - 1, 0)
    reset = missing > max_fill
    fill = np.where(reset, 0, missing)
    flags |= np.where(missing > 0, _GAP, 0) | np.where(reset, _RESET, 0)
    if fill.any():
        # frame j is followed by fill[j+1] held copies of itself
        after = np.append(fill[1:], 0)
        counts = 1 + after
        src = np.repeat(np.arange(k), counts)
        first = np.concatenate(([0], np.cumsum(counts)[:-1]))
        offset = np.arange(src.size) - np.repeat(first, counts)  # 0 for the real frame
        t = t[src] + offset / rate_hz
        forces = forces[src]
        flags = np.where(offset > 0, _FILLED, flags[src])
        reset = np.where(offset > 0, False, reset[src])
    starts = np.flatnonzero(reset).tolist()
    bounds = [0] + [s for s in starts if s > 0] + [t.shape[0]]
    segments = [(a, b) for a, b in zip(bounds[:-1], bounds[1:]) if b > a]
    return Regularized(t, forces, flags, segments, int(dropped_idx.size))
