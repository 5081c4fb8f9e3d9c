"""A Modbus TCP client of plain sockets and hand-built bytes, for the server tests:
no code of the package frames or reads these requests, so the server is checked
against the specification's byte layouts, not against our own encoder."""

from __future__ import annotations

import socket
import struct
import time


def adu(tid: int, unit: int, pdu: bytes) -> bytes:
    """Transaction id, protocol 0, length (unit + PDU), unit id, PDU: big-endian."""
    return struct.pack(">HHHB", tid, 0, len(pdu) + 1, unit) + pdu


def connect(port: int, host: str = "127.0.0.1", source: str | None = None, timeout_s: float = 2.0) -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    try:
        s.settimeout(timeout_s)
        if source is not None:
            s.bind((source, 0))
        s.connect((host, port))
    except OSError:
        s.close()
        raise
    s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    return s


def recv_exact(s: socket.socket, n: int) -> bytes:
    out = b""
    while len(out) < n:
        chunk = s.recv(n - len(out))
        if not chunk:
            raise ConnectionError(f"closed after {len(out)} of {n} bytes")
        out += chunk
    return out


def read_adu(s: socket.socket) -> tuple[int, int, bytes]:
    """(transaction id, unit id, PDU) of the next response."""
    tid, proto, length, unit = struct.unpack(">HHHB", recv_exact(s, 7))
    assert proto == 0
    return tid, unit, recv_exact(s, length - 1)


def ask(s: socket.socket, pdu: bytes, unit: int = 1, tid: int = 7) -> bytes:
    s.sendall(adu(tid, unit, pdu))
    got_tid, got_unit, resp = read_adu(s)
    assert (got_tid, got_unit) == (tid, unit)
    return resp


def read_registers(s: socket.socket, address: int, count: int, fc: int = 3, unit: int = 1) -> list[int]:
    resp = ask(s, struct.pack(">BHH", fc, address, count), unit)
    assert resp[0] == fc, f"exception {resp.hex()}"
    return list(struct.unpack(f">{count}H", resp[2:]))


def closed_by_peer(s: socket.socket, within_s: float = 3.0) -> bool:
    """The server closed (or reset) this connection within ``within_s``."""
    deadline = time.monotonic() + within_s
    while time.monotonic() < deadline:
        s.settimeout(max(deadline - time.monotonic(), 0.01))
        try:
            if s.recv(1) == b"":
                return True
        except (ConnectionResetError, BrokenPipeError):
            return True
        except TimeoutError:
            return False
    return False
