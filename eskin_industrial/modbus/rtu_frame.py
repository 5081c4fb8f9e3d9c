"""Modbus RTU framing, pure: where a request ends, its CRC, a response framed, and
whether a frame is intact (our server's check of a request, and the RTU master's of
an answer, which tells a garbled frame from a timeout).  Layout (Modbus over Serial
Line V1.02, section 2.5.1): unit id (1 byte), the PDU, the CRC-16 (polynomial 0xA001
reflected, initial 0xFFFF), low byte first.

A request's length follows from its function code (and, for 15 and 16, its byte
count), so a frame is found without timing the 3.5-character silence, which a
pseudo-terminal or a USB adapter does not keep anyway: :mod:`.rtu_server` uses the
silence only to drop what cannot be a request.
"""

from __future__ import annotations


def _table() -> list[int]:
    out = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
        out.append(crc)
    return out


_CRC = _table()
#: Request length (unit id and CRC included) of the functions whose length is fixed.
_FIXED = {1: 8, 2: 8, 3: 8, 4: 8, 5: 8, 6: 8, 17: 4, 43: 7}
#: The longest RTU frame (a 253-byte PDU, the unit id, the CRC).
MAX_FRAME = 256


def crc16(data: bytes) -> int:
    crc = 0xFFFF
    for b in data:
        crc = (crc >> 8) ^ _CRC[(crc ^ b) & 0xFF]
    return crc


def frame(unit: int, pdu: bytes) -> bytes:
    body = bytes((unit,)) + pdu
    return body + crc16(body).to_bytes(2, "little")


def intact(data: bytes) -> bool:
    """A whole frame whose CRC matches."""
    return len(data) >= 4 and crc16(data[:-2]) == int.from_bytes(data[-2:], "little")


def request_length(buf: bytes | bytearray) -> int | None:
    """Bytes of the request that starts ``buf``: None while too few bytes have come
    to tell, 0 for a function whose request length is not known here (it ends at
    the next silence)."""
    if len(buf) < 2:
        return None
    fc = buf[1]
    if fc in _FIXED:
        return _FIXED[fc]
    if fc in (15, 16):
        return None if len(buf) < 7 else 9 + buf[6]
    return 0
