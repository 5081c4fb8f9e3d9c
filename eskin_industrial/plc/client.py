"""Client mode: the bridge writes the register image into the PLC's holding registers,
over Modbus TCP (TCP_NODELAY) or RTU.

A writer thread owns the connection, so that a slow or absent PLC never stalls
detection: the bridge hands it the newest image (:meth:`PlcWriter.offer`) and goes
on.  The image is written at once when it is urgent (a state change), otherwise
every ``refresh_s``; an older image not yet written is replaced by the newer one
(the PLC wants the present; events survive in the latch and the counters).  After
each refresh the writer reads COMMAND and ENABLE from the PLC, hands their commands
to the bridge, and writes COMMAND back to 0 (the handshake).  A lost connection is
retried with a delay doubling from ``backoff_s`` up to ``backoff_max_s``.

Over TCP, an urgent image offered while the writer is idle is sent by the offering
thread itself (the bridge's loop): the request goes out at once, with no hand-off to
the writer thread, which only collects the answer.  A slow or hung PLC still never
stalls the loop: a send of one small request into an idle connection does not wait,
and while an answer is outstanding the next image waits for the writer as before.
"""

from __future__ import annotations

import collections
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from ..bus.modbus.io import RtuMaster, SerialSettings
from ..bus.modbus.tcp import PipelinedTcpMaster
from ..errors import ModbusFault, Refused
from ..profile import ModbusPlcSection
from ..sinks.base import Publication, Sink, SinkHealth
from .image import REG, Command, parse_register_write


@dataclass
class WriterStats:
    writes: int = 0
    urgent_writes: int = 0
    failures: int = 0
    connects: int = 0
    superseded: int = 0  #: images replaced by a newer one before they were written
    sent_inline: int = 0  #: urgent images sent by the offering thread (no hand-off)
    last_error: str = ""
    #: offer -> acknowledged write (urgent only); the newest ones, so months of
    #: running do not grow it
    latencies_s: collections.deque[float] = field(default_factory=lambda: collections.deque(maxlen=100_000))


class PlcWriter(Sink):
    # A sink of the "plc" output kind, opened by plc.sink.PlcSink: not a subclass of
    # it, so that the two modules do not import each other.
    kind = "plc"

    def __init__(self, settings: ModbusPlcSection, host: str | None = None, port: int | None = None,
                 *, timeout_s: float = 0.5, poll_commands: bool = True, serial: SerialSettings | None = None,
                 on_written: Callable[[float, float], None] | None = None) -> None:
        super().__init__()
        self.settings = settings
        self.host = host or settings.host
        self.port = port or settings.port
        self.serial = serial
        self.master: PipelinedTcpMaster | RtuMaster
        if serial is not None:  # the PLC as a Modbus RTU slave
            self.master = RtuMaster(serial, settings.unit_id, timeout_s)
        else:
            self.master = PipelinedTcpMaster(self.host, self.port, settings.unit_id, timeout_s)
        self.poll_commands = poll_commands
        self.on_written = on_written
        self.stats = WriterStats()
        self.commands: queue.SimpleQueue[Command] = queue.SimpleQueue()
        self._cond = threading.Condition()
        self._pending: tuple[list[int], bool, float] | None = None
        #: An urgent image the offering thread sent: (transaction id, registers, t_event).
        self._outstanding: tuple[int, list[int], float] | None = None
        self._busy = False  #: the writer thread is in a transaction (the connection is its)
        self._inline = isinstance(self.master, PipelinedTcpMaster)
        self._last: list[int] | None = None
        self._stop = False
        self._flush_until = 0.0  #: on stop, an image still pending is written until then
        self._thread: threading.Thread | None = None
        self.connected = False

        if serial is not None:
            self.where = f"rtu {serial.port} at {serial.baudrate} baud, unit {settings.unit_id} (client)"
        else:
            self.where = f"tcp {self.host}:{self.port} (client)"

    def start(self) -> "PlcWriter":
        self._thread = threading.Thread(target=self._run, name="plc-writer", daemon=True)
        self._thread.start()
        return self

    def _publish(self, publication: Publication) -> None:
        self.offer(publication.registers, publication.urgent, publication.t_event)

    def offer(self, registers: list[int], urgent: bool = False, t_event: float | None = None) -> None:
        """Hand over the newest image; ``t_event`` (perf_counter) dates an urgent one."""
        with self._cond:
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
                    self._outstanding = (tid, list(registers), t0)
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
        out = []
        while True:
            try:
                out.append(self.commands.get_nowait())
            except queue.Empty:
                return out

    def _run(self) -> None:
        s = self.settings
        delay = s.backoff_s
        next_refresh = time.monotonic()
        while True:
            with self._cond:
                self._busy = False
                if self._stop and not self._flushing() and self._outstanding is None:
                    break
                timeout = max(0.0, next_refresh - time.monotonic())
                if self._outstanding is None and not (self._pending is not None and self._pending[1]):
                    self._cond.wait(timeout)
                if self._stop and not self._flushing() and self._outstanding is None:
                    break
                self._busy = True
                sent, self._outstanding = self._outstanding, None
                item = None if sent is not None else self._pending
                if sent is None:
                    self._pending = None
            if sent is not None:
                self._collect(sent)
                continue
            if not self.connected:
                try:
                    self.master.connect()
                    self.connected = True
                    self.stats.connects += 1
                    delay = s.backoff_s
                except ModbusFault as exc:
                    self._fail(exc, item)
                    self._sleep(delay)
                    delay = min(delay * 2, s.backoff_max_s)
                    continue
            registers = item[0] if item is not None else self._last
            urgent = item is not None and item[1]
            try:
                if registers is not None:
                    self.master.write_registers(s.base_address, registers)
                    self._written(registers, item[2] if urgent and item is not None else None)
                if time.monotonic() >= next_refresh:
                    next_refresh = time.monotonic() + s.refresh_s
                    if self.poll_commands:
                        self._read_commands()
            except ModbusFault as exc:
                self._fail(exc, item)
                if exc.kind == "connection" or (exc.kind != "exception" and self.serial is None):
                    self._disconnect()
            except Exception as exc:  # noqa: BLE001 - the writer must outlive any one failure
                self._fail(ModbusFault("connection", f"{type(exc).__name__}: {exc}"), item)
                self._disconnect()

    def _collect(self, sent: tuple[int, list[int], float]) -> None:
        """The answer to an image the offering thread sent."""
        tid, registers, t_event = sent
        try:
            self.master.await_response(tid)  # type: ignore[union-attr]
        except ModbusFault as exc:
            self._fail(exc, (registers, True, t_event))  # written again once the PLC answers
            if exc.kind != "exception":
                self._disconnect()
            return
        self._written(registers, t_event)

    def _written(self, registers: list[int], t_event: float | None) -> None:
        """A write the PLC acknowledged; ``t_event`` dates an urgent one."""
        t_ack = time.perf_counter()
        self._last = registers
        self.stats.writes += 1
        if t_event is not None:
            self.stats.urgent_writes += 1
            self.stats.latencies_s.append(t_ack - t_event)
            if self.on_written is not None:
                self.on_written(t_event, t_ack)

    def _disconnect(self) -> None:
        with self._cond:  # no inline send into a connection being closed
            self.connected = False
        self.master.close()

    def _flushing(self) -> bool:
        """Stopping, but the last image (``bridge offline``) is not written yet."""
        return self._pending is not None and time.monotonic() < self._flush_until

    def _fail(self, exc: ModbusFault, item) -> None:
        self.stats.failures += 1
        self.stats.last_error = str(exc)
        if item is not None:
            with self._cond:  # keep it: the next connection writes it first
                if self._pending is None:
                    self._pending = item

    def _sleep(self, delay: float) -> None:
        with self._cond:
            if not self._stop:
                self._cond.wait(delay)
            elif self._flushing():
                self._cond.wait(min(delay, self._flush_until - time.monotonic()))

    def _read_commands(self) -> None:
        s = self.settings
        at = s.base_address + REG["COMMAND"].offset
        command, enable = self.master.read_holding(at, 2)
        try:
            cmds = parse_register_write(REG["ENABLE"].offset, [enable])
            if command:
                cmds = parse_register_write(REG["COMMAND"].offset, [command]) + cmds
        except Refused:
            cmds = []
        for c in cmds:
            self.commands.put(c)
        if command:
            self.master.write_registers(at, [0])

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

    def health(self) -> SinkHealth:
        return SinkHealth(self.connected, self.stats.failures, self.stats.last_error)

    def counters(self) -> dict[str, int]:
        st = self.stats
        return {"plc_writes": st.writes, "plc_write_failures": st.failures, "plc_connects": st.connects,
                "plc_superseded": st.superseded, "plc_sent_inline": st.sent_inline}
