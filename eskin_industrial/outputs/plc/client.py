"""Client mode: the bridge writes the register image into the PLC's holding registers,
over Modbus TCP (TCP_NODELAY) or RTU.

A writer thread owns the connection, so that a slow or absent PLC never stalls
detection: the bridge hands it the newest image (:meth:`PlcWriter.offer`) and goes
on.  The image is written at once when it is urgent (a state change), otherwise
every ``refresh_s``; an older image not yet written is replaced by the newer one
(the PLC wants the present; events survive in the latch and the counters).  After
each refresh the writer reads COMMAND and ENABLE from the PLC, hands their commands
to the bridge, and writes COMMAND back to 0 (the handshake), or to
:data:`~.image.CMD_REFUSED` for a value it refuses (unknown bits: nothing of it is
done); an ENABLE other than 0 or 1 is ignored (detection stays as it was).  Each
refused value read is counted (``plc_command_values_refused``,
``plc_enable_values_refused``) and logged, at most once per
:data:`~..ratelimit.LOG_EVERY_S` per kind.  The method's scores
(SCORE_A..SCORE_B, after COMMAND and ENABLE) are written at each refresh too, in a
request of their own; a PLC whose map ends before them answers with an exception,
which is no outage (counted, logged once, retried with the back-off).  After an urgent
image they are written at once as well, so that a PLC reacting to a state change reads
the scores that made it.

One request at a time, and a PLC that fails is not hammered.  A request has
``timeout_s`` to be answered; an answer up to as long again still counts as written,
late (``plc_late_writes``), beyond it the request failed.  After any failure (refused,
reset, no answer, an exception reply) the writer waits, and the wait doubles from
``backoff_s`` to ``backoff_max_s`` (each drawn from its last quarter at random, so that
bridges restarted together do not retry in step) until the PLC acknowledges a write.
Nothing wakes that wait but a stop: an urgent image offered meanwhile only replaces
the pending one, and the newest image (with the slip latch) is the first written when
the PLC answers again.  An outage (from the first failure to the next acknowledged
write) is logged by the writer itself, once at its start (``plc_unreachable``) and
once at its end (``plc_connected``, with its duration and the images it superseded).

Over TCP, an urgent image offered while the writer is idle is sent by the offering
thread itself (the bridge's loop): the request goes out at once, with no hand-off to
the writer thread, which only collects the answer.  A slow or hung PLC still never
stalls the loop: a send of one small request into an idle connection does not wait,
and while an answer is outstanding (or the writer waits out a back-off) the next
image waits for the writer as before.
"""

from __future__ import annotations

import collections
import queue
import random
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from ...errors import ModbusFault, Refused
from ...modbus.pymodbus_io import RtuMaster
from ...modbus.serial_line import SerialSettings
from ...modbus.tcp_master import PipelinedTcpMaster
from ...node import Command, NodeSnapshot
from ...profile import ModbusPlcSection
from ...ratelimit import Throttle
from ..base import Sink, SinkHealth
from .image import CMD_REFUSED, REG, TAIL_AT, PlcImage, parse_register_write

#: Each back-off wait is the current delay less up to this share of it, at random.
JITTER = 0.25


@dataclass
class WriterStats:
    writes: int = 0  #: writes the PLC acknowledged, late ones included
    late_writes: int = 0  #: acknowledged after ``timeout_s`` (within as long again)
    urgent_writes: int = 0
    failures: int = 0  #: failed connections and requests (refused, reset, no answer, exception)
    timeouts: int = 0  #: requests given up: no answer within twice ``timeout_s``
    exceptions: collections.Counter[int] = field(default_factory=collections.Counter)  #: replies, by code
    connects: int = 0
    connect_attempts: int = 0
    outages: int = 0  #: episodes from a first failure to the next acknowledged write
    superseded: int = 0  #: images replaced by a newer one before they were written
    sent_inline: int = 0  #: urgent images sent by the offering thread (no hand-off)
    command_reads_refused: int = 0  #: reads of COMMAND/ENABLE answered with an exception
    score_writes: int = 0  #: writes of SCORE_A..SCORE_B the PLC acknowledged
    score_writes_refused: int = 0  #: writes of SCORE_A..SCORE_B answered with an exception
    command_values_refused: int = 0  #: COMMAND values read with unknown bits (answered CMD_REFUSED)
    enable_values_refused: int = 0  #: ENABLE values read other than 0 or 1 (ignored)
    last_error: str = ""
    #: offer -> acknowledged write (urgent only); the newest ones, so months of
    #: running do not grow it
    latencies_s: collections.deque[float] = field(default_factory=lambda: collections.deque(maxlen=100_000))


@dataclass
class _Optional:
    """A request the PLC may refuse with an exception reply (a map with no COMMAND and
    ENABLE, or one that ends at ENABLE): no outage.  Its refusals are counted in
    ``WriterStats.<refused>``, logged once (``refused_event``), and the request backs
    off as writes do until it is answered again (``answered_event``)."""

    refused: str
    refused_event: str
    answered_event: str
    after: float = 0.0  #: monotonic: not before (a back-off)
    delay: float | None = None  #: the next back-off, while the PLC refuses

    def due(self) -> bool:
        return time.monotonic() >= self.after


@dataclass
class _Outage:
    """From the first failure to the next acknowledged write."""

    t0: float  #: monotonic, at the first failure
    cause: str  #: the first failure's kind: connection, timeout, exception, crc
    superseded: int  #: the writer's counts at the start
    failures: int
    attempts: int
    exceptions: dict[int, int]


def _by_code(now: collections.Counter[int], before: dict[int, int]) -> str:
    """``02:13,04:2``: the exception replies since ``before``, by code; ``-`` for none."""
    return ",".join(f"{c:02d}:{n - before.get(c, 0)}" for c, n in sorted(now.items()) if n > before.get(c, 0)) or "-"


class PlcWriter(Sink):
    logs_connection = True  # outages are logged from the writer's own transitions

    def __init__(self, settings: ModbusPlcSection, host: str | None = None, port: int | None = None,
                 *, timeout_s: float | None = None, poll_commands: bool = True, serial: SerialSettings | None = None,
                 on_written: Callable[[float, float], None] | None = None, refresh_s: float = 0.05) -> None:
        """``refresh_s``: the node's ``[output] refresh_s``: how often the image is
        written when nothing changes, and the PLC's commands read."""
        super().__init__()
        self.settings = settings
        self.refresh_s = refresh_s
        self.image = PlcImage(settings)  #: the node's register image (its heartbeat)
        self.host = host or settings.host
        self.port = port or settings.port
        self.serial = serial
        self.timeout_s = settings.timeout_s if timeout_s is None else timeout_s
        self.master: PipelinedTcpMaster | RtuMaster
        if serial is not None:  # the PLC as a Modbus RTU slave
            self.master = RtuMaster(serial, settings.unit_id, self.timeout_s)
        else:
            self.master = PipelinedTcpMaster(self.host, self.port, settings.unit_id, self.timeout_s,
                                             late_s=self.timeout_s)
        self.poll_commands = poll_commands
        self.on_written = on_written
        self.stats = WriterStats()
        self.commands: queue.SimpleQueue[Command] = queue.SimpleQueue()
        self._cond = threading.Condition()
        self._pending: tuple[list[int], bool, float] | None = None
        #: An urgent image the offering thread sent: (transaction id, registers, t_event, monotonic sent).
        self._outstanding: tuple[int, list[int], float, float] | None = None
        self._busy = False  #: the writer thread is in a transaction (the connection is its)
        self._inline = isinstance(self.master, PipelinedTcpMaster)
        self._last: list[int] | None = None
        self._stop = False
        self._flush_until = 0.0  #: on stop, an image still pending is written until then
        self._thread: threading.Thread | None = None
        self.connected = False
        self._delay = settings.backoff_s  #: the next back-off wait (before jitter)
        self._random = random.Random()
        self._outage: _Outage | None = None
        self._late_since: tuple[float, int] | None = None  #: (monotonic, late writes) when answers went late
        self._ever_written = False
        self._commands = _Optional("command_reads_refused", "plc_commands_refused", "plc_commands_read")
        self._tail: tuple[int, ...] = ()  #: the newest image's SCORE_A..SCORE_B
        self._scores = _Optional("score_writes_refused", "plc_scores_refused", "plc_scores_written")
        self._refusals = Throttle()  #: the refused-value log lines, per kind

        if serial is not None:
            self.where = f"rtu {serial.port} at {serial.baudrate} baud, unit {settings.unit_id} (client)"
        else:
            self.where = f"tcp {self.host}:{self.port} (client)"

    def start(self) -> PlcWriter:
        self._thread = threading.Thread(target=self._run, name="plc-writer", daemon=True)
        self._thread.start()
        return self

    def _publish(self, snapshot: NodeSnapshot) -> None:
        image = self.image
        registers = image.render(snapshot)
        self.offer(registers, snapshot.urgent, snapshot.t_event, tuple(image.tail))

    def offer(self, registers: list[int], urgent: bool = False, t_event: float | None = None,
              tail: tuple[int, ...] = ()) -> None:
        """Hand over the newest image; ``t_event`` (perf_counter) dates an urgent one;
        ``tail``: its SCORE_A..SCORE_B, written at the next refresh."""
        with self._cond:
            if tail:
                self._tail = tail
            pending = self._pending
            if (urgent and self._inline and self.connected and not self._busy and self._outstanding is None
                    and (pending is None or not pending[1]) and not self._stop):
                t0 = t_event if t_event is not None else time.perf_counter()
                try:
                    tid = self.master.send_write(self.settings.base_address, registers)  # type: ignore[union-attr]
                except ModbusFault:
                    pass  # the writer finds the connection broken and writes it after reconnecting
                else:
                    if pending is not None:  # a refresh not yet written: this newer image replaces it
                        self._pending = None
                        self.stats.superseded += 1
                    self._outstanding = (tid, list(registers), t0, time.monotonic())
                    self.stats.sent_inline += 1
                    self._cond.notify()  # the writer collects the answer
                    return
            if self._pending is not None:
                self.stats.superseded += 1
                urgent = urgent or self._pending[1]
                t_event = self._pending[2] if self._pending[1] else t_event
            self._pending = (list(registers), urgent, t_event if t_event is not None else time.perf_counter())
            if urgent:
                self._cond.notify()

    def take_commands(self) -> list[Command]:
        if self.commands.empty():  # every scan asks: no exception raised and caught for none
            return []
        out = []
        while True:
            try:
                out.append(self.commands.get_nowait())
            except queue.Empty:
                return out

    def _run(self) -> None:
        next_refresh = time.monotonic()
        while True:
            with self._cond:
                self._busy = False
                if self._finished():
                    break
                if self._outstanding is None and not (self._pending is not None and self._pending[1]):
                    self._cond.wait(max(0.0, next_refresh - time.monotonic()))
                if self._finished():
                    break
                self._busy = True
                sent, self._outstanding = self._outstanding, None
                item = None if sent is not None else self._pending
                if sent is None:
                    self._pending = None
            if sent is not None:
                ok = self._collect(sent)
            else:
                ok, next_refresh = self._cycle(item, next_refresh)
            if not ok:
                self._backoff()

    def _finished(self) -> bool:
        return self._stop and not self._flushing() and self._outstanding is None

    def _cycle(self, item: tuple[list[int], bool, float] | None, next_refresh: float) -> tuple[bool, float]:
        """Connect if need be, write the image (or the last one again), and on refresh
        read the PLC's commands; False when something failed."""
        s = self.settings
        try:
            if not self.connected:
                self.stats.connect_attempts += 1
                self.master.connect()
                with self._cond:
                    self.connected = True
                self.stats.connects += 1
            registers = item[0] if item is not None else self._last
            if registers is not None:
                urgent = item is not None and item[1]
                t_sent = time.monotonic()
                self.master.write_registers(s.base_address, registers)
                self._written(registers, item[2] if urgent and item is not None else None,
                              time.monotonic() - t_sent)
                item = None  # written: a failure of the read below does not bring it back
                if urgent:
                    self._urgent_tail()
            if time.monotonic() >= next_refresh:
                next_refresh = time.monotonic() + self.refresh_s
                # (after an image: never scores in a PLC that has no image yet)
                if self._tail and self._last is not None and self._scores.due():
                    self._write_tail()
                if self.poll_commands and self._commands.due():
                    self._poll_commands()
        except ModbusFault as exc:
            self._fail(exc, item)
            return False, next_refresh
        except Exception as exc:  # noqa: BLE001 - the writer must outlive any one failure
            self._fail(ModbusFault("connection", f"{type(exc).__name__}: {exc}"), item)
            return False, next_refresh
        return True, next_refresh

    def _collect(self, sent: tuple[int, list[int], float, float]) -> bool:
        """The answer to an image the offering thread sent."""
        tid, registers, t_event, t_sent = sent
        try:
            self.master.await_response(tid)  # type: ignore[union-attr]
        except ModbusFault as exc:
            self._fail(exc, (registers, True, t_event))  # written again once the PLC answers
            return False
        self._written(registers, t_event, time.monotonic() - t_sent)
        try:
            self._urgent_tail()
        except ModbusFault as exc:
            self._fail(exc, None)
            return False
        except Exception as exc:  # noqa: BLE001 - the writer must outlive any one failure
            self._fail(ModbusFault("connection", f"{type(exc).__name__}: {exc}"), None)
            return False
        return True

    def _written(self, registers: list[int], t_event: float | None, took_s: float) -> None:
        """A write the PLC acknowledged ``took_s`` after it was sent; ``t_event`` dates an urgent one."""
        t_ack = time.perf_counter()
        self._last = registers
        st = self.stats
        st.writes += 1
        if t_event is not None:
            st.urgent_writes += 1
            st.latencies_s.append(t_ack - t_event)
            if self.on_written is not None:
                self.on_written(t_event, t_ack)
        self._delay = self.settings.backoff_s
        if took_s > self.timeout_s:
            st.late_writes += 1
            if self._late_since is None:
                self._late_since = (time.monotonic(), st.late_writes - 1)
                self._event("plc_late", "warning", plc=self.where, answer_s=round(took_s, 3),
                            timeout_s=self.timeout_s)
        elif self._late_since is not None:
            t0, before = self._late_since
            self._late_since = None
            self._event("plc_on_time", plc=self.where, late_s=round(time.monotonic() - t0, 3),
                        late_writes=st.late_writes - before)
        out = self._outage
        if out is not None:
            self._outage = None
            self._event("plc_connected", plc=self.where, outage_s=round(time.monotonic() - out.t0, 3),
                        cause=out.cause, superseded=st.superseded - out.superseded,
                        failures=st.failures - out.failures, attempts=st.connect_attempts - out.attempts,
                        exceptions=_by_code(st.exceptions, out.exceptions))
        elif not self._ever_written:
            self._event("plc_connected", plc=self.where, outage_s=0.0, cause="-", superseded=0, failures=0,
                        attempts=st.connect_attempts, exceptions="-")
        self._ever_written = True

    def _disconnect(self) -> None:
        with self._cond:  # no inline send into a connection being closed
            self.connected = False
        self.master.close()

    def _flushing(self) -> bool:
        """Stopping, but the last image (``bridge offline``) is not written yet."""
        return self._pending is not None and time.monotonic() < self._flush_until

    def _fail(self, exc: ModbusFault, item: tuple[list[int], bool, float] | None) -> None:
        st = self.stats
        starts = self._outage is None
        if starts:  # the counts before this failure, for the outage's end
            st.outages += 1
            self._outage = _Outage(time.monotonic(), exc.kind, st.superseded, st.failures,
                                   st.connect_attempts - (0 if self.connected else 1), dict(st.exceptions))
        st.failures += 1
        st.last_error = str(exc)
        if exc.kind == "exception":
            st.exceptions[exc.code] += 1
        elif exc.kind == "timeout":
            st.timeouts += 1
        if item is not None:
            with self._cond:  # keep it: the next connection writes it first
                if self._pending is None:
                    self._pending = item
                else:
                    st.superseded += 1  # a newer image came meanwhile, and goes first
        if starts:
            self._event("plc_unreachable", "warning", plc=self.where, cause=exc.kind, error=str(exc),
                        exception=exc.code)
        # An exception reply comes over a working connection; so does a timeout on a
        # serial line.  Anything else leaves a TCP connection in an unknown state.
        if exc.kind == "connection" or (exc.kind != "exception" and self.serial is None):
            self._disconnect()

    def _backoff(self) -> None:
        """Wait after a failure, the delay doubling up to ``backoff_max_s``.  An offer
        does not end the wait (it only replaces the pending image); a stop does, once,
        so that the offline image is tried at once."""
        wait = self._delay * (1.0 - JITTER * self._random.random())
        self._delay = min(self._delay * 2, self.settings.backoff_max_s)
        deadline = time.monotonic() + wait
        with self._cond:
            stopping = self._stop
            while True:
                if self._stop and not stopping:
                    return
                end = min(deadline, self._flush_until) if self._stop else deadline
                left = end - time.monotonic()
                if left <= 0:
                    return
                self._cond.wait(left)

    def _poll_commands(self) -> None:
        """Read the PLC's commands.  A PLC that accepts the image but answers the read
        with an exception (no COMMAND/ENABLE in its map) is no outage: the refusal is
        counted, logged once, and the reads back off as writes do."""
        self._optional(self._commands, self._read_commands)

    def _optional(self, req: _Optional, call: Callable[[], None]) -> bool:
        """``call`` (a request of ``req``'s); False when the PLC refused it."""
        st = self.stats
        try:
            call()
        except ModbusFault as exc:
            if exc.kind != "exception":
                raise
            st.exceptions[exc.code] += 1
            setattr(st, req.refused, getattr(st, req.refused) + 1)
            if req.delay is None:
                req.delay = self.settings.backoff_s
                self._event(req.refused_event, "warning", plc=self.where, exception=exc.code, error=str(exc))
            req.after = time.monotonic() + req.delay
            req.delay = min(2 * req.delay, self.settings.backoff_max_s)
            return False
        if req.delay is not None:
            req.delay = None
            self._event(req.answered_event, plc=self.where, refused=getattr(st, req.refused))
        return True

    def _urgent_tail(self) -> None:
        """The scores right after an urgent image (unless the PLC refuses them and the
        back-off has not run out): the PLC reads the scores of the state change."""
        if self._tail and self._scores.due():
            self._write_tail()

    def _write_tail(self) -> None:
        """Write the newest SCORE_A..SCORE_B.  A PLC that takes the image but answers
        this write with an exception (a map that ends at ENABLE) is no outage: as for
        the command reads, the refusal is counted, logged once, and retried with back-off."""
        with self._cond:
            tail = list(self._tail)
        at = self.settings.base_address + TAIL_AT
        if self._optional(self._scores, lambda: self.master.write_registers(at, tail)):
            self.stats.score_writes += 1

    def _read_commands(self) -> None:
        s = self.settings
        at = s.base_address + REG["COMMAND"].offset
        command, enable = self.master.read_holding(at, 2)
        try:
            cmds = parse_register_write(REG["ENABLE"].offset, [enable])
        except Refused as exc:
            cmds = []  # ENABLE is the PLC's level: ignored, detection stays as it was
            self._refused("enable", enable, exc)
        if command == CMD_REFUSED:
            command = 0  # our refusal, not yet overwritten: nothing new
        answer = 0  # the handshake: done
        if command:
            try:
                cmds = parse_register_write(REG["COMMAND"].offset, [command]) + cmds
            except Refused as exc:
                answer = CMD_REFUSED  # not "done": nothing of it was done
                self._refused("command", command, exc)
        for c in cmds:
            self.commands.put(c)
        if command:
            self.master.write_registers(at, [answer])

    def _refused(self, register: str, value: int, exc: Refused) -> None:
        """A COMMAND or ENABLE value read that the bridge refuses: counted, logged."""
        field_name = f"{register}_values_refused"
        setattr(self.stats, field_name, getattr(self.stats, field_name) + 1)
        held = self._refusals.passes(register)
        if held is not None:
            self._event(f"plc_{register}_refused", "warning", plc=self.where, value=value, error=str(exc),
                        refused=getattr(self.stats, field_name), held_back=held)

    def drain(self, timeout_s: float = 0.5) -> bool:
        # Polled: the writer's thread does not signal a write, and this is asked only at
        # a source's failure, where a few milliseconds do not matter.
        deadline = time.monotonic() + timeout_s
        while not self.flushed:
            if time.monotonic() >= deadline or not self.connected or self._stop:
                return self.flushed
            time.sleep(0.002)
        return True

    def flush(self, timeout_s: float = 1.0) -> bool:
        """Stop the writer once the pending image is written (or ``timeout_s`` passed)."""
        self.stop(timeout_s)
        return self.flushed

    def _close(self) -> None:
        self.stop()

    def stop(self, flush_s: float = 1.0) -> None:
        """Stop the writer; an image still pending (the bridge's last, "offline") is
        written first if the PLC answers within ``flush_s``."""
        with self._cond:
            self._stop = True
            self._flush_until = time.monotonic() + flush_s
            self._cond.notify_all()
        if self._thread is not None:
            self._thread.join(timeout=flush_s + 5)
        self.master.close()

    @property
    def flushed(self) -> bool:
        """Nothing offered is left unwritten."""
        with self._cond:
            return self._pending is None and self._outstanding is None

    def last_written(self) -> tuple[list[int], tuple[int, ...], bool] | None:
        """The image the writer last wrote, its SCORE_A..SCORE_B, and whether the PLC
        acknowledged it: the newest acknowledged image while the PLC answers, else
        (never written, or in an outage) the newest image waiting to be written, not
        acknowledged.  Plain reads (any thread; the writer's lock is not taken)."""
        last, tail = self._last, self._tail
        if last is not None and self._outage is None:
            return last, tail, True
        sent, pending = self._outstanding, self._pending
        image = sent[1] if sent is not None else (pending[0] if pending is not None else last)
        return None if image is None else (image, tail, False)

    @property
    def in_outage(self) -> bool:
        """A failure since the last acknowledged write."""
        return self._outage is not None

    def health(self) -> SinkHealth:
        return SinkHealth(self.connected and self._outage is None, self.stats.failures, self.stats.last_error)

    def counters(self) -> dict[str, int]:
        st = self.stats
        exceptions = sorted(list(st.exceptions.items()))
        out = {"plc_writes": st.writes, "plc_late_writes": st.late_writes, "plc_write_failures": st.failures,
               "plc_write_timeouts": st.timeouts, "plc_exceptions": sum(n for _, n in exceptions),
               "plc_connects": st.connects, "plc_connect_attempts": st.connect_attempts, "plc_outages": st.outages,
               "plc_superseded": st.superseded, "plc_sent_inline": st.sent_inline,
               "plc_command_reads_refused": st.command_reads_refused, "plc_score_writes": st.score_writes,
               "plc_score_writes_refused": st.score_writes_refused,
               "plc_command_values_refused": st.command_values_refused,
               "plc_enable_values_refused": st.enable_values_refused}
        out.update((f"plc_exception_{code:02d}", n) for code, n in exceptions)
        return out
