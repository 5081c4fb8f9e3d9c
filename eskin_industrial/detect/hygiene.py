"""Per-frame input hygiene shared by every streaming detector: the frame-by-frame
form of :func:`~eskin_industrial.detect.regularize.regularize`.

A subclass implements ``_reset(flags)`` (start over: warm-up again) and
``_step(t, forces, flags, out)`` (one clean, regular frame; append any updates to
``out``).  :meth:`FrameHygiene.push` drops frames whose time does not advance,
replaces non-finite values by the taxel's last good one, clips negatives, fills
short gaps by holding the previous frame and resets after long ones.
"""

from __future__ import annotations

import math
from typing import Any, Callable

import numpy as np

from ..frames import FrameFlag

_DUP = int(FrameFlag.DUPLICATE)
_INVALID = int(FrameFlag.INVALID)
_NEG = int(FrameFlag.NEGATIVE)
_GAP = int(FrameFlag.GAP_BEFORE)
_FILLED = int(FrameFlag.FILLED)
_RESET = int(FrameFlag.RESET)


class FrameHygiene:
    n: int  #: taxels

    def __init__(self, n: int, rate_hz: float, max_fill: int) -> None:
        self.n = n
        self._rate = rate_hz
        self._max_fill = max_fill
        # sensor-level memory, kept across resets
        self._last_t = -math.inf
        self._last_good = np.zeros(n)
        self._pending = 0
        self._prev_frame: np.ndarray | None = None
        self.dropped = 0

    def _reset(self, flags: int) -> None:
        raise NotImplementedError

    def _step(self, t: float, f: np.ndarray, flags: int, out: list[Any]) -> None:
        raise NotImplementedError

    def push(self, t: float, forces: np.ndarray, flags: int = 0) -> list[Any]:
        """Feed one frame; returns the updates it completes (usually none or one;
        more only when a gap was filled)."""
        if not t > self._last_t:  # duplicate, out of order, or NaN time
            self.dropped += 1
            self._pending |= _DUP
            return []
        flags |= self._pending
        self._pending = 0
        f = np.asarray(forces, dtype=np.float64)
        if f.shape != (self.n,):
            raise ValueError(f"expected {self.n} taxel forces, got shape {f.shape}")
        if not np.isfinite(f).all():
            f = np.where(np.isfinite(f), f, self._last_good)
            flags |= _INVALID
        self._last_good = f
        if f.min() < 0.0:
            f = np.maximum(f, 0.0)
            flags |= _NEG
        out: list[Any] = []
        last_t = self._last_t
        self._last_t = t
        if self._prev_frame is not None:
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


def feed(push: Callable[[float, np.ndarray, int], list[Any]], t: np.ndarray, forces: np.ndarray,
         flags: np.ndarray | None = None) -> list[Any]:
    """Push a chunk of frames in order through ``push``; all the updates they complete."""
    out: list[Any] = []
    fl = np.zeros(len(t), np.int64) if flags is None else flags
    for i, ti in enumerate(np.asarray(t, dtype=np.float64).tolist()):
        out.extend(push(ti, forces[i], int(fl[i])))
    return out
