"""Supervised outputs: no output's failure takes the others (the PLC's block) with it.

An *output* is one output kind with its sinks, one per node, as
``cls.open_nodes(options, nodes, context)`` opened them.  The loop never holds a kind's
sink itself: it holds one :class:`SupervisedSink` per node, and an
:class:`Output` per kind watches them.

- An exception from any call the loop makes (publish, on_update, on_frame,
  take_commands, commands_done, source_ended, health, counters), a call in progress
  longer than ``hang_s``, or the death of a thread the kind owns (by name: a thread
  named for the kind, ``opcua-server``, or one the kind declares in
  :attr:`~eskin_industrial.outputs.base.OutputKind.thread_names`, paho's), is one failure:
  one line (``output_failed``, the output and node named), the output set down (its
  sinks answer nothing until it is back), its instance closed off the loop with a
  time limit, and a fresh one opened after a back-off (``backoff_s`` doubling to
  ``backoff_max_s``, jittered, as the PLC writer's reconnects): ``output_restarted``.
  ``on_failure = "stop"`` stops the whole bridge with a failure instead.
- An output that cannot *open* at start (a full disk, a folder it cannot make, a
  library's error) is down from the start, the same one line (``call=open``), and
  opened after the back-off as after any failure: the others (the PLC) run meanwhile.
  A refusal stays the bridge's, one line before anything runs: a port in use, a
  profile's or a setting's error, a missing extra (what ``--check`` finds), and any
  error of an essential output or of one whose ``on_failure`` is ``stop``.
- An *essential* output (the PLC by default: its latency is the product) is called
  on the loop's thread, inside ``try``; it costs nothing while nothing raises.  Any
  other is driven from a handover of its own: the loop leaves the newest snapshot and
  frame (the newest wins, the superseded counted), the updates (bounded, the dropped
  counted) and the source's end in its mailbox, and a thread named ``KIND-output``
  hands them on.  A call there that hangs cannot stall the loop: the supervisor sees
  it past ``hang_s``, abandons that thread (a daemon, counted) and opens a fresh
  instance.  (A hang in an essential output stalls its loop: :mod:`.stall` then sets
  the loop's nodes offline until it turns again.)
- The state of each output is in every node's counters: ``KIND_output_up``,
  ``KIND_output_failures``, ``KIND_output_restarts``, ``KIND_output_abandoned``,
  ``KIND_output_superseded``, ``KIND_output_dropped``.

A frame handed across threads is not copied: the calibration makes a new forces array
for every scan (``Calibrator.to_newtons``), none is changed once the loop hands it on.
"""

from __future__ import annotations

import collections
import functools
import random
import threading
import time
import weakref
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal

from ..outputs.base import EventHandler, OutputKind, Sink, SinkHealth

if TYPE_CHECKING:
    from ..detect.updates import Update
    from ..frames import Frame
    from ..node import Command, NodeSnapshot
    from ..seam import NodeLike, OpenContext

#: Share of a back-off taken off at random (the PLC writer's, plc/client.py).
JITTER = 0.25
#: Updates held in a handover for its thread; past it the oldest are dropped (counted).
UPDATES_HELD = 4096
#: A handover's thread looks at its mailbox at least this often (commands, health).
POLL_S = 0.02
#: Health and counters of a handed-over output are read this often by its thread.
CACHE_S = 0.1
#: An instance's close at a restart may take this long at least (``hang_s`` when longer);
#: past it the close's thread is abandoned and a fresh instance opened all the same.
CLOSE_MIN_S = 3.0
#: The last close, when the bridge stops: a server serving its offline image lingers.
CLOSE_AT_STOP_S = 15.0


@dataclass(frozen=True)
class Policy:
    """How one output is supervised (``[supervision]`` of the bridge configuration)."""

    essential: bool = False
    on_failure: Literal["restart", "stop"] = "restart"
    backoff_s: float = 1.0
    backoff_max_s: float = 30.0
    hang_s: float = 5.0


def owns_thread(cls: type[OutputKind[Any]], name: str) -> bool:
    """A thread of this output kind, by its name (``opcua-server``, paho's)."""
    return name == cls.name or any(name.startswith(prefix) for prefix in (f"{cls.name}-", *cls.thread_names))


class _Down(Sink):
    """What a sink of an output that is down answers: nothing, at once."""


_DOWN = _Down()


class _NotOpen(Sink):
    """A node's sink of an output that did not open at start, until it does: what the
    kind wants of the loop is not known yet, so the loop is asked for everything
    (updates, commands, every frame); the handover passes on what the kind's sink,
    once open, takes (its frames at its own ``frame_every_s``)."""

    def __init__(self, kind: str) -> None:
        super().__init__()
        self.kind = kind
        self.where = f"{kind} (not open)"
        self.frame_every_s = 0.0

    def on_update(self, update: Update) -> None:
        """(Overridden: the loop hands updates to this sink.)"""

    def take_commands(self) -> list[Command]:
        return []


class SupervisedSink(Sink):
    """One node's sink of a supervised output, as the loop holds it; what the kind's
    instance has of its own (``server``, ``node``) is read through."""

    def __init__(self, output: Output, index: int, inner: Sink) -> None:
        super().__init__()
        self.kind = output.kind  # the kind's name, as the bridge reads it off every sink
        self.output = output
        self.index = index
        self.node_name = output.nodes[index].name
        self.inner: Sink = inner
        self._kind_cls = type(inner)
        self.where = inner.where
        self.frame_every_s = inner.frame_every_s
        #: Built on a :class:`_NotOpen`: the loop hands every frame, the handover gates them.
        self.late = isinstance(inner, _NotOpen)
        self.next_frame = 0.0  #: (late) when the kind's sink takes its next frame (monotonic)
        self._handler: EventHandler | None = None

    def __getattr__(self, name: str) -> Any:
        inner = self.__dict__.get("inner")
        if inner is None or name.startswith("__"):
            raise AttributeError(name)
        return getattr(inner, name)

    def overrides(self, name: str) -> bool:
        return getattr(self._kind_cls, name) is not getattr(Sink, name)

    def attach(self, inner: Sink) -> None:
        """A fresh instance of the kind (a restart), its events to the same handler."""
        self.inner = inner
        self._kind_cls = type(inner)  # (an instance opened late: the kind's own, from now on)
        self.where = inner.where
        if self._handler is not None:
            inner.on_events(self._handler)

    def on_events(self, handler: EventHandler) -> None:
        self._handler = handler
        self.inner.on_events(handler)

    def _own(self, out: dict[str, int]) -> dict[str, int]:
        out.update(self.output.counters())
        return out

    def close(self) -> None:
        """The output closes its instance (:meth:`Output.close`): nothing per node."""


class GuardedSink(SupervisedSink):
    """An essential output's sink: called on the loop's thread, an exception caught."""

    def publish(self, snapshot: NodeSnapshot) -> None:
        try:
            self.inner.publish(snapshot)
        except Exception as exc:  # noqa: BLE001 - the output fails, the loop goes on
            self.output.failed("publish", self.index, exc)

    def on_update(self, update: Update) -> None:
        try:
            self.inner.on_update(update)
        except Exception as exc:  # noqa: BLE001
            self.output.failed("on_update", self.index, exc)

    def on_frame(self, frame: Frame) -> None:
        try:
            self.inner.on_frame(frame)
        except Exception as exc:  # noqa: BLE001
            self.output.failed("on_frame", self.index, exc)

    def take_commands(self) -> list[Command]:
        try:
            return self.inner.take_commands()
        except Exception as exc:  # noqa: BLE001
            self.output.failed("take_commands", self.index, exc)
            return []

    def commands_done(self) -> None:
        try:
            self.inner.commands_done()
        except Exception as exc:  # noqa: BLE001
            self.output.failed("commands_done", self.index, exc)

    def source_ended(self, error: str) -> None:
        try:
            self.inner.source_ended(error)
        except Exception as exc:  # noqa: BLE001
            self.output.failed("source_ended", self.index, exc)

    def health(self) -> SinkHealth:
        try:
            return self.inner.health()
        except Exception as exc:  # noqa: BLE001
            self.output.failed("health", self.index, exc)
            return SinkHealth()

    def counters(self) -> dict[str, int]:
        try:
            out = dict(self.inner.counters())
        except Exception as exc:  # noqa: BLE001
            self.output.failed("counters", self.index, exc)
            out = {}
        return self._own(out)

    def drain(self, timeout_s: float = 0.5) -> bool:
        if not self.output.up:
            return False
        try:
            return self.inner.drain(timeout_s)
        except Exception as exc:  # noqa: BLE001
            self.output.failed("drain", self.index, exc)
            return False

    def flush(self, timeout_s: float = 1.0) -> bool:
        if not self.output.up:
            return False
        return self.inner.flush(timeout_s)


class HandedSink(SupervisedSink):
    """A non-essential output's sink: the loop leaves what it hands in a mailbox, the
    output's thread (:class:`_Handover`) calls the kind's instance."""

    def __init__(self, output: Output, index: int, inner: Sink) -> None:
        super().__init__(output, index, inner)
        self.lock = threading.Lock()
        self.snapshot: NodeSnapshot | None = None
        self.frame: Frame | None = None
        self.updates: collections.deque[Update] = collections.deque()
        self.ended: str | None = None
        self.done = False  #: commands_done asked
        self.commands: collections.deque[Command] = collections.deque()
        self.flush_asked: tuple[float, threading.Event, list[bool]] | None = None
        self.cached_health = SinkHealth()
        self.cached_counters: dict[str, int] = {}

    def attach(self, inner: Sink) -> None:
        self.cached_health, self.cached_counters = SinkHealth(), {}  # the old instance's no longer
        super().attach(inner)

    def publish(self, snapshot: NodeSnapshot) -> None:
        if self.snapshot is not None:
            self.output.superseded += 1
        self.snapshot = snapshot
        self.output.wake.set()

    def drain(self, timeout_s: float = 0.5) -> bool:
        """Wait until the output's thread has taken the snapshot in the mailbox: what
        the loop publishes next (the bridge's offline image after a BUS_FAULT one)
        then follows it instead of replacing it unseen.  False if the output is down or
        its thread did not come within ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        while self.snapshot is not None and self.output.up and time.monotonic() < deadline:
            self.output.wake.set()
            time.sleep(0.002)
        return self.snapshot is None and self.output.up

    def on_update(self, update: Update) -> None:
        updates = self.updates
        if len(updates) >= UPDATES_HELD:
            updates.popleft()
            self.output.dropped += 1
        updates.append(update)

    def on_frame(self, frame: Frame) -> None:
        if self.frame is not None and not self.late:  # (late: every frame comes, the newest is taken)
            self.output.superseded += 1
        self.frame = frame
        self.output.wake.set()

    def take_commands(self) -> list[Command]:
        commands = self.commands
        out = []
        while commands:
            out.append(commands.popleft())
        return out

    def commands_done(self) -> None:
        self.done = True

    def source_ended(self, error: str) -> None:
        self.ended = error
        self.output.wake.set()

    # Health and counters are plain reads in every kind, asked by the supervising thread
    # (never a loop): read at once, as before supervision (a status line right after a
    # burst counts all of it); the handover's thread refreshes the same cache, which
    # answers while the output is down.
    def health(self) -> SinkHealth:
        if self.output.up:
            try:
                self.cached_health = self.inner.health()
            except Exception as exc:  # noqa: BLE001 - the output fails, the caller goes on
                self.output.failed("health", self.index, exc)
        return self.cached_health

    def counters(self) -> dict[str, int]:
        if self.output.up:
            try:
                self.cached_counters = dict(self.inner.counters())
            except Exception as exc:  # noqa: BLE001
                self.output.failed("counters", self.index, exc)
        return self._own(dict(self.cached_counters))

    def flush(self, timeout_s: float = 1.0) -> bool:
        """What is in the mailbox handed on, then the kind's own flush, within ``timeout_s``."""
        if not self.output.up:
            return False
        done = threading.Event()
        result: list[bool] = []
        self.flush_asked = (time.monotonic() + timeout_s, done, result)
        self.output.wake.set()
        done.wait(timeout_s)
        return bool(result and result[0])


class _Handover:
    """The thread that calls a non-essential output's instance for every node."""

    def __init__(self, output: Output, generation: int) -> None:
        self.output = output
        self.generation = generation
        #: (the call, the node's index, until when it may take) of the call in progress
        self.busy: tuple[str, int, float] | None = None
        self.thread = threading.Thread(target=self._run, name=f"{output.kind}-output", daemon=True)

    def _live(self) -> bool:
        return self.output.generation == self.generation and self.output.up

    def _call(self, name: str, sink: HandedSink, call: Callable[[], Any], allowed_s: float = 0.0) -> tuple[bool, Any]:
        """``call``, its exception the output's failure; past ``hang_s`` (and the
        ``allowed_s`` the call has of its own, a flush's) it is a hang."""
        self.busy = (name, sink.index, time.monotonic() + self.output.policy.hang_s + allowed_s)
        try:
            return True, call()
        except Exception as exc:  # noqa: BLE001 - the output fails, the bridge goes on
            self.output.failed(name, sink.index, exc, self.generation)
            return False, None
        finally:
            self.busy = None

    def _run(self) -> None:
        out = self.output
        sinks: Sequence[HandedSink] = out.sinks  # type: ignore[assignment]
        next_cache = 0.0
        while not out.closing or any(s.flush_asked is not None for s in sinks):
            out.wake.wait(POLL_S)
            out.wake.clear()
            if not self._live():
                return  # abandoned, or the output is down: a fresh instance has its own thread
            now = time.monotonic()
            for s in sinks:
                if not self._serve(s, now >= next_cache):
                    return
            if now >= next_cache:
                next_cache = now + CACHE_S

    def _serve(self, s: HandedSink, refresh: bool) -> bool:
        """One node's mailbox handed on; False once this thread is no longer the output's."""
        inner = s.inner
        while s.updates:
            u = s.updates.popleft()
            if not self._call("on_update", s, functools.partial(inner.on_update, u))[0] or not self._live():
                return False
        snap, s.snapshot = s.snapshot, None
        if snap is not None and (not self._call("publish", s, functools.partial(inner.publish, snap))[0] or not self._live()):
            return False
        frame, s.frame = s.frame, None
        if frame is not None and s.late:  # the loop hands every frame: the kind's interval here
            every = getattr(inner, "frame_every_s", None)
            if every is None or time.monotonic() < s.next_frame:
                frame = None
            else:
                s.next_frame = time.monotonic() + every
        if frame is not None and (not self._call("on_frame", s, functools.partial(inner.on_frame, frame))[0] or not self._live()):
            return False
        ended, s.ended = s.ended, None
        if ended is not None and (not self._call("source_ended", s, functools.partial(inner.source_ended, ended))[0]
                                  or not self._live()):
            return False
        if s.done:
            s.done = False
            if not self._call("commands_done", s, inner.commands_done)[0] or not self._live():
                return False
        if s.overrides("take_commands"):
            ok, commands = self._call("take_commands", s, inner.take_commands)
            if not ok or not self._live():
                return False
            s.commands.extend(commands)
        asked, s.flush_asked = s.flush_asked, None
        if asked is not None:
            until, done, result = asked
            left = max(0.0, until - time.monotonic())
            ok, flushed = self._call("flush", s, functools.partial(inner.flush, left), left)
            result.append(bool(ok and flushed))
            refresh = True
            done.set()
            if not ok or not self._live():
                return False
        if refresh:
            return self.refresh(s)
        return True

    def refresh(self, s: HandedSink) -> bool:
        ok, health = self._call("health", s, s.inner.health)
        if not ok or not self._live():
            return False
        ok, counters = self._call("counters", s, s.inner.counters)
        if not ok or not self._live():
            return False
        s.cached_health, s.cached_counters = health, dict(counters)
        return True


class Output:
    """One output kind's sinks, watched: failures caught, the instance restarted."""

    def __init__(self, cls: type[OutputKind[Any]], options: Any, nodes: Sequence[NodeLike[Any]], context: OpenContext,
                 policy: Policy, log: Callable[..., None], stop: Callable[[str], None]) -> None:
        self.cls = cls
        self.options = options
        self.nodes = nodes
        self.context = context
        self.policy = policy
        self._log = log
        self._stop_bridge = stop
        self.kind = cls.name
        self.lock = threading.Lock()
        self.wake = threading.Event()
        self.up = False
        self.closing = False
        self.generation = 0
        self.failures = self.restarts = self.abandoned = self.superseded = self.dropped = 0
        self.last_error = ""
        self.sinks: list[SupervisedSink] = []
        self._closers: list[Callable[[], None]] = []
        self._handover: _Handover | None = None
        self._retired: weakref.WeakSet[threading.Thread] = weakref.WeakSet()
        self._failed_at = 0.0  #: the failure (or failed reopen) the back-off is counted from
        self._down_since = 0.0
        self._up_since = 0.0
        self._delay = policy.backoff_s
        self._random = random.Random()
        self._kick = threading.Event()
        self._watch: threading.Thread | None = None

    # -- opening ----------------------------------------------------------------------
    def _open_instance(self) -> list[Sink]:
        from ..seam import OpenContext

        closers: list[Callable[[], None]] = []
        context = OpenContext(queue_frames=self.context.queue_frames, all_frames=self.context.all_frames,
                              closers=closers, reopen=self.generation > 0, identity=self.context.identity,
                              kept=self.context.kept)
        try:
            opened = self.cls.open_nodes(self.options, self.nodes, context)
        except BaseException:
            _close_all(closers)
            raise
        self._closers = closers
        return opened

    def open(self) -> list[SupervisedSink]:
        """The first instance.  A refusal, or any error of an essential output (or of
        one that stops the bridge), is the bridge's: nothing runs yet.  Any other
        output that fails to open is down from the start: one line, opened again after
        the back-off."""
        from ..errors import ListenError, MissingExtra, ProfileError

        error: Exception | None = None
        try:
            opened = self._open_instance()
        except (ListenError, ProfileError, MissingExtra, ValueError):
            raise
        except Exception as exc:  # a full disk at start: the PLC is served all the same
            if self.policy.essential or self.policy.on_failure == "stop":
                raise
            error = exc
            opened = [_NotOpen(self.kind) for _ in self.nodes]
        base = GuardedSink if self.policy.essential else HandedSink
        # what the kind's sinks say of themselves, as the bridge reads it off the class
        # (the kind's name is each proxy's own, as every sink's)
        proxy = type(f"{base.__name__}_{self.kind}", (base,),
                     {"logs_connection": any(s.logs_connection for s in opened), "__module__": __name__})
        self.sinks = [proxy(self, i, sink) for i, sink in enumerate(opened)]
        self.up = True
        self._up_since = time.monotonic()
        if error is not None:
            self.failed("open", None, error)  # down: one line, the supervisor opens it after the back-off
        elif not self.policy.essential:
            self._start_handover()
        self._watch = threading.Thread(target=self._supervise, name=f"supervise-{self.kind}", daemon=True)
        self._watch.start()
        return self.sinks

    def _start_handover(self) -> None:
        self._handover = _Handover(self, self.generation)
        self._handover.thread.start()

    # -- failing --------------------------------------------------------------------------
    def failed(self, call: str, index: int | None, error: BaseException | str, generation: int | None = None) -> None:
        """A failure of this output, from any thread (one line; later ones of the same
        instance are the same failure)."""
        text = error if isinstance(error, str) else f"{type(error).__name__}: {error}"
        with self.lock:
            if not self.up or self.closing or (generation is not None and generation != self.generation):
                return
            self.up = False
            self.generation += 1
            self.failures += 1
            self.last_error = text
            self._failed_at = self._down_since = time.monotonic()
            for s in self.sinks:
                if isinstance(s, GuardedSink):
                    s.inner = _DOWN
            self._retired.update(t for t in threading.enumerate() if owns_thread(self.cls, t.name))
        node = self.nodes[index].name if index is not None else "-"
        stop = self.policy.on_failure == "stop"
        self._log("output_failed", "error", output=self.kind, node=node, call=call, error=text,
                  then="stop" if stop else "restart")
        if stop:
            self._stop_bridge(f"output {self.kind} failed: {call}: {text}")
        self._kick.set()

    def thread_died(self, thread: threading.Thread | None, error: str) -> bool:
        """A thread of this kind ended by an exception: True when it is handled here
        (a restart, or a thread of an instance already given up); False: the bridge
        stops (``on_failure = "stop"``)."""
        if thread is not None and thread in self._retired:
            return True
        if self.policy.on_failure == "stop":
            return False
        self.failed(f"thread {thread.name if thread is not None else '-'}", None, error)
        return True

    # -- the supervisor's thread ----------------------------------------------------------
    def _supervise(self) -> None:
        tick = min(0.05, self.policy.hang_s / 4)
        while not self.closing:
            self._kick.wait(tick)
            self._kick.clear()
            if self.closing:
                return
            try:
                if self.up:
                    self._watch_up()
                elif self.policy.on_failure == "restart":
                    self._restart()
            except Exception as exc:  # noqa: BLE001 - the supervisor itself must go on
                self._log("supervise_failed", "error", output=self.kind, error=f"{type(exc).__name__}: {exc}")

    def _watch_up(self) -> None:
        handover = self._handover
        busy = handover.busy if handover is not None else None
        if busy is not None and handover is not None:
            call, index, until = busy
            if time.monotonic() > until:
                generation = self.generation
                self.failed(call, index, f"{call} did not return within hang_s ({self.policy.hang_s:g} s)",
                            handover.generation)
                if self.generation != generation:
                    self.abandoned += 1  # that thread stays where it is, a daemon
                    self._retired.add(handover.thread)
        if time.monotonic() - self._up_since >= self.policy.backoff_max_s:
            self._delay = self.policy.backoff_s  # up long enough: the next failure waits the least again

    def _restart(self) -> None:
        """Close the failed instance (off the loop, within a limit), wait out the
        back-off (counted from the failure: a slow close is part of it), open a fresh one."""
        self._handover = None
        closers, self._closers = self._closers, []
        t0 = time.monotonic()
        if not _close_within(closers, max(self.policy.hang_s, CLOSE_MIN_S), f"{self.kind}-close"):
            self.abandoned += 1
        close_s = time.monotonic() - t0
        wait = self._delay * (1.0 - JITTER * self._random.random())
        self._delay = min(self._delay * 2, self.policy.backoff_max_s)
        end = self._failed_at + wait
        while not self.closing and time.monotonic() < end:
            time.sleep(min(0.02, max(0.0, end - time.monotonic())))
        if self.closing:
            return
        t1 = time.monotonic()
        try:
            opened = self._open_instance()
        except Exception as exc:  # noqa: BLE001 - tried again after the next back-off
            self._failed_at = time.monotonic()
            self.last_error = f"{type(exc).__name__}: {exc}"
            self._log("output_restart_failed", "warning", output=self.kind, error=self.last_error,
                      retry_in_s=round(self._delay, 3))
            self._kick.set()
            return
        open_s = time.monotonic() - t1
        with self.lock:
            if self.closing:
                _close_within(self._closers, CLOSE_MIN_S, f"{self.kind}-close")
                return
            for s, inner in zip(self.sinks, opened):
                s.attach(inner)
            self.restarts += 1
            self.up = True
            self._up_since = time.monotonic()
        if not self.policy.essential:
            self._start_handover()
        self._log("output_restarted", "info", output=self.kind, restarts=self.restarts,
                  down_s=round(time.monotonic() - self._down_since, 3), backoff_s=round(wait, 3),
                  close_s=round(close_s, 3), open_s=round(open_s, 3), where=self.sinks[0].where)

    # -- state and the end -----------------------------------------------------------------
    def counters(self) -> dict[str, int]:
        k = self.kind
        return {f"{k}_output_up": int(self.up), f"{k}_output_failures": self.failures,
                f"{k}_output_restarts": self.restarts, f"{k}_output_abandoned": self.abandoned,
                f"{k}_output_superseded": self.superseded, f"{k}_output_dropped": self.dropped}

    def close(self) -> None:
        """Stop watching, let the handover's thread end, close the instance (an
        essential one on this thread, as ever; any other within a time limit)."""
        with self.lock:
            self.closing = True
        self._kick.set()
        self.wake.set()
        handover = self._handover
        if handover is not None:
            handover.thread.join(timeout=max(self.policy.hang_s, 0.5))
            if self.up and not handover.thread.is_alive():
                for s in self.sinks:  # the counters as the instance ends them
                    if isinstance(s, HandedSink):
                        handover.refresh(s)
        if self._watch is not None and self._watch is not threading.current_thread():
            self._watch.join(timeout=1.0)
        closers, self._closers = self._closers, []
        if self.policy.essential:
            _close_all(closers)
        elif not _close_within(closers, CLOSE_AT_STOP_S, f"{self.kind}-close"):
            self.abandoned += 1


def _close_all(closers: list[Callable[[], None]]) -> None:
    error: BaseException | None = None
    for close in reversed(closers):
        try:
            close()
        except Exception as exc:  # noqa: BLE001 - the others are closed all the same
            error = error or exc
    if error is not None:
        raise error


def _close_within(closers: list[Callable[[], None]], limit_s: float, name: str) -> bool:
    """Run the closers on a thread of their own for at most ``limit_s``; False when
    they did not end in time (the thread is left, a daemon)."""
    if not closers:
        return True

    def run() -> None:
        try:
            _close_all(closers)
        except Exception:  # noqa: BLE001 - an instance given up: its close is best effort
            pass

    t = threading.Thread(target=run, name=name, daemon=True)
    t.start()
    t.join(limit_s)
    return not t.is_alive()


class Supervision:
    """Every output of a bridge (or of one node's command), and the thread deaths;
    ``log(event, level, **fields)`` takes the outputs' failures and restarts, ``stop(reason)``
    stops the run (an output whose ``on_failure`` is ``stop``)."""

    def __init__(self, log: Callable[..., None], stop: Callable[[str], None]) -> None:
        self.outputs: list[Output] = []
        self.log = log
        self.stop = stop

    def add(self, output: Output) -> list[SupervisedSink]:
        sinks = output.open()
        self.outputs.append(output)
        return sinks

    def thread_died(self, thread: threading.Thread | None, error: str) -> bool:
        """True when the thread was an output's and its output handles it (a restart)."""
        name = thread.name if thread is not None else ""
        for out in self.outputs:
            if owns_thread(out.cls, name):
                return out.thread_died(thread, error)
        return False

    def counters(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for o in self.outputs:
            out.update(o.counters())
        return out
