"""The bridge process: every node's source -> its loop -> its sinks.

Threads, and why each exists:

- one reader per CAN bus (or replayed log): ``recv`` into a bounded queue, so a busy
  detector never makes the kernel drop frames, and a full queue drops and counts;
- one loop thread per transport: the nodes whose sources share one feeder (a CAN bus)
  are stepped by one thread, which waits once a round; any other node (an RTU line, a
  scene) has its own loop thread, paced by its source;
- whatever the sinks run themselves: a writer per node in PLC client mode (a slow or
  absent PLC never stalls detection), one Modbus server for all blocks in server mode;
- the caller's thread supervises: it logs what changed (sensor stale, bus fault, an
  output's connection) and the counters, and handles the stop.

:meth:`Bridge.stop` stops the loops, then leaves every output reading BRIDGE_OFFLINE
(written to the PLC before the writer lets go, or served for ``offline_linger_s``).
Nothing grows with time: queues are bounded, latencies kept in a ring.
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from ..bus.source import Feeder, OpenContext, Source
from ..detect.state import GraspState
from ..detect.updates import Update
from ..plc.image import Status
from ..sinks.base import Sink
from .config import BridgeConfig, ResolvedNode, output_classes
from .logs import EventLog
from .loop import NodeLoop

#: The interpreter hands the GIL between threads every 5 ms by default; a reader
#: thread waiting that long would add 5 ms to a 1 kHz scan's latency.  Every command
#: that runs a reader thread beside its loop uses this one value.
SWITCH_INTERVAL_S = 0.0002


@dataclass
class NodeRun:
    """One node inside the bridge: its loop and what was last logged."""

    node: ResolvedNode
    loop: NodeLoop
    last_state: tuple[int, bool] | None = None
    logged: dict[str, object] = field(default_factory=dict)

    @property
    def name(self) -> str:
        return self.node.name

    @property
    def sinks(self) -> list[Sink]:
        return self.loop.sinks


def open_nodes(config: BridgeConfig, nodes: list[ResolvedNode], closers: list[Callable[[], None]],
               default_output: bool = True, all_frames: bool = False, **loop_kw: Any) -> list[NodeLoop]:
    """Open every output and every source, and build one loop per node; what must be
    closed is appended to ``closers`` (also when a later one fails to open).  The one
    wiring path of every command."""
    context = OpenContext(queue_frames=config.queue_frames, all_frames=all_frames, closers=closers)
    per_node: list[list[Sink]] = [[] for _ in nodes]
    for cls, options in output_classes(config, default_output):
        for i, sink in enumerate(cls.open_nodes(options, nodes, context)):
            per_node[i].append(sink)
    sources: list[Source | None] = [None] * len(nodes)
    by_kind: dict[type[Source], list[int]] = {}
    for i, n in enumerate(nodes):
        by_kind.setdefault(n.kind, []).append(i)
    src: Source | None  # (opened below, then read back from sources)
    for kind, members in by_kind.items():
        for i, src in zip(members, kind.open_nodes([nodes[i] for i in members], context)):
            sources[i] = src
    loops = []
    for n, src, sinks in zip(nodes, sources, per_node):
        assert src is not None
        loops.append(NodeLoop(n.profile, src, sinks, rate_hz=n.rate_hz, **loop_kw))
    return loops


class SingleNode:
    """One node's loop on the caller's thread, for the commands that run one node in
    the foreground (``modbus-bridge``, ``receive``, ``monitor``, ``demo``): the same
    configuration, the same wiring and the same loop as the bridge."""

    def __init__(self, config: BridgeConfig, node: ResolvedNode, *, extra_sinks: Sequence[Sink] = (),
                 default_output: bool = True, all_frames: bool = False, **loop_kw: Any) -> None:
        self.closers: list[Callable[[], None]] = []
        try:
            (self.loop,) = open_nodes(config, [node], self.closers, default_output, all_frames, **loop_kw)
        except BaseException:
            self.close()
            raise
        for sink in extra_sinks:
            self.loop.add_sink(sink)
        self.source = self.loop.source

    def __enter__(self) -> "SingleNode":
        self._switch_interval = sys.getswitchinterval()
        sys.setswitchinterval(SWITCH_INTERVAL_S)  # the reader thread, not the loop, comes first
        self.source.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.loop.shutdown()
        for sink in self.loop.sinks:
            sink.flush()
        self.close()
        sys.setswitchinterval(self._switch_interval)

    def close(self) -> None:
        """Close everything opened; safe to call twice."""
        for close in reversed(self.closers):
            close()
        self.closers.clear()


class Bridge:
    def __init__(self, config: BridgeConfig, nodes: list[ResolvedNode], log: EventLog,
                 on_update: Callable[[str, Update], None] | None = None) -> None:
        self.config = config
        self.nodes = nodes
        self.log = log
        self.on_update = on_update
        self.runs: list[NodeRun] = []
        #: Nodes stepped together: (feeder, indices of their runs).
        self.groups: list[tuple[Feeder, list[int]]] = []
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
        """Open outputs and sources; an error here stops before any loop runs."""
        try:
            loops = open_nodes(self.config, self.nodes, self._closers)
        except BaseException:
            self._close_all()
            raise
        for node, loop in zip(self.nodes, loops):
            run = NodeRun(node, loop)
            loop.on_update = self._update_hook(run)
            loop.on_command = self._command_hook(run)
            for sink in loop.sinks:  # a sink's own events (a PLC outage's start and end)
                sink.on_events(self._sink_event_hook(run))
            self.runs.append(run)
        feeders: dict[int, tuple[Feeder, list[int]]] = {}
        for i, run in enumerate(self.runs):
            feeder = run.loop.source.feeder
            if feeder is not None:
                feeders.setdefault(id(feeder), (feeder, []))[1].append(i)
        self.groups = list(feeders.values())
        return self

    @property
    def server(self) -> Any:
        """The PLC server of server mode (shared by every node's block), or None."""
        for run in self.runs:
            for sink in run.sinks:
                server = getattr(sink, "server", None)
                if server is not None:
                    return server
        return None

    @property
    def where(self) -> str:
        sinks = self.runs[0].sinks if self.runs else []
        return "; ".join(s.where for s in sinks) or "-"

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

    def _sink_event_hook(self, run: NodeRun) -> Callable[[str, str, dict[str, Any]], None]:
        return lambda name, level, fields: self.log.event(name, level, node=run.name, **fields)

    # -- running --------------------------------------------------------------------
    def start(self) -> "Bridge":
        self._switch_interval = sys.getswitchinterval()
        sys.setswitchinterval(SWITCH_INTERVAL_S)
        self.log.event("start", nodes=",".join(r.name for r in self.runs), outputs=self.where,
                       sources=",".join(r.node.kind.describe(r.node) for r in self.runs))
        for run in self.runs:
            run.loop.source.start()  # a shared reader starts once, here: a replayed log does not run ahead
        for feeder, members in self.groups:
            runs = [self.runs[i] for i in members]
            self._spawn(f"feed-{'+'.join(r.name for r in runs)}", self._group_loop, feeder, runs)
        grouped = {i for _, members in self.groups for i in members}
        for i, run in enumerate(self.runs):
            if i not in grouped:
                self._spawn(f"node-{run.name}", self._node_loop, run)
        self.started = True
        return self

    def _spawn(self, name: str, target: Callable[..., None], *args: Any) -> None:
        t = threading.Thread(target=self._guard, args=(target, *args), name=name, daemon=True)
        self._threads.append(t)
        t.start()

    def _guard(self, target: Callable[..., None], *args: Any) -> None:
        """A loop that fails stops the bridge (and its outputs go offline) rather
        than leaving a stale image behind a live heartbeat."""
        try:
            target(*args)
        except Exception as exc:  # noqa: BLE001 - reported, then the whole bridge stops
            self.failure = f"{threading.current_thread().name}: {type(exc).__name__}: {exc}"
            self.log.event("loop_failed", level="error", loop=threading.current_thread().name,
                           error=f"{type(exc).__name__}: {exc}")
            self._stop.set()

    def _node_loop(self, run: NodeRun) -> None:
        step, stop = run.loop.step, self._stop
        source = run.loop.source
        while not stop.is_set():
            step()
            if source.done:
                self.log.event("source_ended", node=run.name, error=source.last_error or "-")
                self._sinks_source_ended([run])
                break

    def _group_loop(self, feeder: Feeder, runs: list[NodeRun]) -> None:
        stop = self._stop
        loops = [r.loop for r in runs]
        sources = [lp.source for lp in loops]

        def serve() -> None:  # route what came, step every node: one round, under the lock
            feeder.route(0.0)
            for lp, src in zip(loops, sources):
                lp.step(0.0)
                while src.pending:  # every scan routed in this round
                    lp.step(0.0)

        feeder.serve_arrivals(serve)  # an idle bus's frame is served by its reader at once
        while not stop.is_set():
            feeder.wait(min(lp.wait_budget() for lp in loops))  # the round's one wait
            with feeder.lock:
                serve()
            if feeder.serve_error is not None:
                raise feeder.serve_error
            if feeder.done:
                self.log.event("source_ended", node=",".join(r.name for r in runs),
                               error=sources[0].last_error or "-")
                self._sinks_source_ended(runs)
                break

    @staticmethod
    def _sinks_source_ended(runs: list[NodeRun]) -> None:
        """Each sink of a node whose source ended hears it (a Sparkplug device's DDEATH)."""
        for run in runs:
            for sink in run.sinks:
                sink.source_ended(run.loop.source.last_error or "")

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
        """Log what changed since the last look: stale, bus fault, each output's connection."""
        now = time.monotonic()
        for run in self.runs:
            lp = run.loop
            status = lp.image.status(lp.health(now))
            seen: dict[str, tuple[bool, Sink | None]] = {
                "stale": (bool(status & Status.SENSOR_STALE), None),
                "bus_fault": (bool(status & Status.BUS_FAULT), None),
            }
            sink: Sink | None  # (each output, then the one a change is about)
            for sink in run.sinks:
                health = sink.health()
                if health.connected is not None and not sink.logs_connection:
                    seen[f"{sink.kind}_connected"] = (health.connected, sink)
            for key, (value, sink) in seen.items():
                before = run.logged.get(key)
                if before == value:
                    continue
                if before is None:
                    # At start, no frame yet and no connection yet are normal: wait for
                    # the first frame, the first connection or the first refusal.
                    if (key == "stale" and value) or (sink is not None and not value and not sink.health().failures):
                        continue
                run.logged[key] = value
                # A healthy start is not news; an output refusing from the start is (the
                # first refusal reaches here only after a failed write).
                if before is not None or value or sink is not None:
                    self._log_change(run, key, value, sink)

    def _log_change(self, run: NodeRun, key: str, value: bool, sink: Sink | None) -> None:
        source = run.loop.source
        if key == "stale":
            age = source.frame_age()
            self.log.event("sensor_stale" if value else "sensor_fresh", level="warning" if value else "info",
                           node=run.name, frame_age_ms=None if age is None else round(age * 1000, 1))
        elif key == "bus_fault":
            self.log.event("bus_fault" if value else "bus_ok", level="warning" if value else "info",
                           node=run.name, error=source.last_error or "-")
        elif sink is not None:
            error = (sink.health().last_error or "-") if not value else "-"
            self.log.event(f"{sink.kind}_connected" if value else f"{sink.kind}_unreachable",
                           level="info" if value else "warning", node=run.name, error=error,
                           **{sink.kind: sink.where})

    def counters(self) -> dict[str, dict[str, int]]:
        return {run.name: run.loop.counters() for run in self.runs}

    def log_counters(self, event: str) -> None:
        for name, c in self.counters().items():
            self.log.event(event, "info", node=name, **c)  # level given: no counter can be taken for it
        if self.log.drops:
            self.log.event("log_drops", level="warning", dropped=self.log.drops)

    def stop(self) -> None:
        """Stop the loops, publish BRIDGE_OFFLINE to every output, close everything.
        Safe to call twice."""
        if self.stopped:
            return
        self.stopped = True
        self._stop.set()
        for t in self._threads:
            t.join(timeout=5.0)
        for run in self.runs:
            run.loop.shutdown()
        offline = []
        for run in self.runs:
            # every sink flushed (a writer wrote the offline image, a server served it)
            if all([sink.flush() for sink in run.sinks]):
                offline.append(run.name)
        self._close_all()
        if self._switch_interval is not None:  # the process's setting, as it was
            sys.setswitchinterval(self._switch_interval)
        self.log.event("stopped", reason=self.stop_reason or ("failure" if self.failure else "end"),
                       offline_written=",".join(offline) or "-")

    def _close_all(self) -> None:
        for close in reversed(self._closers):
            try:
                close()
            except Exception as exc:  # noqa: BLE001 - closing must go on for the others
                self.log.event("close_failed", level="warning", error=f"{type(exc).__name__}: {exc}")
        self._closers.clear()
