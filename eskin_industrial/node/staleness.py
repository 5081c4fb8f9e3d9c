"""When a silent sensor is stale: a limit that tracks the sensor's own arrivals, not
the host's scheduling.

Pure code, no clock: :meth:`Staleness.observe` takes each scan's host receipt time.
The limit starts at ``[output] stale_s`` (2.5 scan periods) and rises to 1.5 times
the longest interval between arrivals seen lately (a maximum that decays with a
half-life of :data:`HALF_LIFE_S`), never above ``stale_max_s``.  A healthy sensor on
a loaded host, whose scans reach the loop 30 ms apart now and then, thus stops
reading stale for that, while a silent one is still flagged within ``stale_max_s``
at worst (within ``stale_s`` once the arrivals have been regular for a while).

An interval longer than ``stale_max_s`` / 1.5 is a silence, not jitter, and teaches
nothing: one dropout does not raise the limit for the next.
"""

from __future__ import annotations

import math

#: The learnt longest interval halves in this long without a new one as long.
HALF_LIFE_S = 30.0
#: The limit is this many times the longest interval seen lately.
MARGIN = 1.5


class Staleness:
    """The stale limit of one node, learnt from its arrivals."""

    __slots__ = ("base_s", "max_s", "limit_s", "_longest", "_last", "_at")

    def __init__(self, stale_s: float, stale_max_s: float) -> None:
        self.base_s = stale_s
        self.max_s = max(stale_max_s, stale_s)
        self.limit_s = stale_s  #: the limit now
        self._longest = 0.0  #: the longest interval seen lately (decayed)
        self._last = math.nan
        self._at = math.nan  #: when _longest was last set

    def observe(self, rx: float) -> float:
        """A scan arrived at ``rx`` (host monotonic seconds); the limit after it."""
        last, self._last = self._last, rx
        if not rx > last or self.max_s <= self.base_s:  # (the first scan, NaN, or learning off)
            return self.limit_s
        gap = rx - last
        longest = self._longest * 0.5 ** ((rx - self._at) / HALF_LIFE_S) if self._longest > 0 else 0.0
        if gap * MARGIN <= self.max_s and gap > longest:
            self._longest, self._at = gap, rx
            longest = gap
        self.limit_s = min(max(self.base_s, MARGIN * longest), self.max_s)
        return self.limit_s
