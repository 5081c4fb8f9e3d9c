"""The bridge loop for one sensor node: source -> pipeline -> register image -> PLC sink.

The source is anything with ``poll(timeout_s) -> RawScan | None`` (the RTU poller,
the CAN scan poller, a recording replay), ``bus_fault``, ``frame_age()`` and
bus-error counters.  The sink is a :class:`~eskin_industrial.bus.plc_server.PlcServer`
(or one block of it) or a :class:`~eskin_industrial.bus.plc_client.PlcWriter`; both
take ``publish`` and hand back the PLC's commands.  A state change is published at
once, a status bit change (stale, bus fault) as soon as it happens, otherwise every
``refresh_s``.  :meth:`ModbusBridge.shutdown` leaves the PLC reading BRIDGE_OFFLINE.
"""

from __future__ import annotations

import collections
import threading
import time
from collections.abc import Callable
from typing import Protocol

import numpy as np

from ..detect.updates import Update
from ..frames import RawScan
from ..pipeline import Pipeline
from ..plc.image import Command, Health, PlcImage, Status
from ..profile import Profile

_QUIET = ~int(Status.BRIDGE_ALIVE)  # the life bit changes at every publication


class Source(Protocol):
    bus_fault: bool

    def poll(self, timeout_s: float | None = None) -> RawScan | None: ...

    def frame_age(self, now: float | None = None) -> float | None: ...


class Sink(Protocol):
    def publish(self, registers: list[int], image: PlcImage, urgent: bool = False,
                t_event: float | None = None) -> None: ...

    def take_commands(self) -> list[Command]: ...

    def commands_done(self) -> None: ...


class ModbusBridge:
    #: Unloaded scans kept for a tare.
    TARE_SCANS = 50

    #: Longest wait for traffic before the loop looks at the time again.
    MAX_WAIT_S = 0.05

    def __init__(self, profile: Profile, source, sink, *, rate_hz: float | None = None,
                 on_update: Callable[[Update], None] | None = None,
                 on_command: Callable[[str], None] | None = None) -> None:
        self.profile = profile
        self.source = source
        self.sink = sink
        self.pipeline = Pipeline(profile, rate_hz=rate_hz)
        self.image = PlcImage(profile.modbus.plc)
        self.recent_raw: collections.deque[np.ndarray] = collections.deque(maxlen=self.TARE_SCANS)
        self.tares = 0
        self.publications = 0
        self._last_pub = float("-inf")
        self._last_status = -1
        self._stop = threading.Event()
        self.on_update = on_update
        self.on_command = on_command
        self.offline = False

    def health(self, now: float | None = None) -> Health:
        src = self.source
        counters = getattr(src, "counters", None)
        return Health(
            frame_age_s=src.frame_age(now),
            bus_fault=bool(src.bus_fault),
            lost_scans=self.pipeline.counters.lost_scans,
            bus_errors=int(getattr(counters, "bus_errors", 0)),
        )

    def step(self, timeout_s: float | None = None) -> bool:
        """One poll (waiting up to ``timeout_s`` for traffic, default: until a
        publication falls due), its updates, the PLC's commands and, when due, a
        publication.  Returns whether it published."""
        scan = self.source.poll(self.wait_budget() if timeout_s is None else timeout_s)
        t_event = time.perf_counter()  # after the wait: the event is now
        urgent = False
        if scan is not None:
            self.recent_raw.append(scan.raw)
            hook = self.on_update
            for u in self.pipeline.push(scan):
                urgent |= self.image.observe(u)
                if hook is not None:
                    hook(u)
        commands = self.sink.take_commands()
        for cmd in commands:
            before = (self.image.enabled, self.image.latched)
            if cmd.name == "tare":
                self._tare()
            else:
                self.image.apply(cmd)
                # A client-mode PLC's ENABLE is read back every refresh: only a change counts.
                if (self.image.enabled, self.image.latched) == before:
                    continue
            if self.on_command is not None:
                self.on_command(cmd.name)
            urgent = True
        if commands:
            self.sink.commands_done()
        return self.publish_if_due(urgent, t_event)

    def publish_if_due(self, urgent: bool, t_event: float | None = None) -> bool:
        """Publish when urgent, when a status bit other than the life bit changed
        (stale, bus fault, ...), or when ``refresh_s`` has passed."""
        now = time.monotonic()
        health = self.health(now)
        status = self.image.status(health) & _QUIET
        if not urgent and status == self._last_status and now - self._last_pub < self.profile.modbus.plc.refresh_s:
            return False
        src_counters = getattr(self.source, "counters", None)
        if src_counters is not None and hasattr(src_counters, "as_dict"):
            self.pipeline.counters.extra.update(src_counters.as_dict())
        regs = self.image.render(health)
        self.sink.publish(regs, self.image, urgent or status != self._last_status, t_event)
        self._last_status = status
        self._last_pub = now
        self.publications += 1
        return True

    def wait_budget(self, now: float | None = None) -> float:
        """How long the loop may wait for traffic before a publication falls due:
        the next refresh, or the moment the newest frame turns stale."""
        now = time.monotonic() if now is None else now
        budget = min(self.MAX_WAIT_S, self._last_pub + self.profile.modbus.plc.refresh_s - now)
        age = self.source.frame_age(now)
        stale_s = self.image.stale_limit_s
        if age is not None and age <= stale_s:
            budget = min(budget, stale_s - age + 1e-4)
        return max(budget, 0.0)

    def shutdown(self) -> None:
        """Publish the last image, BRIDGE_OFFLINE with no state claimed, and stop the sink
        (a client-mode writer writes it before it lets go)."""
        if self.offline:
            return
        self.offline = True
        regs = self.image.render_offline(self.health())
        self.sink.publish(regs, self.image, True, time.perf_counter())
        self.publications += 1

    def _tare(self) -> None:
        """Move each taxel's zero to its mean over the recent scans (gripper open)."""
        if not self.recent_raw:
            return
        pipe = self.pipeline
        pipe.calibrator = pipe.calibrator.tared(np.stack(list(self.recent_raw)))
        self.tares += 1

    def run(self, duration_s: float | None = None) -> None:
        end = None if duration_s is None else time.monotonic() + duration_s
        while not self._stop.is_set() and (end is None or time.monotonic() < end):
            self.step()

    def stop(self) -> None:
        self._stop.set()

    def counters(self) -> dict[str, int]:
        c = self.pipeline.counters
        out = {"scans": c.scans, "updates": c.updates, "lost_scans": c.lost_scans,
               "state_changes": c.state_changes, "publications": self.publications, "tares": self.tares}
        src_counters = getattr(self.source, "counters", None)
        if src_counters is not None and hasattr(src_counters, "as_dict"):
            out.update(src_counters.as_dict())
        stats = getattr(self.sink, "stats_dict", None)
        if stats is not None:
            out.update(stats())
        return out


