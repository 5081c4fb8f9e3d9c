"""The OPC UA server in a process of its own, so that its heap is not the bridge's.

Why: asyncua's address space is about 450 000 objects the garbage collector tracks
(the standard nodes, their attributes), six times the rest of the bridge.  A full
(generation 2) collection walks every tracked object holding the GIL: in the bridge's
process that was 0.3 to 1.2 s on two loaded cores, and building a server anew at a
restart triggers several, so the Modbus server's thread could not answer the PLC
meanwhile (reads of the served block stalled for up to 2.4 s).  Here the server's
collections walk its own heap, in its own process, and the bridge's stay small.

The bridge's side, :class:`OpcuaProcess`, answers the sinks as :class:`.server.OpcuaServer`
did: the loops put snapshots and frames into the same bounded handovers
(:mod:`.handover`, newest wins, the loop never waits); a thread ``opcua-server`` sends
what they hold through a pipe; a thread ``opcua-server-rx`` takes back the
server's events, its commands, its counters and the offline snapshots applied.
The server's process ending while it should serve is that thread's death: the output's
failure (one line), restarted after its back-off as any other.  The process is started
with ``spawn`` (no copy of the bridge's threads or locks) and ends when the bridge's
side of the pipe closes, so that a bridge killed leaves no server behind.
"""

from __future__ import annotations

import gc
import multiprocessing
import multiprocessing.connection
import threading
import time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

from ...errors import TransportError
from ...node import Command, NodeSnapshot
from .handover import Handover, Waker
from .options import OpcuaOptions
from .users import UserEntry

if TYPE_CHECKING:
    from .nodeinfo import NodeInfo

__all__ = ["OpcuaProcess"]

#: The longest a start may take: the process's imports, a new certificate, the
#: standard address space (the server's own START_TIMEOUT_S).
START_TIMEOUT_S = 60.0
#: The server's process looks at its queued commands and the offline snapshots
#: applied this often (and sends them at once).
REPORT_S = 0.02
#: The counters are asked of the server's process (what a client did is counted once
#: its answer is out); past this the last ones it sent answer.
COUNTERS_WAIT_S = 1.0
#: The sending thread looks at the handovers at least this often (a refresh wakes no one).
SEND_S = 0.02
#: A stop waits this long (after ``offline_linger_s``) for the server to close its
#: sessions and its port, then kills its process (the port is free at once): a
#: restart's close must end within the supervisor's limit on a loaded host too.
STOP_S = 2.0
#: The server's process runs this much nicer than the bridge's: on a busy host its
#: work (a restart's address space built anew, a client's browse) waits for the PLC's.
NICE = 5


class _Node:
    """What the sinks read of a node (``server.nodes[i].info``)."""

    def __init__(self, info: NodeInfo) -> None:
        self.info = info
        self.offline_applied = threading.Event()


class OpcuaProcess:
    """The bridge's side of one server in its own process; started and stopped from
    the bridge's thread, fed from the loops'."""

    def __init__(self, options: OpcuaOptions, infos: Sequence[NodeInfo], users: tuple[UserEntry, ...] = (),
                 on_event: Callable[..., None] | None = None, refresh_s: float = 0.05) -> None:
        self.options = options
        self.infos = list(infos)
        self.users = users
        self.refresh_s = refresh_s
        self.on_event: Callable[..., None] = on_event or (lambda *args, **fields: None)
        self.nodes = [_Node(info) for info in infos]
        self.wake = threading.Event()
        self.waker = Waker()
        self.waker.attach(self.wake.set)
        self.handovers = [Handover(self.waker) for _ in infos]
        #: The newest snapshot each node's loop published (its source's end is told on it).
        self.published: list[NodeSnapshot | None] = [None] * len(self.infos)
        self._commands: list[list[Command]] = [[] for _ in infos]
        self._ended: list[tuple[int, str]] = []
        self._counters: list[dict[str, int]] = [{} for _ in infos]
        self._asked = self._answered = 0  #: the counters asked for, the newest answer's
        self._answer = threading.Condition()
        self._lock = threading.Lock()
        self._send_lock = threading.Lock()
        self._stopping = False
        self._ready = threading.Event()
        self._start_error: BaseException | None = None
        self._conn: multiprocessing.connection.Connection | None = None
        self._process: multiprocessing.process.BaseProcess | None = None
        self._sender: threading.Thread | None = None
        self._receiver: threading.Thread | None = None
        self.url = options.endpoint
        self.certificate_made = ""

    # -- life (the bridge's thread) ---------------------------------------------------
    def start(self) -> OpcuaProcess:
        """Listen; returns once clients can connect (the server's errors as its own)."""
        ctx = multiprocessing.get_context("spawn")
        ours, theirs = ctx.Pipe()
        self._conn = ours
        self._process = ctx.Process(target=_serve, name="opcua-server", daemon=True,
                                    args=(theirs, self.options, self.infos, self.users, self.refresh_s))
        self._process.start()
        _lower_priority(self._process.pid)
        theirs.close()  # the process's end: its death is our EOF
        self._receiver = threading.Thread(target=self._receive, name="opcua-server-rx", daemon=True)
        self._receiver.start()
        if not self._ready.wait(START_TIMEOUT_S) or self._start_error is not None:
            error = self._start_error or TransportError(f"[opcua] the server did not start within "
                                                        f"{START_TIMEOUT_S:g} s")
            self._stop_process(0.0)
            raise error
        self._sender = threading.Thread(target=self._send, name="opcua-server", daemon=True)
        self._sender.start()
        return self

    def stop(self) -> None:
        """What the loops handed over sent (the offline snapshots), the server stopped
        (it lingers ``offline_linger_s``), the process ended.  Safe to call twice."""
        sender = self._sender
        if self._stopping:
            return
        self._stopping = True
        self.wake.set()
        t0 = time.monotonic()
        if sender is not None:
            sender.join(timeout=STOP_S)
        self._stop_process(max(0.0, STOP_S + self.options.offline_linger_s - (time.monotonic() - t0)))

    def _stop_process(self, timeout_s: float) -> None:
        self._stopping = True
        process = self._process
        if process is None:
            return
        process.join(timeout_s)
        if process.is_alive():
            process.kill()
            process.join(5.0)
        if self._conn is not None:
            self._conn.close()
        receiver = self._receiver
        if receiver is not None and receiver is not threading.current_thread():
            receiver.join(timeout=5.0)

    @property
    def pid(self) -> int | None:
        return None if self._process is None else self._process.pid

    def wait_applied(self, index: int, timeout_s: float) -> bool:
        """The node's offline snapshot is in the address space (``flush``)."""
        return self.nodes[index].offline_applied.wait(timeout_s)

    # -- the loops' side ------------------------------------------------------------------
    def take_commands(self, index: int) -> list[Command]:
        with self._lock:
            out, self._commands[index] = self._commands[index], []
        return out

    def source_ended(self, index: int, error: str) -> None:
        """The node's source is gone: its values say so at once."""
        with self._lock:
            self._ended.append((index, error))
        self.wake.set()

    def counters(self, index: int) -> dict[str, int]:
        """The server's counters now (asked of its process, at most COUNTERS_WAIT_S)."""
        conn = self._conn
        if conn is not None and self._ready.is_set() and not self._stopping:
            with self._answer:
                self._asked += 1
                asked = self._asked
            sent = False
            # (a sender held up by a process that reads nothing: the last counters)
            if self._send_lock.acquire(timeout=COUNTERS_WAIT_S):
                try:
                    conn.send([("counters", asked)])
                    sent = True
                except (OSError, ValueError):
                    pass  # the process is gone: its last counters
                finally:
                    self._send_lock.release()
            if sent:
                with self._answer:
                    self._answer.wait_for(lambda: self._answered >= asked or self._stopping, COUNTERS_WAIT_S)
        out = dict(self._counters[index])
        h = self.handovers[index]
        out["opcua_handover_dropped"] = out.get("opcua_handover_dropped", 0) + h.dropped
        if "opcua_frames_replaced" in out:
            out["opcua_frames_replaced"] += h.frames_replaced
        return out

    # -- the sending thread -----------------------------------------------------------------
    def _send(self) -> None:
        conn = self._conn
        assert conn is not None
        while True:
            stopping = self._stopping
            self.wake.wait(SEND_S)
            self.wake.clear()
            self.waker.arm()
            with self._lock:
                ended, self._ended = self._ended, []
            batch: list[tuple[Any, ...]] = []
            for i, h in enumerate(self.handovers):
                snapshots = h.take()
                if snapshots:
                    batch.append(("snapshots", i, snapshots))
                frame = h.take_frame()
                if frame is not None:
                    batch.append(("frame", i, frame))
            batch.extend(("ended", i, error) for i, error in ended)
            if stopping:
                batch.append(("stop",))
            if batch:
                try:
                    with self._send_lock:
                        conn.send(batch)
                except OSError:
                    if self._stopping:
                        return
                    raise
            if stopping:
                return

    # -- the receiving thread ---------------------------------------------------------------
    def _receive(self) -> None:
        conn = self._conn
        assert conn is not None
        what = ""
        while True:
            try:
                message = conn.recv()
            except (EOFError, OSError):
                break
            what = message[0]
            if what == "event":
                _, name, level, node, fields = message
                self.on_event(name, level, node, **fields)
            elif what == "commands":
                with self._lock:
                    self._commands[message[1]].extend(message[2])
            elif what == "counters":
                with self._answer:
                    self._counters = message[1]
                    self._answered = max(self._answered, message[2])
                    self._answer.notify_all()
            elif what == "applied":
                self.nodes[message[1]].offline_applied.set()
            elif what == "ready":
                self._start_error, self.certificate_made = message[1], message[2]
                self._ready.set()
            elif what == "stopped":
                break
        with self._answer:
            self._answered = self._asked  # (no answer is to come)
            self._answer.notify_all()
        if what == "stopped":
            return
        if not self._ready.is_set():
            self._start_error = TransportError(f"[opcua] the server's process ended while starting "
                                               f"(exit code {self._exit_code()})")
            self._ready.set()
            return
        if not self._stopping:  # this thread's death is the output's failure
            raise TransportError(f"[opcua] the server's process ended (exit code {self._exit_code()})")

    def _exit_code(self) -> int | None:
        process = self._process
        if process is None:
            return None
        process.join(1.0)
        return process.exitcode


# -- the server's process -------------------------------------------------------------------
def _lower_priority(pid: int | None) -> None:
    """The server's process (``pid``; None: this one) at NICE above the bridge's niceness.

    Set by the bridge the moment the process exists, not only by the process once it
    runs: its start (the interpreter, the imports of the bridge's own modules, then
    asyncua's, about a second of CPU) would otherwise compete at the bridge's priority,
    on the CPU the bridge's threads run on (a new process starts beside its parent),
    while the PLC's reads are served through a restart."""
    import os

    try:
        bridge = os.getpriority(os.PRIO_PROCESS, os.getpid() if pid is not None else os.getppid())
        target = min(bridge + NICE, 19)
        if os.getpriority(os.PRIO_PROCESS, pid or 0) < target:
            os.setpriority(os.PRIO_PROCESS, pid or 0, target)
    except (OSError, AttributeError):
        pass  # (not on every system; a process already gone)


def _serve(conn: multiprocessing.connection.Connection, options: OpcuaOptions, infos: list[NodeInfo],
           users: tuple[UserEntry, ...], refresh_s: float) -> None:
    """The server, fed from the pipe until the bridge says stop or its end closes."""
    _lower_priority(None)  # (the bridge has done it already, unless it could not)
    try:
        from .server import OpcuaServer
    except BaseException as exc:  # noqa: BLE001 - an install asyncua does not import in: the start's error
        conn.send(("ready", _portable(exc), ""))
        return
    lock = threading.Lock()

    def send(message: tuple[Any, ...]) -> None:
        with lock:
            try:
                conn.send(message)
            except OSError:
                pass  # the bridge is gone: the pipe's EOF ends this process

    def on_event(name: str, level: str, node: str | None, **fields: Any) -> None:
        send(("event", name, level, node, fields))

    server = OpcuaServer(options, infos, users, on_event, refresh_s=refresh_s)
    try:
        server.start()
    except BaseException as exc:  # noqa: BLE001 - the bridge's side raises it
        send(("ready", _portable(exc), ""))
        return
    # the address space (asyncua's standard nodes and ours: hundreds of thousands of
    # objects) lives as long as the process: out of the collector's generations, so
    # that the full collections a connect/close storm's garbage sets off do not walk
    # it each time (a stall of the server's loop of 100 ms and more)
    gc.freeze()
    applied = [False] * len(infos)
    send(("counters", [server.counters(i) for i in range(len(infos))], 0))  # (there from the start)
    send(("ready", None, server.certificate_made))
    try:
        while True:
            if conn.poll(REPORT_S):
                try:
                    batch = conn.recv()
                except (EOFError, OSError):
                    return
                if any(m[0] == "stop" for m in batch):
                    _apply(server, batch)
                    server.stop()
                    _report(server, send, applied)
                    send(("counters", [server.counters(i) for i in range(len(infos))], 0))
                    send(("stopped",))
                    return
                _apply(server, batch)
                asked = max((m[1] for m in batch if m[0] == "counters"), default=0)
                if asked:
                    send(("counters", [server.counters(i) for i in range(len(infos))], asked))
            _report(server, send, applied)
    finally:
        server.stop()


def _apply(server: Any, batch: list[tuple[Any, ...]]) -> None:
    for message in batch:
        what, i = message[0], message[1] if len(message) > 1 else 0
        if what == "snapshots":
            for s in message[2]:
                server.published[i] = s
                server.handovers[i].put(s)
        elif what == "frame":
            server.handovers[i].put_frame(*message[2])
        elif what == "ended":
            server.source_ended(i, message[2])


def _report(server: Any, send: Callable[[tuple[Any, ...]], None], applied: list[bool]) -> None:
    """The commands queued, the offline snapshots applied."""
    for i in range(len(applied)):
        commands = server.take_commands(i)
        if commands:
            send(("commands", i, commands))
        if not applied[i] and server.nodes[i].offline_applied.is_set():
            applied[i] = True
            send(("applied", i))


def _portable(exc: BaseException) -> BaseException:
    """The start's error as the bridge's side can raise it (its type and its one line)."""
    import pickle

    try:
        pickle.loads(pickle.dumps(exc))
        return exc
    except Exception:  # noqa: BLE001 - an error that does not pickle: its line kept
        return TransportError(f"[opcua] {type(exc).__name__}: {exc}")
