"""The bridge process: every node's source -> detector -> its PLC register block.

Threads, and why each exists:

- one reader per CAN bus (or replayed log): ``recv`` into a bounded queue, so a busy
  detector never makes the kernel drop frames, and a full queue drops and counts;
- one loop per CAN bus, serving every node on it (route frames, assemble, detect,
  publish), or one loop per RTU node / scene replay (its source keeps the pace);
- one writer per node in client mode (a slow or absent PLC never stalls detection),
  or one Modbus server for all blocks in server mode;
- the caller's thread supervises: it logs what changed (sensor stale, bus fault, PLC
  connection) and the counters, and handles the stop.

:meth:`Bridge.stop` stops the loops, then leaves every block reading BRIDGE_OFFLINE
(written to the PLC before the writer lets go, or served for ``offline_linger_s``).
Nothing grows with time: queues are bounded, latencies kept in a ring.
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..detect.state import GraspState
from ..detect.updates import Update
from ..errors import EskinError
from ..plc.image import Status
from .config import BridgeConfig, ResolvedNode, plc_mode
from .logs import EventLog
from .loop import ModbusBridge

#: The interpreter hands the GIL between threads every 5 ms by default; a reader
#: thread waiting that long would add 5 ms to a 1 kHz scan's latency.
SWITCH_INTERVAL_S = 0.0005


@dataclass
class NodeRun:
    """One node inside the bridge: its loop (``bridge``) and what was last logged."""

    node: ResolvedNode
    bridge: ModbusBridge
    sink: object
    last_state: tuple[int, bool] | None = None
    logged: dict[str, object] = field(default_factory=dict)

    @property
    def name(self) -> str:
        return self.node.name


class Bridge:
    def __init__(self, config: BridgeConfig, nodes: list[ResolvedNode], log: EventLog,
                 on_update: Callable[[str, Update], None] | None = None) -> None:
        self.config = config
        self.nodes = nodes
        self.log = log
        self.on_update = on_update
        self.mode = plc_mode(config, nodes)
        self.runs: list[NodeRun] = []
        self.groups: list = []
        self.server = None
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._closers: list[Callable[[], None]] = []
        self.started = False
        self.stopped = False
        self._switch_interval: float | None = None
        self.failure = ""
        self.stop_reason = ""  #: the signal's name, when one stopped the bridge

    # -- building: everything is opened before anything runs ----------------------
    def open(self) -> "Bridge":
        """Open sources and the PLC side; an error here stops before any loop runs."""
        try:
            sinks = self._open_sinks()
            sources = self._open_sources()
        except BaseException:
            self._close_all()
            raise
        for node, sink, source in zip(self.nodes, sinks, sources):
            run = NodeRun(node, None, sink)  # type: ignore[arg-type]
            run.bridge = ModbusBridge(node.profile, source, sink, rate_hz=node.rate_hz,
                                      on_update=self._update_hook(run), on_command=self._command_hook(run))
            self.runs.append(run)
        return self

    def _open_sinks(self) -> list:
        from ..bus.modbus.io import SerialSettings
        from ..plc.client import PlcWriter
        from ..plc.server import PlcServer

        out = self.config.plc
        first = self.nodes[0].profile.modbus.plc
        serial = SerialSettings(out.serial_port, out.baudrate) if out.transport == "rtu" else None
        if self.mode == "server":
            tcp = None if serial else (out.host or first.bind, out.port or first.port)
            self.server = PlcServer(first, tcp=tcp, serial=serial,
                                    blocks=[n.profile.modbus.plc for n in self.nodes]).start()
            self._closers.append(self.server.stop)
            return [self.server.block(i) for i in range(len(self.nodes))]
        sinks = []
        for n in self.nodes:
            w = PlcWriter(n.profile.modbus.plc, out.host, out.port, serial=serial).start()
            self._closers.append(w.stop)
            sinks.append(w)
        return sinks

    def _open_sources(self) -> list:
        from ..bus.can.group import CanGroup

        by_key: dict[tuple, list[int]] = {}
        sources: list = [None] * len(self.nodes)
        for i, n in enumerate(self.nodes):
            kind = n.config.source
            if kind in ("can", "can-log"):
                by_key.setdefault(n.bus_key, []).append(i)
            elif kind == "modbus-rtu":
                sources[i] = self._rtu_source(n)
            else:
                sources[i] = self._scene_source(n)
        for key, members in by_key.items():
            reader = self._can_reader(self.nodes[members[0]])
            group = CanGroup(reader, [self.nodes[i] for i in members])
            self.groups.append((group, members))
            for i, poller in zip(members, group.pollers):
                sources[i] = poller
        return sources

    def _can_reader(self, n: ResolvedNode):
        c = n.config
        if c.source == "can-log":
            from ..bus.can.log import LogPlayer, read_can_log

            reader = LogPlayer(c.path, read_can_log(c.path), self.config.queue_frames)  # type: ignore[arg-type]
        else:
            from ..bus.can.reader import BusReader, bus_kwargs, open_bus

            kw = bus_kwargs(n.profile, c.interface, c.channel, c.bitrate_bps, c.fd, c.data_bitrate_bps)
            reader = BusReader(lambda: open_bus(**kw), self.config.queue_frames)
        self._closers.append(reader.stop)
        return reader

    def _rtu_source(self, n: ResolvedNode):
        from ..bus.modbus.rtu import RtuPoller

        poller = RtuPoller(n.profile, n.config.serial_port, baudrate=n.config.baudrate)  # type: ignore[arg-type]
        poller.open()
        self._closers.append(poller.close)
        return poller

    def _scene_source(self, n: ResolvedNode):
        from ..bus.replay import ReplaySource
        from ..calibration import Calibrator
        from ..scenes import render

        rec = render(n.config.scene, n.rate_hz, n.config.seed)  # type: ignore[arg-type]
        if rec.forces.shape[1] != n.profile.taxels:
            raise EskinError(f"node {n.name!r}: scene {n.config.scene} has {rec.forces.shape[1]} taxels, "
                             f"profile {n.profile.name} has {n.profile.taxels}")
        raw = np.rint(Calibrator.from_section(n.profile.calibration, n.profile.taxels).to_raw(rec.forces))
        return ReplaySource(n.profile, rec.t, raw, n.rate_hz, loop=n.config.loop)

    # -- hooks called from the loops: cheap, never blocking ------------------------
    def _update_hook(self, run: NodeRun) -> Callable[[Update], None]:
        outer = self.on_update
        log = self.log

        def hook(u: Update) -> None:
            key = (u.state, u.valid)
            if key != run.last_state:
                run.last_state = key
                log.event("state", node=run.name, state=GraspState(u.state).label, valid=int(u.valid),
                          t=round(u.t, 4), f_sum=round(u.f_sum, 3), r_coe=round(u.r_coe, 3), r_dw=round(u.r_dw, 3))
            if outer is not None:
                outer(run.name, u)

        return hook

    def _command_hook(self, run: NodeRun) -> Callable[[str], None]:
        return lambda name: self.log.event("plc_command", node=run.name, command=name)

    # -- running --------------------------------------------------------------------
    def start(self) -> "Bridge":
        self._switch_interval = sys.getswitchinterval()
        sys.setswitchinterval(SWITCH_INTERVAL_S)
        self.log.event("start", nodes=",".join(r.name for r in self.runs), plc=self.where, mode=self.mode,
                       sources=",".join(_describe_source(r.node) for r in self.runs))
        for group, members in self.groups:
            runs = [self.runs[i] for i in members]
            # The reader (BusReader or LogPlayer) is only built by open(): without this
            # no frame ever reached a CAN node's loop.  Started here, not in open(), so
            # that a replayed log does not run ahead of its loop.
            group.reader.start()
            self._spawn(f"can-{'+'.join(r.name for r in runs)}", self._group_loop, group, runs)
        grouped = {i for _, members in self.groups for i in members}
        for i, run in enumerate(self.runs):
            if i not in grouped:
                self._spawn(f"node-{run.name}", self._node_loop, run)
        self.started = True
        return self

    @property
    def where(self) -> str:
        if self.server is not None:
            return self.server.where
        return self.runs[0].sink.where if self.runs else "-"  # type: ignore[attr-defined]

    def _spawn(self, name: str, target, *args) -> None:
        t = threading.Thread(target=self._guard, args=(target, *args), name=name, daemon=True)
        self._threads.append(t)
        t.start()

    def _guard(self, target, *args) -> None:
        """A loop that fails stops the bridge (and its PLC blocks go offline) rather
        than leaving a stale image behind a live heartbeat."""
        try:
            target(*args)
        except Exception as exc:  # noqa: BLE001 - reported, then the whole bridge stops
            self.failure = f"{threading.current_thread().name}: {type(exc).__name__}: {exc}"
            self.log.event("loop_failed", level="error", loop=threading.current_thread().name,
                           error=f"{type(exc).__name__}: {exc}")
            self._stop.set()

    def _node_loop(self, run: NodeRun) -> None:
        step, stop = run.bridge.step, self._stop
        source = run.bridge.source
        while not stop.is_set():
            step()
            if getattr(source, "done", False):
                self.log.event("source_ended", node=run.name)
                break

    def _group_loop(self, group, runs: list[NodeRun]) -> None:
        stop = self._stop
        bridges = [r.bridge for r in runs]
        pollers = group.pollers
        while not stop.is_set():
            group.route(min(b.wait_budget() for b in bridges))  # the round's one wait
            for b, p in zip(bridges, pollers):
                b.step(0.0)
                while p.pending:  # every scan routed in this round
                    b.step(0.0)
            if group.done:
                self.log.event("source_ended", node=",".join(r.name for r in runs),
                               error=getattr(group.reader, "last_error", "") or "-")
                break

    def wait(self, duration_s: float | None = None, tick_s: float = 0.1) -> None:
        """Supervise until :meth:`request_stop`, ``duration_s``, or every source ended."""
        end = None if duration_s is None else time.monotonic() + duration_s
        status_every = self.config.log.status_every_s
        next_status = time.monotonic() + status_every if status_every else None
        while not self._stop.is_set():
            if end is not None and time.monotonic() >= end:
                break
            if self._threads and not any(t.is_alive() for t in self._threads):
                break
            self._stop.wait(tick_s)
            self.check_health()
            if next_status is not None and time.monotonic() >= next_status:
                next_status += status_every
                self.log_counters("counters")

    def request_stop(self, reason: str = "") -> None:
        """Safe from a signal handler: only sets a flag."""
        if reason and not self._stop.is_set():
            self.stop_reason = reason
        self._stop.set()

    def check_health(self) -> None:
        """Log what changed since the last look: stale, bus fault, PLC connection."""
        now = time.monotonic()
        for run in self.runs:
            b = run.bridge
            health = b.health(now)
            status = b.image.status(health)
            seen = {
                "stale": bool(status & Status.SENSOR_STALE),
                "bus_fault": bool(status & Status.BUS_FAULT),
            }
            connected = getattr(run.sink, "connected", None)
            if connected is not None:
                seen["plc_connected"] = bool(connected)
            for key, value in seen.items():
                before = run.logged.get(key)
                if before == value:
                    continue
                if before is None:
                    # At start, no frame yet and no PLC connection yet are normal: wait
                    # for the first frame, the first connection or the first refusal.
                    stats = getattr(run.sink, "stats", None)
                    if (key == "stale" and value) or (key == "plc_connected" and not value and not (
                            stats is not None and stats.failures)):
                        continue
                run.logged[key] = value
                # A healthy start is not news; a PLC refusing from the start is (the
                # first refusal reaches here only after a failed write).
                if before is not None or value or key == "plc_connected":
                    self._log_change(run, key, value)

    def _log_change(self, run: NodeRun, key: str, value: bool) -> None:
        b = run.bridge
        if key == "stale":
            age = b.source.frame_age()
            self.log.event("sensor_stale" if value else "sensor_fresh", level="warning" if value else "info",
                           node=run.name, frame_age_ms=None if age is None else round(age * 1000, 1))
        elif key == "bus_fault":
            err = getattr(getattr(b.source, "reader", None), "last_error", "") or "-"
            self.log.event("bus_fault" if value else "bus_ok", level="warning" if value else "info",
                           node=run.name, error=err)
        else:
            stats = getattr(run.sink, "stats", None)
            self.log.event("plc_connected" if value else "plc_unreachable", level="info" if value else "warning",
                           node=run.name, plc=run.sink.where,  # type: ignore[attr-defined]
                           error=(getattr(stats, "last_error", "") or "-") if not value else "-")

    def counters(self) -> dict[str, dict[str, int]]:
        out = [dict(run.bridge.counters()) for run in self.runs]
        for group, members in self.groups:  # frames of no node on a shared bus
            for i in members:
                out[i]["unrouted_frames"] = group.unrouted_frames
        return {run.name: c for run, c in zip(self.runs, out)}

    def log_counters(self, event: str) -> None:
        for name, c in self.counters().items():
            self.log.event(event, node=name, **c)
        if self.log.drops:
            self.log.event("log_drops", level="warning", dropped=self.log.drops)

    def stop(self) -> None:
        """Stop the loops, publish BRIDGE_OFFLINE in every block, close everything.
        Safe to call twice."""
        if self.stopped:
            return
        self.stopped = True
        self._stop.set()
        for t in self._threads:
            t.join(timeout=5.0)
        for run in self.runs:
            run.bridge.shutdown()
        if self.server is not None and self.runs:
            time.sleep(self.config.plc.offline_linger_s)  # let a polling PLC read "offline"
        self._close_all()
        if self._switch_interval is not None:  # the process's setting, as it was
            sys.setswitchinterval(self._switch_interval)
        offline = [r.name for r in self.runs if getattr(r.sink, "flushed", True)]
        self.log.event("stopped", reason=self.stop_reason or ("failure" if self.failure else "end"),
                       offline_written=",".join(offline) or "-")

    def _close_all(self) -> None:
        for close in reversed(self._closers):
            try:
                close()
            except Exception as exc:  # noqa: BLE001 - closing must go on for the others
                self.log.event("close_failed", level="warning", error=f"{type(exc).__name__}: {exc}")
        self._closers.clear()


def _describe_source(n: ResolvedNode) -> str:
    c = n.config
    if c.source == "can":
        return f"can:{c.interface or 'configured'}:{c.channel or '-'}@{n.profile.can.base_id:#x}"
    return {"can-log": f"log:{c.path}", "modbus-rtu": f"rtu:{c.serial_port}", "scene": f"scene:{c.scene}"}[c.source]
