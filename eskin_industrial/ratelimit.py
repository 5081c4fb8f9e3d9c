"""One log line per kind of event per interval at most, the rest counted: what keeps a
client that floods (commands, malformed requests) from flooding the log too."""

from __future__ import annotations

import threading
import time
from collections.abc import Hashable

#: One log line per event name in this time at most; the rest are counted.
LOG_EVERY_S = 10.0


class Throttle:
    """``passes(key)``: None while ``key`` passed less than ``every_s`` ago (counted as
    held back), else the number held back since its last pass (0 for none).  Safe
    from any thread."""

    def __init__(self, every_s: float = LOG_EVERY_S) -> None:
        self.every_s = every_s
        self._last: dict[Hashable, float] = {}
        self._held: dict[Hashable, int] = {}
        self._lock = threading.Lock()

    def passes(self, key: Hashable) -> int | None:
        now = time.monotonic()
        with self._lock:
            last = self._last.get(key)
            if last is not None and now - last < self.every_s:
                self._held[key] = self._held.get(key, 0) + 1
                return None
            self._last[key] = now
            return self._held.pop(key, 0)
