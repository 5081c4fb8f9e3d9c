"""A Modbus RTU server of our own (a slave on a serial line), on a background thread:
the same PDU handler as the TCP server (:mod:`.pdu`), the frames found by
:mod:`.rtu_frame` (pure); this module moves the bytes.

- A request for our unit id is answered; one for another unit id is left to that
  device (silence: the line is shared); unit id 0 (broadcast) is acted on and never
  answered, as the serial line specification says.
- A frame whose CRC fails is counted and skipped byte by byte until a request with a
  good CRC starts; bytes that make no request before a silence are dropped and counted.
- ``read_only``: every write is answered with exception 01 (ILLEGAL FUNCTION).
- A serial port that fails (a USB adapter pulled out) is logged, rate-limited, and
  opened again every :data:`REOPEN_S` until it comes back.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass
from typing import Any

from ..errors import TransportError
from . import pdu, rtu_frame
from .exception_codes import ILLEGAL_FUNCTION
from .serial_line import SerialSettings
from .serving import RateLimitedLog, answer

#: After a failure of the port, how long before opening it again.
REOPEN_S = 0.5
#: A silence this long ends whatever came before it (at least 3.5 characters).
MIN_SILENCE_S = 0.02


@dataclass
class RtuServerCounters:
    requests: int = 0  #: for our unit id (or broadcast)
    other_units: int = 0  #: for another device on the line: left unanswered
    crc_errors: int = 0
    dropped_bytes: int = 0  #: before a silence, making no request
    denied_writes: int = 0
    handler_errors: int = 0
    serial_errors: int = 0

    def as_dict(self) -> dict[str, int]:
        return {f"modbus_{k}": v for k, v in vars(self).items()}


class RtuServer:
    """Serves ``handler`` as unit ``unit_id`` on a serial line; ``start()`` returns
    once the port is open."""

    def __init__(self, handler: pdu.RegisterHandler, serial: SerialSettings, unit_id: int, identity: pdu.Identity,
                 read_only: bool = False) -> None:
        self.handler = handler
        self.settings = serial
        self.unit_id = unit_id
        self.identity = identity
        self.read_only = read_only
        self.counters = RtuServerCounters()
        self.log = RateLimitedLog(logging.getLogger(__name__))
        char_s = 11 / serial.baudrate
        self.silence_s = max(3.5 * char_s, MIN_SILENCE_S)
        self._port: Any = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def where(self) -> str:
        return f"rtu {self.settings.port} at {self.settings.baudrate} baud"

    def _open(self) -> Any:
        import serial  # pyserial

        s = self.settings
        return serial.Serial(s.port, s.baudrate, parity=s.parity, stopbits=s.stopbits, timeout=self.silence_s)

    def start(self) -> RtuServer:
        try:
            self._port = self._open()
        except (OSError, ValueError) as exc:  # serial.SerialException is an OSError
            # a transport that cannot be opened: exit 3, as the bridge's serial line
            raise TransportError(f"cannot open serial port {self.settings.port}: {exc}") from None
        self._thread = threading.Thread(target=self._run, name="modbus-rtu-server", daemon=True)
        self._thread.start()
        return self

    def _run(self) -> None:
        buf = bytearray()
        while not self._stop.is_set():
            port = self._port
            try:
                if port is None:
                    port = self._port = self._open()
                chunk = port.read(max(port.in_waiting, 1))
            except (OSError, ValueError, TypeError) as exc:  # a port gone away: closed, then opened again
                self.counters.serial_errors += 1
                self.log.event("modbus_serial_error", level=logging.ERROR, port=self.settings.port,
                               error=f"{type(exc).__name__}: {exc}")
                self._close_port()
                buf.clear()
                self._stop.wait(REOPEN_S)
                continue
            if not chunk:  # a silence: what is left can be no request but one of unknown length
                if buf:
                    self._at_silence(bytes(buf))
                    buf.clear()
                continue
            buf += chunk
            self._take(buf)

    def _take(self, buf: bytearray) -> None:
        """Answer every whole request at the start of ``buf``, and remove it."""
        while buf:
            n = rtu_frame.request_length(buf)
            if n is None or n == 0 or len(buf) < n:
                if len(buf) > rtu_frame.MAX_FRAME:  # no request is that long: drop a byte, look again
                    del buf[:1]
                    self.counters.dropped_bytes += 1
                    continue
                return
            request = bytes(buf[:n])
            if not rtu_frame.intact(request):
                self.counters.crc_errors += 1
                del buf[:1]  # a request may start at the next byte
                continue
            del buf[:n]
            self._answer(request)

    def _at_silence(self, data: bytes) -> None:
        """What came before a silence and made no whole request: a request of a
        function we do not serve, framed by the silence (answered: exception 01), or
        bytes to drop, one at a time, answering any request found behind them."""
        buf = bytearray(data)
        while buf:
            if rtu_frame.request_length(buf) == 0 and rtu_frame.intact(bytes(buf)):
                self._answer(bytes(buf))
                return
            del buf[:1]
            self.counters.dropped_bytes += 1
            self._take(buf)

    def _answer(self, request: bytes) -> None:
        unit, req = request[0], request[1:-2]
        if unit not in (self.unit_id, 0):
            self.counters.other_units += 1
            return
        c = self.counters
        c.requests += 1
        fc = req[0]
        if self.read_only and fc in pdu.WRITES:
            c.denied_writes += 1
            self.log.event("modbus_write_denied", port=self.settings.port, function=fc, reason="read_only")
            resp = pdu.exception(fc, ILLEGAL_FUNCTION)
        else:
            resp = answer(req, self.handler, self.identity, self.unit_id, self.log, c)
        if unit == 0:
            return  # broadcast: acted on, never answered
        port = self._port
        if port is not None:
            try:
                port.write(rtu_frame.frame(unit, resp))
            except (OSError, ValueError) as exc:
                c.serial_errors += 1
                self.log.event("modbus_serial_error", level=logging.ERROR, port=self.settings.port,
                               error=f"{type(exc).__name__}: {exc}")

    def _close_port(self) -> None:
        port, self._port = self._port, None
        if port is not None:
            try:
                port.close()
            except (OSError, ValueError):
                pass

    def stop(self) -> None:
        """Stop serving and close the port; safe to call twice."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
            self._thread = None
        self._close_port()

    def __enter__(self) -> RtuServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
