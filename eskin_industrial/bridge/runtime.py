"""The bridge process: every node's source -> its loop -> its sinks.

Threads, and why each exists:

- one reader per CAN bus (or replayed log): ``recv`` into a bounded queue, so a busy
  detector never makes the kernel drop frames, and a full queue drops and counts;
- one loop thread per transport: the nodes whose sources share one feeder (a CAN bus)
  are stepped by one thread, which waits once a round; any other node (an RTU line, a
  scene) has its own loop thread, paced by its source;
- whatever the sinks run themselves: a writer per node in PLC client mode (a slow or
  absent PLC never stalls detection), one Modbus server for all blocks in server mode;
- per output, its supervisor (``supervise-KIND``: a failure restarts that output, not
  the bridge) and, unless the output is essential, the thread that hands it the
  loops' data (``KIND-output``: a hang there never stalls a loop), :mod:`.supervise`;
- the caller's thread supervises: it logs what changed (sensor stale, bus fault, an
  output's connection) and the counters, feeds systemd's watchdog while every loop
  thread turns (bridge/notify.py), and handles the stop.

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

from ..bus.source import Feeder, Source
from ..detect.state import GraspState
from ..detect.updates import Update
from ..errors import ListenError
from ..frames import FrameFlag
from ..outputs.base import Sink
from ..ratelimit import Throttle
from ..seam import OpenContext
from .config import BridgeConfig, ResolvedNode, device_identity, output_classes
from .logs import EventLog
from .loop import NodeLoop
from .notify import Notifier
from .signals import SignalFlags
from .stall import StallGuard
from .supervise import Output, Policy, Supervision

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


def policy_of(config: BridgeConfig, kind: str) -> Policy:
    """How the output ``kind`` is supervised, from ``[supervision]``."""
    sup = config.supervision
    return Policy(essential=kind in sup.essential, on_failure=sup.policy_value(kind, "on_failure"),
                  backoff_s=sup.policy_value(kind, "backoff_s"), backoff_max_s=sup.policy_value(kind, "backoff_max_s"),
                  hang_s=sup.policy_value(kind, "hang_s"))


def open_nodes(config: BridgeConfig, nodes: list[ResolvedNode], closers: list[Callable[[], None]],
               default_output: bool = True, all_frames: bool = False, supervision: Supervision | None = None,
               **loop_kw: Any) -> list[NodeLoop]:
    """Open every output and every source, and build one loop per node; what must be
    closed is appended to ``closers`` (also when a later one fails to open).  The one
    wiring path of every command.  With ``supervision``, each output is opened
    supervised (:mod:`.supervise`): the loops hold its supervised sinks."""
    context = OpenContext(queue_frames=config.queue_frames, all_frames=all_frames, closers=closers,
                          identity=device_identity(config, nodes))
    per_node: list[list[Sink]] = [[] for _ in nodes]
    for cls, options in output_classes(config, default_output):
        try:
            opened: list[Sink]
            if supervision is None:
                opened = cls.open_nodes(options, nodes, context)
            else:
                output = Output(cls, options, nodes, context, policy_of(config, cls.name), supervision.log,
                                supervision.stop)
                opened = list(supervision.add(output))
                closers.append(output.close)
        except ListenError as exc:  # a port in use: the line --check gives (probe_outputs)
            raise ListenError(f"{config.source}: [{cls.name}] port: {exc}") from None
        for i, sink in enumerate(opened):
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
    configuration, the same wiring and the same loop as the bridge.  Inside ``with``,
    a helper thread that ends by an exception (the CAN reader, an output's) stops the
    loop and leaves :attr:`failure` set, as the bridge's thread watch does: no command
    goes on deciding with a source or an output gone."""

    #: why the run was stopped: a thread that died ("" while none did)
    failure = ""

    def __init__(self, config: BridgeConfig, node: ResolvedNode, *, extra_sinks: Sequence[Sink] = (),
                 default_output: bool = True, all_frames: bool = False,
                 on_event: Callable[[str, str, dict[str, Any]], None] | None = None, **loop_kw: Any) -> None:
        self.closers: list[Callable[[], None]] = []
        self.offline_written = False  #: every sink took the offline image (set on exit)
        #: the outputs' failures and restarts (``output_failed``): to ``on_event``, else a line on stderr
        self.on_event = on_event or _stderr_event
        self.supervision = Supervision(lambda name, level, **fields: self.on_event(name, level, fields),
                                       self._output_stops)
        try:
            (self.loop,) = open_nodes(config, [node], self.closers, default_output, all_frames, self.supervision,
                                      **loop_kw)
        except BaseException:
            self.close()
            raise
        for sink in extra_sinks:
            self.loop.add_sink(sink)
        self.source = self.loop.source

    def __enter__(self) -> SingleNode:
        self._switch_interval = sys.getswitchinterval()
        sys.setswitchinterval(SWITCH_INTERVAL_S)  # the reader thread, not the loop, comes first
        self._excepthook = threading.excepthook
        threading.excepthook = self._thread_died
        try:
            self.source.start()
        except BaseException:  # (no __exit__ follows a failed __enter__: put back what it changed)
            threading.excepthook = self._excepthook
            sys.setswitchinterval(self._switch_interval)
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        try:
            self.loop.shutdown()
        finally:  # a sink that failed its offline image: the others are flushed and closed all the same
            self.offline_written = all([sink.flush() for sink in self.loop.sinks])
            self.close()
            sys.setswitchinterval(self._switch_interval)
            threading.excepthook = self._excepthook

    def _thread_died(self, args: threading.ExceptHookArgs) -> None:
        if args.exc_type is SystemExit:
            return
        name = args.thread.name if args.thread is not None else "-"
        error = f"{args.exc_type.__name__}: {args.exc_value}"
        if self.supervision.thread_died(args.thread, error):
            return  # an output's: it restarts, the loop goes on
        if not self.failure:
            self.failure = f"thread {name} died: {error}"
        self.loop.stop()

    def _output_stops(self, reason: str) -> None:
        """An output failed, and its ``on_failure`` is ``stop``."""
        if not self.failure:
            self.failure = reason
        self.loop.stop()

    def close(self) -> None:
        """Close everything opened; safe to call twice."""
        for close in reversed(self.closers):
            close()
        self.closers.clear()


def _stderr_event(name: str, level: str, fields: dict[str, Any]) -> None:
    """An output's failure or restart in a command that has no log of its own: one line."""
    sys.stderr.write(f"eskin-bus: {level}: {name} " + " ".join(f"{k}={v}" for k, v in fields.items()) + "\n")


class Bridge:
    def __init__(self, config: BridgeConfig, nodes: list[ResolvedNode], log: EventLog,
                 on_update: Callable[[str, Update], None] | None = None, notifier: Notifier | None = None) -> None:
        self.config = config
        self.nodes = nodes
        self.log = log
        self.on_update = on_update
        self._commands_logged = Throttle()
        #: systemd's READY/STOPPING/STATUS and its watchdog (does nothing outside systemd).
        self.notifier = notifier or Notifier(None)
        self.runs: list[NodeRun] = []
        #: Nodes stepped together: (feeder, indices of their runs).
        self.groups: list[tuple[Feeder, list[int]]] = []
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        #: +1 at every turn of each loop thread (by thread): what feeds systemd's watchdog.
        self._beats: list[int] = []
        self._starved = False
        self._closers: list[Callable[[], None]] = []
        self.started = False
        self.stopped = False
        self._switch_interval: float | None = None
        self.failure = ""
        self._excepthook: Callable[[threading.ExceptHookArgs], Any] | None = None
        self.stop_reason = ""  #: the signal's name, when one stopped the bridge
        self.failed_sources: list[str] = []  #: "node: error" of each source that failed
        #: Every output, watched: a failure is logged and restarts it (``[supervision]``).
        self.supervision = Supervision(lambda name, level, **fields: self.log.event(name, level, **fields),
                                       self._output_stops)
        #: A loop that stops turning leaves no verdict standing (:mod:`.stall`).
        self._stall = StallGuard(config.supervision.loop_stall_s,
                                 lambda name, level, **fields: self.log.event(name, level, **fields))

    # -- building: everything is opened before anything runs ----------------------
    def open(self) -> Bridge:
        """Open outputs and sources; an error here stops before any loop runs."""
        # An output's own thread (paho's, a writer's) that dies of an exception would
        # otherwise stop that output in silence: it stops the bridge, exit 1.
        self._excepthook = threading.excepthook
        threading.excepthook = self._thread_died
        try:
            loops = open_nodes(self.config, self.nodes, self._closers, supervision=self.supervision)
        except BaseException:
            self._close_all()
            threading.excepthook = self._excepthook
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
                          t=round(u.t, 4), f_sum=round(u.f_sum, 3), r_coe=round(u.r_coe, 3), r_dw=round(u.r_dw, 3),
                          score_a=round(u.score_a, 3), score_b=round(u.score_b, 3))
            if outer is not None:
                outer(run.name, u)

        return hook

    def _command_hook(self, run: NodeRun) -> Callable[[str], None]:
        log, throttle = self.log, self._commands_logged

        def hook(name: str) -> None:
            # A client may write commands as fast as the link goes: one line per
            # command and node per LOG_EVERY_S, the next saying how many were held back
            # (the loop's ``commands`` counter counts every one).
            held = throttle.passes((run.name, name))
            if held is not None:
                log.event("plc_command", node=run.name, command=name, held_back=held)

        return hook

    def _sink_event_hook(self, run: NodeRun) -> Callable[[str, str, dict[str, Any]], None]:
        return lambda name, level, fields: self.log.event(name, level, node=run.name, **fields)

    # -- running --------------------------------------------------------------------
    def start(self) -> Bridge:
        self._switch_interval = sys.getswitchinterval()
        sys.setswitchinterval(SWITCH_INTERVAL_S)
        self.log.event("start", nodes=",".join(r.name for r in self.runs), outputs=self.where,
                       sources=",".join(r.node.kind.describe(r.node) for r in self.runs))
        for run in self.runs:
            run.loop.source.start()  # a shared reader starts once, here: a replayed log does not run ahead
        for feeder, members in self.groups:
            runs = [self.runs[i] for i in members]
            self._stall.add(f"feed-{'+'.join(r.name for r in runs)}", runs)
            self._spawn(f"feed-{'+'.join(r.name for r in runs)}", self._group_loop, feeder, runs)
        grouped = {i for _, members in self.groups for i in members}
        for i, run in enumerate(self.runs):
            if i not in grouped:
                self._stall.add(f"node-{run.name}", [run])
                self._spawn(f"node-{run.name}", self._node_loop, run)
        self.started = True
        self.notifier.ready(f"running: {len(self.runs)} node(s) -> {self.where}")
        return self

    def _spawn(self, name: str, target: Callable[..., None], *args: Any) -> None:
        # the loop's index in _beats comes last
        t = threading.Thread(target=self._guard, args=(target, *args, len(self._threads)), name=name, daemon=True)
        self._threads.append(t)
        self._beats.append(0)
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

    def _thread_died(self, args: threading.ExceptHookArgs) -> None:
        """A thread of the process ended by an exception (the loops catch theirs).  An
        output's (by its name) is that output's failure: it restarts, the bridge goes
        on (:mod:`.supervise`); any other's (a source's reader), or an output's whose
        ``on_failure`` is ``stop``: logged, and the bridge stops with a failure."""
        if args.exc_type is SystemExit:
            return
        name = args.thread.name if args.thread is not None else "-"
        error = f"{args.exc_type.__name__}: {args.exc_value}"
        if self.supervision.thread_died(args.thread, error):
            return
        if not self.failure:
            self.failure = f"thread {name} died: {error}"
        self.log.event("thread_failed", level="error", thread=name, error=error)
        self._stop.set()

    def _output_stops(self, reason: str) -> None:
        """An output failed, and its ``on_failure`` is ``stop``: the bridge stops with a failure."""
        if not self.failure:
            self.failure = reason
        self._stop.set()

    def _node_loop(self, run: NodeRun, beat: int) -> None:
        step, stop, beats = run.loop.step, self._stop, self._beats
        source = run.loop.source
        while not stop.is_set():
            step()
            beats[beat] += 1
            if source.done:
                self._source_end([run])
                break

    def _group_loop(self, feeder: Feeder, runs: list[NodeRun], beat: int) -> None:
        stop, beats = self._stop, self._beats
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
            beats[beat] += 1
            if feeder.serve_error is not None:
                raise feeder.serve_error
            if feeder.done:  # (a log refused for its layout stops its player: done too)
                self._source_end(runs)
                break

    def _source_end(self, runs: list[NodeRun]) -> None:
        """Finite sources have ended.  A clean end is news; a failed one (a corrupt log,
        one of another layout) is an error: its node's image is published once more, with
        BUS_FAULT, and the bridge will exit non-zero once no loop runs."""
        clean = [r.name for r in runs if not r.loop.source.failed]
        if clean:
            self.log.event("source_ended", node=",".join(clean), error="-")
        for run in runs:
            source = run.loop.source
            if not source.failed and not self._stop.is_set():
                # The node's last image while the bridge runs on: nothing claimed, the
                # node offline (its heartbeat stops here), never its last "stable".
                run.loop.shutdown()
            elif source.failed:
                self.log.event("source_failed", level="error", node=run.name, error=source.last_error)
                run.loop.publish_if_due(True)  # BUS_FAULT now, before the loop lets go
                # ... and handed on before the bridge's end offers its offline image, which
                # would otherwise replace a BUS_FAULT image still waiting to be written
                for sink in run.sinks:
                    sink.drain(0.5)
                self.failed_sources.append(f"{run.name}: {source.last_error}")
        self._sinks_source_ended(runs)  # a Sparkplug device's DDEATH, after the BUS_FAULT image

    @staticmethod
    def _sinks_source_ended(runs: list[NodeRun]) -> None:
        """Each sink of a node whose source ended hears it (a Sparkplug device's DDEATH)."""
        for run in runs:
            for sink in run.sinks:
                sink.source_ended(run.loop.source.last_error or "")

    def _fail_if_sources_failed(self) -> None:
        """A bridge whose sources have all ended, one of them failed, has failed (exit 1):
        a service manager must restart it, not take it for a finished replay."""
        if self.failed_sources and not self.failure and all(r.loop.source.done for r in self.runs):
            self.failure = "source failed: " + "; ".join(self.failed_sources)

    def wait(self, duration_s: float | None = None, tick_s: float = 0.1, signals: SignalFlags | None = None) -> None:
        """Supervise until :meth:`request_stop`, a stopping signal in ``signals``,
        ``duration_s``, or every source ended; log the counters when USR1 came."""
        end = None if duration_s is None else time.monotonic() + duration_s
        status_every = self.config.log.status_every_s
        next_status = time.monotonic() + status_every if status_every else None
        feed_every = self.notifier.watchdog_interval_s
        # the first WATCHDOG=1 after one period: every loop must have turned by then
        next_feed = time.monotonic() + feed_every if feed_every is not None else None
        seen = list(self._beats)
        usr1 = 0
        while not self._stop.is_set():
            if signals is not None:
                if signals.reason:  # a signal during open() too
                    self.request_stop(signals.reason)
                    break
                if signals.counters != usr1:
                    usr1 = signals.counters
                    self.log_counters("counters")
            if end is not None and time.monotonic() >= end:
                break
            if self._threads and not any(t.is_alive() for t in self._threads):
                self._fail_if_sources_failed()
                break
            if next_feed is not None and feed_every is not None and time.monotonic() >= next_feed:
                next_feed = time.monotonic() + feed_every
                seen = self._feed_watchdog(seen)
            self._stop.wait(tick_s)
            if not self._stop.is_set():
                self._stall.check(self._beats, [t.is_alive() for t in self._threads], tick_s)
            self.check_health()
            if next_status is not None and time.monotonic() >= next_status:
                next_status += status_every
                self.log_counters("counters")

    def _feed_watchdog(self, seen: list[int]) -> list[int]:
        """WATCHDOG=1 when every loop still running has turned since the last look;
        otherwise nothing (systemd restarts a hung bridge) and one error line naming
        the loops that did not.  Returns the beats now."""
        beats = list(self._beats)
        stuck = [t.name for t, b, s in zip(self._threads, beats, seen) if t.is_alive() and b == s]
        if not stuck:
            self.notifier.watchdog()
            if self._starved:
                self._starved = False
                self.log.event("watchdog_fed", level="info")
        elif not self._starved:
            self._starved = True
            self.log.event("watchdog_starved", level="error", loops=",".join(stuck))
        return beats

    def request_stop(self, reason: str = "") -> None:
        """Stop from another thread (a signal handler sets :class:`SignalFlags`
        instead: an Event takes a lock the interrupted thread may hold)."""
        if reason and not self._stop.is_set():
            self.stop_reason = reason
        self._stop.set()

    def check_health(self) -> None:
        """Log what changed since the last look: stale, bus fault, each output's connection."""
        now = time.monotonic()
        for run in self.runs:
            src = run.loop.source
            seen: dict[str, tuple[bool, Sink | None]] = {
                "stale": (run.loop.status.is_stale(src.frame_age(now)), None),
                "bus_fault": (src.bus_fault, None),
                # once per episode (a scan more, or a second kind joining, is no news)
                "sensor_fault": (bool(run.loop.pipeline.fault), None),
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
        elif key == "sensor_fault":
            fault = run.loop.pipeline.fault
            c = run.loop.pipeline.counters
            if value:
                # what the transport saw, when it raised the fault (STREAM: which frames)
                seen = {"detail": source.fault_reason} if source.fault_reason else {}
                self.log.event("sensor_fault", level="warning", node=run.name, why=FrameFlag.describe(fault),
                               fault_scans=c.fault_scans, invalid_scans=c.invalid_scans, **seen)
            else:
                self.log.event("sensor_ok", level="info", node=run.name, fault_scans=c.fault_scans)
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
        self.notifier.stopping(f"stopping: {self.stop_reason or ('failure' if self.failure else 'end')}")
        for t in self._threads:
            t.join(timeout=5.0)
        self._fail_if_sources_failed()
        for run in self.runs:
            self._guarded(run.loop.shutdown)  # one node's failure does not keep the others online
        offline = []
        for run in self.runs:
            # every sink flushed (a writer wrote the offline image, a server served it)
            if all([self._guarded(sink.flush) for sink in run.sinks]):
                offline.append(run.name)
        self._close_all()
        if self._switch_interval is not None:  # the process's setting, as it was
            sys.setswitchinterval(self._switch_interval)
        if self._excepthook is not None:
            threading.excepthook = self._excepthook
        self.log.event("stopped", reason=self.stop_reason or ("failure" if self.failure else "end"),
                       offline_written=",".join(offline) or "-")
        self.notifier.close()

    def _guarded(self, call: Callable[[], Any]) -> Any:
        """A step of the shutdown; an exception is logged and the shutdown goes on."""
        try:
            return call()
        except Exception as exc:  # noqa: BLE001 - every other output must still go offline
            self.log.event("stop_failed", level="error", error=f"{type(exc).__name__}: {exc}")
            return False

    def _close_all(self) -> None:
        for close in reversed(self._closers):
            try:
                close()
            except Exception as exc:  # noqa: BLE001 - closing must go on for the others
                self.log.event("close_failed", level="warning", error=f"{type(exc).__name__}: {exc}")
        self._closers.clear()
