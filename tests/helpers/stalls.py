"""How long this test process went without running: a thread that wakes every
millisecond or two and notes when it did.

A test that times the bridge against the wall clock (a verdict withdrawn within the
stale limit, say) shares its process and two cores with the rest of the suite: a
pause of the whole process (a descheduled interpreter, a full garbage collection)
delays the bridge and the test's own PLC stand-in alike, and a write sent in time is
then noted late.  Such a test allows the longest pause this meter saw; a bridge that
is late on its own is late with no pause to excuse it, and still fails.
"""

from __future__ import annotations

import threading
import time
from types import TracebackType


class StallMeter:
    def __init__(self, every_s: float = 0.001) -> None:
        self.every_s = every_s
        self.ticks: list[float] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="stall-meter", daemon=True)

    def _run(self) -> None:
        while not self._stop.is_set():
            self.ticks.append(time.perf_counter())
            time.sleep(self.every_s)

    def __enter__(self) -> StallMeter:
        self._thread.start()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self._stop.set()
        self._thread.join(1)

    def longest(self, t0: float, t1: float) -> float:
        """The longest gap between ticks (perf_counter) that overlaps ``[t0, t1]``, in seconds."""
        ticks = list(self.ticks)
        gaps = [b - a for a, b in zip(ticks, ticks[1:]) if b >= t0 and a <= t1]
        return max(gaps, default=0.0)
