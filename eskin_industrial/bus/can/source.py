"""CAN scans one at a time, for loops that poll a source (the Modbus bridge loop).

:class:`~eskin_industrial.bus.can_source.CanSource` runs its own loop into a
pipeline; this adapter instead hands out one :class:`RawScan` per ``poll()``, with
the health a bridge publishes (frame age, bus fault) and the CAN counters.
"""

from __future__ import annotations

import collections
import time

from ...frames import RawScan
from .layout import ScanAssembler
from .reader import BusReader


class _Counters:
    def __init__(self, poller: "CanScanPoller") -> None:
        self._p = poller

    @property
    def bus_errors(self) -> int:
        return self._p.reader.counters.get("bus_errors", 0)

    def as_dict(self) -> dict[str, int]:
        return {**self._p.assembler.counters, **self._p.reader.counters}


class CanScanPoller:
    def __init__(self, reader: BusReader, assembler: ScanAssembler, idle_sleep_s: float = 0.0005) -> None:
        self.reader = reader
        self.assembler = assembler
        self.idle_sleep_s = idle_sleep_s
        self.counters = _Counters(self)
        self._ready: collections.deque[RawScan] = collections.deque()
        self._last_rx: float | None = None
        self._errors_seen = 0

    @property
    def bus_fault(self) -> bool:
        """Bus errors were reported and no frame has arrived since."""
        return self.counters.bus_errors > self._errors_seen

    def poll(self, timeout_s: float | None = None) -> RawScan | None:
        """The next complete scan, or None after waiting up to ``timeout_s`` (default
        ``idle_sleep_s``) for frames."""
        q = self.reader.queue
        if not self._ready and not q:
            arrived = getattr(self.reader, "arrived", None)
            wait = self.idle_sleep_s if timeout_s is None else timeout_s
            if arrived is None:
                time.sleep(wait)
            else:
                # Cleared before the second look, so a frame queued in between is seen.
                arrived.clear()
                if not q:
                    arrived.wait(wait)
        while not self._ready and q:
            scan = self.assembler.feed(q.popleft())
            self._errors_seen = self.counters.bus_errors  # a frame arrived: the bus works
            if scan is not None:
                self._ready.append(scan)
        if self._ready:
            self._last_rx = time.monotonic()
            return self._ready.popleft()
        return None

    @property
    def pending(self) -> bool:
        """Frames or scans are waiting: another ``poll`` returns at once."""
        return bool(self._ready or self.reader.queue)

    def frame_age(self, now: float | None = None) -> float | None:
        if self._last_rx is None:
            return None
        return (time.monotonic() if now is None else now) - self._last_rx
