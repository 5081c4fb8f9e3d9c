"""A Modbus TCP master that can send a write without waiting for its answer.

The PLC client's writer thread owns the connection and reads every answer; the
bridge's loop may send an urgent write itself (:meth:`PipelinedTcpMaster.send_write`)
and go on: the PLC gets the new state without a hand-off to the writer thread, and
the writer collects the answer (:meth:`PipelinedTcpMaster.await_response`).  Answers
are matched by transaction id; a late answer to a request given up on is counted and
dropped.  An answer is taken for what it says only if it answers the request sent
under its transaction id: the same function code (an FC3-shaped answer to an FC16
write acknowledges nothing) and, for a write, the same address and count echoed;
anything else is a device that does not speak Modbus as it should, a ``connection``
fault.  The framing is :mod:`.mbap` (pure).
"""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Sequence

from ..errors import DecodeError, ModbusFault
from . import mbap
from .exception_codes import exception_name


class PipelinedTcpMaster:
    def __init__(self, host: str, port: int, unit_id: int = 1, timeout_s: float = 1.0, late_s: float = 0.0) -> None:
        self.host, self.port, self.unit_id, self.timeout_s = host, port, unit_id, timeout_s
        #: An answer up to this long after ``timeout_s`` is still taken (the caller,
        #: who knows when it sent, counts it as late); only then is the request given up.
        self.late_s = late_s
        self.sock: socket.socket | None = None
        self.stale_answers = 0
        self._tid = 0
        self._rx = bytearray()
        self._send_lock = threading.Lock()
        #: What each transaction asked: (function, address, count), until its answer.
        self._asked: dict[int, tuple[int, int, int]] = {}

    @property
    def where(self) -> str:
        return f"{self.host}:{self.port}"

    def connect(self) -> None:
        self.close()
        try:
            sock = socket.create_connection((self.host, self.port), timeout=self.timeout_s)
        except OSError as exc:
            raise ModbusFault("connection", f"cannot connect to {self.where}: {exc}") from None
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.sock = sock
        self._rx.clear()
        self._asked.clear()

    def close(self) -> None:
        sock, self.sock = self.sock, None
        if sock is not None:
            try:
                sock.close()
            except OSError:
                pass

    # -- sending: any thread, never waits for the device ------------------------------
    def send_write(self, address: int, values: Sequence[int]) -> int:
        """Send an FC16 request; returns its transaction id."""
        with self._send_lock:
            self._tid = (self._tid + 1) & 0xFFFF
            tid = self._tid
            self._asked[tid] = (mbap.FC_WRITE_MULTIPLE, address, len(values))
            self._send(mbap.write_request(tid, self.unit_id, address, values))
        return tid

    def send_read(self, address: int, count: int) -> int:
        with self._send_lock:
            self._tid = (self._tid + 1) & 0xFFFF
            tid = self._tid
            self._asked[tid] = (mbap.FC_READ_HOLDING, address, count)
            self._send(mbap.read_request(tid, self.unit_id, address, count))
        return tid

    def _send(self, frame: bytes) -> None:
        sock = self.sock
        if sock is None:
            raise ModbusFault("connection", f"write to {self.where}: not connected")
        try:
            sock.sendall(frame)  # a few dozen bytes into an empty socket buffer: at once
        except OSError as exc:
            raise ModbusFault("connection", f"write to {self.where}: {exc}") from None

    # -- receiving: the owner thread only ----------------------------------------------
    def await_response(self, tid: int, timeout_s: float | None = None) -> mbap.Response:
        """The answer to transaction ``tid`` within ``timeout_s`` (default: the master's)
        plus ``late_s``; ModbusFault ``timeout``, ``connection`` or ``exception`` (with
        its code)."""
        wait = (self.timeout_s if timeout_s is None else timeout_s) + self.late_s
        deadline = time.monotonic() + wait
        while True:
            resp = self._next_frame(deadline, tid, wait)
            asked = self._asked.pop(resp.tid, None)
            if resp.tid != tid:
                self.stale_answers += 1  # the answer to a request given up on
                continue
            if asked is not None:
                self._check(resp, *asked)
            if resp.exception:
                raise ModbusFault("exception", f"{self.where} answered exception {resp.exception:02d} "
                                  f"({exception_name(resp.exception)}) to function {resp.function}",
                                  resp.exception)
            return resp

    def _check(self, resp: mbap.Response, function: int, address: int, count: int) -> None:
        """``resp`` answers the request of its transaction id, else a ``connection`` fault."""
        if resp.function != function:
            raise ModbusFault("connection", f"{self.where} answered function {resp.function} to a function "
                              f"{function} request (transaction {resp.tid})")
        if function == mbap.FC_WRITE_MULTIPLE and not resp.exception and resp.registers != (address, count):
            got_address, got_count = resp.registers
            raise ModbusFault("connection", f"{self.where} acknowledged {got_count} registers at {got_address}, "
                              f"written: {count} at {address} (transaction {resp.tid})")

    def _next_frame(self, deadline: float, tid: int, wait_s: float) -> mbap.Response:
        rx = self._rx
        while True:
            if len(rx) >= mbap.HEADER_BYTES:
                try:
                    need = mbap.frame_length(bytes(rx[:mbap.HEADER_BYTES]))
                except DecodeError as exc:
                    raise ModbusFault("connection", f"{self.where}: {exc}") from None
                if len(rx) >= need:
                    frame = bytes(rx[:need])
                    del rx[:need]
                    try:
                        return mbap.decode_response(frame)
                    except DecodeError as exc:
                        raise ModbusFault("connection", f"{self.where}: {exc}") from None
            sock = self.sock
            if sock is None:
                raise ModbusFault("connection", f"{self.where}: not connected")
            left = deadline - time.monotonic()
            if left <= 0:
                raise ModbusFault("timeout", f"{self.where}: no answer to transaction {tid} within {wait_s:g} s")
            try:
                sock.settimeout(left)
                chunk = sock.recv(4096)
            except TimeoutError:
                continue
            except OSError as exc:
                raise ModbusFault("connection", f"{self.where}: {exc}") from None
            if not chunk:
                raise ModbusFault("connection", f"{self.where}: connection closed by the device")
            rx += chunk

    # -- the blocking calls of a plain master --------------------------------------------
    def write_registers(self, address: int, values: Sequence[int]) -> None:
        self.await_response(self.send_write(address, values))

    def read_holding(self, address: int, count: int) -> list[int]:
        resp = self.await_response(self.send_read(address, count))
        if len(resp.registers) != count:
            raise ModbusFault("connection", f"{self.where}: read {len(resp.registers)} registers, asked {count}")
        return list(resp.registers)
