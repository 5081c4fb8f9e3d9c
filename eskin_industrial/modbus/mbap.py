"""Modbus TCP framing (MBAP), pure: requests to bytes, bytes to responses.

The client side: what the PLC client sends, write multiple registers (FC16) and read
holding registers (FC3), and their answers, including exception responses.  The
server side (:mod:`.tcp_server`): a request frame split into its header and PDU
(:func:`split_request`), and a response framed (:func:`frame`).  No socket here:
:mod:`.tcp_master` and :mod:`.tcp_server` move the bytes.  Layout (Modbus Messaging
on TCP/IP, section 3.1.3): transaction id (2 bytes), protocol id 0 (2), length of
what follows (2), unit id (1), then the PDU; big-endian.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from typing import NamedTuple

from ..errors import DecodeError

HEADER = struct.Struct(">HHHB")
HEADER_BYTES = HEADER.size  # 7
FC_READ_HOLDING = 3
FC_WRITE_MULTIPLE = 16
#: The longest PDU the protocol allows (253 bytes), hence the longest frame.
MAX_PDU = 253
MAX_WRITE = 123  #: registers in one FC16 request
MAX_READ = 125  #: registers in one FC3 response


class Response(NamedTuple):
    tid: int
    unit: int
    function: int  #: the request's function code (without the exception bit)
    exception: int  #: 0, or the exception code the device answered with
    registers: tuple[int, ...]  #: FC3: the values read; FC16: (address, count) echoed


def write_request(tid: int, unit: int, address: int, values: Sequence[int]) -> bytes:
    """FC16: write ``values`` (each 0..65535) from ``address``."""
    n = len(values)
    if not 1 <= n <= MAX_WRITE:
        raise ValueError(f"write of {n} registers: expected 1 to {MAX_WRITE}")
    pdu = struct.pack(f">BHHB{n}H", FC_WRITE_MULTIPLE, address, n, 2 * n, *values)
    return HEADER.pack(tid & 0xFFFF, 0, len(pdu) + 1, unit) + pdu


def read_request(tid: int, unit: int, address: int, count: int) -> bytes:
    """FC3: read ``count`` holding registers from ``address``."""
    if not 1 <= count <= MAX_READ:
        raise ValueError(f"read of {count} registers: expected 1 to {MAX_READ}")
    pdu = struct.pack(">BHH", FC_READ_HOLDING, address, count)
    return HEADER.pack(tid & 0xFFFF, 0, len(pdu) + 1, unit) + pdu


def frame_length(header: bytes) -> int:
    """Bytes of the whole frame whose first :data:`HEADER_BYTES` are ``header``;
    :class:`DecodeError` for a header no Modbus TCP device sends."""
    _tid, proto, length, _unit = HEADER.unpack(header[:HEADER_BYTES])
    if proto != 0 or not 2 <= length <= MAX_PDU + 1:
        raise DecodeError(f"not a Modbus TCP frame (protocol {proto}, length {length})")
    return HEADER_BYTES - 1 + length


def decode_response(frame: bytes) -> Response:
    """One whole response frame (see :func:`frame_length`)."""
    tid, _proto, length, unit = HEADER.unpack(frame[:HEADER_BYTES])
    pdu = frame[HEADER_BYTES:HEADER_BYTES - 1 + length]
    if len(pdu) != length - 1 or not pdu:
        raise DecodeError(f"transaction {tid}: truncated frame")
    fc = pdu[0]
    if fc & 0x80:
        if len(pdu) != 2:
            raise DecodeError(f"transaction {tid}: exception response of {len(pdu)} bytes")
        return Response(tid, unit, fc & 0x7F, pdu[1], ())
    if fc == FC_WRITE_MULTIPLE:
        if len(pdu) != 5:
            raise DecodeError(f"transaction {tid}: write response of {len(pdu)} bytes")
        return Response(tid, unit, fc, 0, struct.unpack(">HH", pdu[1:5]))
    if fc == FC_READ_HOLDING:
        if len(pdu) < 2 or pdu[1] != len(pdu) - 2 or pdu[1] % 2:
            raise DecodeError(f"transaction {tid}: read response with a bad byte count")
        n = pdu[1] // 2
        return Response(tid, unit, fc, 0, struct.unpack(f">{n}H", pdu[2:]))
    raise DecodeError(f"transaction {tid}: unexpected function code {fc}")


def split_request(frame: bytes) -> tuple[int, int, bytes]:
    """Transaction id, unit id and PDU of one whole request frame (its length from
    :func:`frame_length`)."""
    tid, _proto, _length, unit = HEADER.unpack(frame[:HEADER_BYTES])
    return tid, unit, frame[HEADER_BYTES:]


def frame(tid: int, unit: int, pdu: bytes) -> bytes:
    """A frame carrying ``pdu`` (a response: the request's transaction and unit id)."""
    return HEADER.pack(tid & 0xFFFF, 0, len(pdu) + 1, unit) + pdu
