"""The per-node loop: source -> pipeline -> node snapshot -> sinks.

One loop per sensor node, the same in every command (``bridge``, ``modbus-bridge``,
``receive``, ``monitor``, ``demo``).  :meth:`NodeLoop.step` polls the source once,
runs each scan through the pipeline (calibration, detector), hands every update to
every sink (as the snapshot shows it: no verdict under a sensor fault), applies the
commands the sinks took (acknowledge, tare, enable), and publishes the node's
snapshot (:class:`~eskin_industrial.node.NodeSnapshot`) when due: a state change at
once, a change of a health condition (stale, bus fault) as soon as it happens,
otherwise every ``[output] refresh_s``.  A sink that asks for
taxel frames (``Sink.frame_every_s``) gets the newest calibrated frame once its
interval has passed: the loop decides which frames are due, after the publication.
:meth:`NodeLoop.shutdown` publishes the last snapshot, offline, with no state
claimed.  Nothing here knows which kind of source or sink it drives, nor any
output's wire format.
"""

from __future__ import annotations

import collections
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from ..bus.source import Source
from ..detect.updates import Update
from ..node import Health, NodeSnapshot, NodeStatus, refusal
from ..node.staleness import Staleness
from ..outputs.base import Sink
from ..pipeline import Pipeline
from ..profile import Profile


class NodeLoop:
    #: Unloaded scans kept for a tare.
    TARE_SCANS = 50

    #: Longest wait for traffic before the loop looks at the time again.
    MAX_WAIT_S = 0.05

    def __init__(self, profile: Profile, source: Source, sinks: Sequence[Sink], *, rate_hz: float | None = None,
                 method: str | None = None, on_update: Callable[[Update], None] | None = None,
                 on_command: Callable[[str], None] | None = None) -> None:
        self.profile = profile
        self.source = source
        self.pipeline = Pipeline(profile, rate_hz=rate_hz, method=method)
        chosen = self.pipeline.method
        self.status = NodeStatus(profile.stale_s, chosen.name, chosen.code,
                                 (chosen.scores[0].name, chosen.scores[1].name))
        #: The stale limit, learnt from the sensor's arrivals (``status.stale_s`` follows it).
        self.staleness = Staleness(profile.stale_s, profile.stale_max_s)
        #: The newest snapshot published (None before the first).
        self.snapshot: NodeSnapshot | None = None
        self.recent_raw: collections.deque[np.ndarray] = collections.deque(maxlen=self.TARE_SCANS)
        self.tares = 0
        self.tares_refused = 0
        self.commands = 0  #: commands applied (a client-mode ENABLE read back unchanged is none)
        self.publications = 0
        self._last_pub = float("-inf")
        self._last_conditions = -1
        self._last_bus_fault = False
        self._last_stale = False
        self._lost_shown = 0
        self._refresh_s = profile.output.refresh_s
        #: a stop asked (:meth:`stop`): a plain attribute, which another thread and a
        #: signal handler on this one may set alike (an Event's set() takes a lock that
        #: the code a handler interrupted may hold)
        self._stopping = False
        self.on_update = on_update
        self.on_command = on_command
        self.offline = False
        # Only the sinks that override them are called per update and for commands:
        # the per-scan path stays a few attribute reads.
        self._update_sinks: list[Callable[[Update], None]] = []
        self._command_sinks: list[Sink] = []
        #: [on_frame, interval (s), next due (perf_counter)] of each sink that wants frames.
        self._frame_sinks: list[list[Any]] = []
        self.sinks: list[Sink] = []
        for sink in sinks:
            self.add_sink(sink)

    def add_sink(self, sink: Sink) -> None:
        self.sinks.append(sink)
        if sink.overrides("on_update"):
            self._update_sinks.append(sink.on_update)
        if sink.overrides("take_commands"):
            self._command_sinks.append(sink)
        if sink.frame_every_s is not None:
            self._frame_sinks.append([sink.on_frame, sink.frame_every_s, float("-inf")])

    def health(self, now: float | None = None) -> Health:
        src = self.source
        return Health(frame_age_s=src.frame_age(now), bus_fault=src.bus_fault,
                      lost_scans=self.lost_scans(), bus_errors=src.bus_errors(), fault=self.pipeline.fault)

    def lost_scans(self) -> int:
        """Gaps the pipeline counted, plus the scans an outage under way has lost so far
        (LOST_SCANS grows while it lasts); never less than shown before, so a PLC that
        takes differences never sees it go back when the outage's estimate is confirmed."""
        lost = self.pipeline.counters.lost_scans + self.source.lost_pending()
        if lost < self._lost_shown:
            return self._lost_shown
        self._lost_shown = lost
        return lost

    def step(self, timeout_s: float | None = None) -> bool:
        """One poll (waiting up to ``timeout_s`` for traffic, default: until a
        publication falls due), its updates, the commands and, when due, a
        publication.  Returns whether it published."""
        scan = self.source.poll(self.wait_budget() if timeout_s is None else timeout_s)
        t_event = time.perf_counter()  # after the wait: the event is now
        urgent = False
        updates: list[Update] = []
        if scan is not None:
            self.recent_raw.append(scan.raw)
            # the transport's receipt when it stamps one (a reader thread), else now
            rx = scan.rx_time if scan.rx_time == scan.rx_time else time.monotonic()
            self.status.stale_s = self.staleness.observe(rx)
            observe = self.status.observe
            updates = self.pipeline.push(scan)
            for u in updates:
                urgent |= observe(u)
        if self._command_sinks and self._apply_commands():
            urgent = True
        if (scan is None and not urgent and not self._last_bus_fault and not self.source.bus_fault
                and self._due_in(time.monotonic()) > 0):
            return False  # no scan, no command, nothing due: a frame of a scan under way costs little
        published = self.publish_if_due(urgent, t_event)
        # The PLC first, then whatever else wants each update (a recorder, the logs): a
        # sink as the snapshot shows it (no verdict under a sensor fault), the hook
        # the detector's own (what a caller measures the detector by).
        hook = self.on_update
        if updates:
            shown = self.pipeline.shown(updates) if self._update_sinks else updates
            for u, s in zip(updates, shown):
                for on_update in self._update_sinks:
                    on_update(s)
                if hook is not None:
                    hook(u)
        if self._frame_sinks and scan is not None:
            self._hand_frame(t_event)
        return published

    def _hand_frame(self, now: float) -> None:
        """The newest frame to each sink whose interval has passed (the next one due a
        whole interval later: never two closer than that); decided before the sink
        copies anything."""
        frame = self.pipeline.last_frame
        if frame is None:
            return
        for due in self._frame_sinks:
            if now >= due[2]:
                due[2] = now + due[1]
                due[0](frame)

    def _apply_commands(self) -> bool:
        acted = False
        status = self.status
        for sink in self._command_sinks:
            commands = sink.take_commands()
            for cmd in commands:
                before = (status.enabled, status.latched)
                if cmd.name == "tare":
                    if refusal(cmd, self._now_snapshot()) is not None:
                        # Refused when applied too (an output refuses when it takes the
                        # command; a client-mode PLC's COMMAND or a contact since then lands here).
                        self.tares_refused += 1
                        if self.on_command is not None:
                            self.on_command("tare_refused")
                        continue
                    self._tare()
                else:
                    status.apply(cmd)
                    # A client-mode PLC's ENABLE is read back every refresh: only a change counts.
                    if (status.enabled, status.latched) == before:
                        continue
                self.commands += 1
                if self.on_command is not None:
                    self.on_command(cmd.name)
                acted = True
            if commands:
                sink.commands_done()
        return acted

    def publish_if_due(self, urgent: bool, t_event: float | None = None) -> bool:
        """Publish when urgent, when a condition the outputs show changed (stale, bus
        fault, enable, latch, validity), or when ``refresh_s`` has passed."""
        now = time.monotonic()
        src = self.source
        if not urgent and src.pending:
            return False  # scans wait: the loop, not the sensor, is late; take them first
        age, bus_fault = src.frame_age(now), src.bus_fault
        fault = self.pipeline.fault
        conditions = self.status.conditions(age, bus_fault, fault)
        if not urgent and conditions == self._last_conditions and now - self._last_pub < self._refresh_s:
            return False
        t0 = time.perf_counter()
        if t_event is None:
            t_event = t0
        snap = self.status.snapshot(Health(age, bus_fault, self.lost_scans(), src.bus_errors(), fault),
                                    scans=self.pipeline.counters.scans, t_event=t_event,
                                    # the wall clock of the deciding scan's arrival, not of now
                                    wall_time_s=time.time() - (t0 - t_event),
                                    urgent=urgent or conditions != self._last_conditions)
        self.snapshot = snap
        for sink in self.sinks:
            sink.publish(snap)
        self._last_conditions = conditions
        self._last_bus_fault = bus_fault
        self._last_stale = snap.stale
        self._last_pub = now
        self.publications += 1
        return True

    def _now_snapshot(self) -> NodeSnapshot:
        """A snapshot of this moment, not published (a command judged as it is applied)."""
        t = time.perf_counter()
        return self.status.snapshot(self.health(), scans=self.pipeline.counters.scans, t_event=t,
                                    wall_time_s=time.time(), urgent=False)

    def _due_in(self, now: float) -> float:
        """Seconds until a publication falls due with no new scan or command: the next
        refresh, or the moment the newest frame turns stale."""
        due = self._last_pub + self._refresh_s - now
        age = self.source.frame_age(now)
        if age is not None and not self._last_stale:  # published fresh: due when it turns stale
            due = min(due, self.status.stale_s - age + 1e-4)
        return due

    def wait_budget(self, now: float | None = None) -> float:
        """How long the loop may wait for traffic before a publication falls due."""
        return max(min(self.MAX_WAIT_S, self._due_in(time.monotonic() if now is None else now)), 0.0)

    def offline_snapshot(self) -> NodeSnapshot:
        """This node offline, now: nothing claimed (its counts and centre of force kept)."""
        return self.status.offline_snapshot(self.health(), scans=self.pipeline.counters.scans,
                                            t_event=time.perf_counter(), wall_time_s=time.time())

    def shutdown(self) -> None:
        """Publish the last snapshot, offline with no state claimed (a client-mode PLC
        writer writes it before it lets go).  Safe to call twice."""
        if self.offline:
            return
        self.offline = True
        snap = self.offline_snapshot()
        self.snapshot = snap
        failed: Exception | None = None
        for sink in self.sinks:
            try:
                sink.publish(snap)
            except Exception as exc:  # noqa: BLE001 - the other sinks still get the offline image
                failed = failed or exc
        self.publications += 1
        if failed is not None:
            raise failed

    def _tare(self) -> None:
        """Move each taxel's zero to its mean over the recent scans (gripper open)."""
        if not self.recent_raw:
            return
        pipe = self.pipeline
        pipe.calibrator = pipe.calibrator.tared(np.stack(list(self.recent_raw)))
        self.tares += 1

    def run(self, duration_s: float | None = None, idle_timeout_s: float | None = None,
            max_scans: int | None = None) -> str:
        """Step until :meth:`stop`, ``duration_s``, no scan for ``idle_timeout_s``
        (``"idle"``; ``"silent"`` when not one came since the start: a channel nobody
        sends on ends the run too), ``max_scans`` scans, or a finite source's end;
        returns which."""
        start = time.monotonic()
        end = None if duration_s is None else start + duration_s
        source, counters = self.source, self.pipeline.counters
        while not self._stopping:
            self.step()
            if end is not None and time.monotonic() >= end:
                return "duration"
            if idle_timeout_s is not None:
                age = source.frame_age()
                if age is None and time.monotonic() - start >= idle_timeout_s:
                    return "silent"
                if age is not None and age >= idle_timeout_s:
                    return "idle"
            if max_scans is not None and counters.scans >= max_scans:
                return "scans"
            if source.done:
                return "done"
        return "stopped"

    def stop(self) -> None:
        """Stop :meth:`run` at the end of its step (from any thread, or a signal handler)."""
        self._stopping = True

    def counters(self) -> dict[str, int]:
        c = self.pipeline.counters
        out = {"scans": c.scans, "updates": c.updates, "lost_scans": self.lost_scans(),
               "state_changes": c.state_changes, "publications": self.publications, "tares": self.tares,
               "tares_refused": self.tares_refused, "commands": self.commands, "invalid_scans": c.invalid_scans,
               "saturated_scans": c.saturated_scans, "fault_scans": c.fault_scans, "sensor_faults": c.sensor_faults}
        out.update(self.pipeline.time_faults())
        out.update(self.source.counters())
        for sink in self.sinks:
            out.update(sink.counters())
        return out
