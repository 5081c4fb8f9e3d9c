"""A PLC stand-in for the client writer's fault tests: a Modbus TCP server on
127.0.0.1, written here with its own framing (not the package's), that behaves as a
PLC can misbehave.  Its ``mode`` can be changed while it runs:

- ``ok``: answers FC16 and FC3 at once, keeps the registers;
- ``reset``: accepts the connection, then resets it (RST) before reading anything;
- ``silent``: accepts and reads, never answers;
- ``late``: answers correctly after ``delay_s``;
- ``exception``: answers every request with exception ``code`` (02, 04, ...);
- ``no-reads``: takes writes, answers reads (FC3) with exception ``code``;
- ``wrong-fc``: answers a write (FC16), without taking it, as if it had been a read
  (FC3 function code and layout), reads correctly;
- ``down``: not listening at all (connections refused), see :meth:`go_down`.

With ``map_size``, a request that reaches past that many registers is answered with
exception ``code`` whatever the mode: a PLC program whose map is shorter.

Everything it sees is counted: connections accepted, requests, and every FC16
write decoded here (time, address, values).
"""

from __future__ import annotations

import socket
import struct
import threading
import time
from dataclasses import dataclass, field

from eskin_industrial.outputs.plc.image import REG


@dataclass
class Seen:
    connects: list[float] = field(default_factory=list)  #: monotonic time of each accepted connection
    requests: int = 0
    reads: int = 0  #: FC3 requests
    #: every FC16 request received: (monotonic, address, values)
    writes: list[tuple[float, int, tuple[int, ...]]] = field(default_factory=list)


class PlcStandIn:
    def __init__(self, mode: str = "ok", *, delay_s: float = 0.6, code: int = 2, port: int = 0,
                 map_size: int | None = None) -> None:
        self.mode, self.delay_s, self.code, self.map_size = mode, delay_s, code, map_size
        self.seen = Seen()
        self.regs = [0] * 2048
        self.regs[REG["ENABLE"].offset] = 1  # the PLC program enables detection (base address 0)
        self.port = port
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._listener: socket.socket | None = None
        self._accepter: threading.Thread | None = None
        self._conns: list[socket.socket] = []

    # -- up and down ------------------------------------------------------------------
    def start(self) -> PlcStandIn:
        sock = socket.socket()
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(("127.0.0.1", self.port))
        sock.listen(16)
        sock.settimeout(0.05)
        self.port = sock.getsockname()[1]
        self._listener = sock
        self._stop.clear()
        self._accepter = threading.Thread(target=self._accept, args=(sock,), daemon=True)
        self._accepter.start()
        return self

    def go_down(self) -> None:
        """Close the listener and every connection: the PLC is gone (refused)."""
        self._stop.set()
        if self._accepter is not None:
            self._accepter.join(5)
        if self._listener is not None:
            self._listener.close()
            self._listener = None
        with self._lock:
            conns, self._conns = self._conns, []
        for c in conns:
            _reset(c)

    def come_back(self) -> None:
        self.start()

    stop = go_down

    def __enter__(self) -> PlcStandIn:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.go_down()

    # -- serving ----------------------------------------------------------------------
    def _accept(self, listener: socket.socket) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = listener.accept()
            except (TimeoutError, OSError):
                continue
            self.seen.connects.append(time.monotonic())
            if self.mode == "reset":
                _reset(conn)
                continue
            with self._lock:
                self._conns.append(conn)
            threading.Thread(target=self._serve, args=(conn,), daemon=True).start()

    def _serve(self, conn: socket.socket) -> None:
        conn.settimeout(0.05)
        buf = b""
        while not self._stop.is_set():
            try:
                chunk = conn.recv(4096)
            except TimeoutError:
                continue
            except OSError:
                return
            if not chunk:
                return
            buf += chunk
            while len(buf) >= 6:
                length = struct.unpack(">H", buf[4:6])[0]
                if len(buf) < 6 + length:
                    break
                frame, buf = buf[:6 + length], buf[6 + length:]
                answer = self._answer(frame)
                if answer is None:
                    continue
                if self.mode == "late":
                    time.sleep(self.delay_s)
                try:
                    conn.sendall(answer)
                except OSError:
                    return

    def _answer(self, frame: bytes) -> bytes | None:
        tid, _proto, _length, unit = struct.unpack(">HHHB", frame[:7])
        pdu = frame[7:]
        fc = pdu[0]
        self.seen.requests += 1
        if fc == 16:
            address, count, _nbytes = struct.unpack(">HHB", pdu[1:6])
            values = struct.unpack(f">{count}H", pdu[6:6 + 2 * count])
            self.seen.writes.append((time.monotonic(), address, values))
        if self.mode == "silent":
            return None
        elif fc == 3:
            self.seen.reads += 1
        past = fc in (3, 16) and self.map_size is not None and sum(struct.unpack(">HH", pdu[1:5])) > self.map_size
        if self.mode == "exception" or (self.mode == "no-reads" and fc == 3) or past:
            body = bytes([fc | 0x80, self.code])
        elif self.mode == "wrong-fc" and fc == 16:
            body = struct.pack(">BBH", 3, 2, 0)
        elif fc == 16:
            self.regs[address:address + count] = values
            body = struct.pack(">BHH", 16, address, count)
        elif fc == 3:
            address, count = struct.unpack(">HH", pdu[1:5])
            body = struct.pack(f">BB{count}H", 3, 2 * count, *self.regs[address:address + count])
        else:
            body = bytes([fc | 0x80, 1])
        return struct.pack(">HHHB", tid, 0, len(body) + 1, unit) + body


def _reset(conn: socket.socket) -> None:
    """Close with an RST, as a PLC that drops the connection does."""
    try:
        conn.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        conn.close()
    except OSError:
        pass
