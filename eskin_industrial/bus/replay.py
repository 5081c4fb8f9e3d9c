"""A recording's (or a rendered scene's) raw scans replayed in real time, as if polled."""

from __future__ import annotations

import time

import numpy as np

from ..frames import RawScan
from ..profile import Profile


class ReplaySource:
    """A recording's raw scans played at ``rate_hz`` (any speed), as if polled; scan
    times are the recording's."""

    def __init__(self, profile: Profile, t: np.ndarray, raw: np.ndarray, rate_hz: float, *, loop: bool = False) -> None:
        self.t, self.raw, self.rate_hz, self.loop = t, raw, rate_hz, loop
        self.k = 0
        self.bus_fault = False
        self.last_rx: float | None = None
        self._next = time.monotonic()

    @property
    def done(self) -> bool:
        return not self.loop and self.k >= len(self.t)

    def poll(self, timeout_s: float | None = None) -> RawScan | None:
        now = time.monotonic()
        if self._next > now:
            time.sleep(self._next - now)
        self._next = max(self._next, now) + 1.0 / self.rate_hz
        if self.done:
            return None
        lap, i = divmod(self.k, len(self.t))
        self.k += 1
        rx = time.monotonic()
        self.last_rx = rx
        # The recording's own time (each loop continues it), whatever the replay speed.
        t = float(self.t[i]) + lap * (float(self.t[-1] - self.t[0]) + 1.0 / self.rate_hz)
        return RawScan(self.k - 1, t, self.raw[i], 0, rx)

    def frame_age(self, now: float | None = None) -> float | None:
        if self.last_rx is None:
            return None
        return (time.monotonic() if now is None else now) - self.last_rx
