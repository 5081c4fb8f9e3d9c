"""A Modbus server's answers, pure: one request PDU in, its response PDU out.

No socket and no framing here: :mod:`.tcp_server` (TCP, MBAP framing from :mod:`.mbap`)
moves the bytes and applies the access policy (who may write, which unit ids).  The
register contents come from a :class:`RegisterHandler`, which decides which
addresses exist and which exception a refused request gets.

Served, as the Modbus Application Protocol Specification V1.1b3 describes them:

- 1 read coils, 2 read discrete inputs, 3 read holding registers, 4 read input
  registers;
- 5 write single coil and 6 write single register (the response echoes the request),
  15 write multiple coils and 16 write multiple registers (the response gives the
  starting address and the quantity);
- 17 report server id (a server id byte, the run indicator 0xFF, then the product's
  name and revision in ASCII);
- 43 / 14 read device identification: the basic objects (vendor name, product code,
  revision) and the regular ones (vendor URL, product name, model name), by stream
  (read codes 1, 2, 3) or one at a time (code 4); conformity level 0x82.

Anything else is answered with exception 01 (ILLEGAL FUNCTION); a quantity out of the
specification's range or a malformed request with 03 (ILLEGAL DATA VALUE).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Literal, Protocol

from .exception_codes import ILLEGAL_ADDRESS, ILLEGAL_FUNCTION, ILLEGAL_VALUE

Table = Literal["coils", "discrete", "holding", "input"]

READ_COILS, READ_DISCRETE, READ_HOLDING, READ_INPUT = 1, 2, 3, 4
WRITE_COIL, WRITE_REGISTER, WRITE_COILS, WRITE_REGISTERS = 5, 6, 15, 16
REPORT_SERVER_ID = 17
ENCAPSULATED = 43
MEI_DEVICE_ID = 0x0E
#: The function codes that change something: refused as a whole by a read-only policy.
WRITES = frozenset({WRITE_COIL, WRITE_REGISTER, WRITE_COILS, WRITE_REGISTERS})

_TABLE: dict[int, Table] = {READ_COILS: "coils", READ_DISCRETE: "discrete", READ_HOLDING: "holding",
                            READ_INPUT: "input"}
#: Quantity limits of the specification (section 6): bits, registers.
_MAX_READ = {READ_COILS: 2000, READ_DISCRETE: 2000, READ_HOLDING: 125, READ_INPUT: 125}
_MAX_WRITE_COILS = 1968
_MAX_WRITE_REGISTERS = 123


class RegisterHandler(Protocol):
    """What a served device answers.  Called on the server's thread: keep them short.

    Return the values, or a Modbus exception code (an int) to refuse."""

    def read(self, table: Table, address: int, count: int) -> list[int] | list[bool] | int: ...

    def write(self, table: Table, address: int, values: list[int] | list[bool]) -> int | None: ...


@dataclass(frozen=True)
class Identity:
    """The device identification objects (FC43/14), in object id order 0 .. 5."""

    vendor_name: str
    product_code: str
    revision: str
    vendor_url: str = ""
    product_name: str = ""
    model_name: str = ""

    def objects(self) -> list[tuple[int, bytes]]:
        """(object id, value) of every object given; the three basic ones always."""
        values = (self.vendor_name, self.product_code, self.revision, self.vendor_url, self.product_name,
                  self.model_name)
        return [(i, v.encode("ascii", "replace")[:_MAX_OBJECT]) for i, v in enumerate(values) if v or i < 3]

    def server_id(self) -> bytes:
        """The additional data of FC17: the product and its revision."""
        name = self.product_name or self.product_code
        return f"{self.vendor_name} {name} {self.revision}".encode("ascii", "replace")[:_MAX_OBJECT]


#: A value longer than this is cut: one object always fits in a response.
_MAX_OBJECT = 200
#: A PDU is at most 253 bytes.
_MAX_PDU = 253
#: Conformity level: regular identification, stream and individual access.
CONFORMITY = 0x82


def exception(function: int, code: int) -> bytes:
    return bytes((function | 0x80, code))


def handle(pdu: bytes, handler: RegisterHandler, identity: Identity, server_id: int = 1) -> bytes:
    """The response PDU to ``pdu`` (never raises for any bytes)."""
    if not pdu:
        return exception(0, ILLEGAL_FUNCTION)
    fc = pdu[0]
    if fc in _TABLE:
        return _read(fc, pdu, handler)
    if fc == WRITE_COIL:
        if len(pdu) != 5:
            return exception(fc, ILLEGAL_VALUE)
        address, value = struct.unpack(">HH", pdu[1:5])
        if value not in (0x0000, 0xFF00):
            return exception(fc, ILLEGAL_VALUE)
        return _written(fc, handler.write("coils", address, [value == 0xFF00]), pdu)
    if fc == WRITE_REGISTER:
        if len(pdu) != 5:
            return exception(fc, ILLEGAL_VALUE)
        address, value = struct.unpack(">HH", pdu[1:5])
        return _written(fc, handler.write("holding", address, [value]), pdu)
    if fc == WRITE_COILS:
        if len(pdu) < 6:
            return exception(fc, ILLEGAL_VALUE)
        address, count, nbytes = struct.unpack(">HHB", pdu[1:6])
        if not 1 <= count <= _MAX_WRITE_COILS or nbytes != (count + 7) // 8 or len(pdu) != 6 + nbytes:
            return exception(fc, ILLEGAL_VALUE)
        bits = [bool(pdu[6 + i // 8] >> (i % 8) & 1) for i in range(count)]
        return _written(fc, handler.write("coils", address, bits), pdu[:5])
    if fc == WRITE_REGISTERS:
        if len(pdu) < 6:
            return exception(fc, ILLEGAL_VALUE)
        address, count, nbytes = struct.unpack(">HHB", pdu[1:6])
        if not 1 <= count <= _MAX_WRITE_REGISTERS or nbytes != 2 * count or len(pdu) != 6 + nbytes:
            return exception(fc, ILLEGAL_VALUE)
        values = list(struct.unpack(f">{count}H", pdu[6:]))
        return _written(fc, handler.write("holding", address, values), pdu[:5])
    if fc == REPORT_SERVER_ID:
        if len(pdu) != 1:
            return exception(fc, ILLEGAL_VALUE)
        data = bytes((server_id & 0xFF, 0xFF)) + identity.server_id()  # 0xFF: running
        return bytes((fc, len(data))) + data
    if fc == ENCAPSULATED and len(pdu) >= 2 and pdu[1] == MEI_DEVICE_ID:
        return _device_id(pdu, identity)
    return exception(fc, ILLEGAL_FUNCTION)


def _read(fc: int, pdu: bytes, handler: RegisterHandler) -> bytes:
    if len(pdu) != 5:
        return exception(fc, ILLEGAL_VALUE)
    address, count = struct.unpack(">HH", pdu[1:5])
    if not 1 <= count <= _MAX_READ[fc]:
        return exception(fc, ILLEGAL_VALUE)
    if address + count > 0x10000:
        return exception(fc, ILLEGAL_ADDRESS)
    values = handler.read(_TABLE[fc], address, count)
    if isinstance(values, int):
        return exception(fc, values)
    if len(values) != count:  # a handler's bug, not the client's: no partial answer
        return exception(fc, ILLEGAL_ADDRESS)
    if fc in (READ_COILS, READ_DISCRETE):
        packed = bytearray((count + 7) // 8)
        for i, v in enumerate(values):
            if v:
                packed[i // 8] |= 1 << (i % 8)
        return bytes((fc, len(packed))) + bytes(packed)
    return bytes((fc, 2 * count)) + struct.pack(f">{count}H", *(int(v) & 0xFFFF for v in values))


def _written(fc: int, result: int | None, echo: bytes) -> bytes:
    """FC5 / FC6: the request itself; FC15 / FC16: function, address and quantity."""
    return echo if result is None else exception(fc, result)


def _device_id(pdu: bytes, identity: Identity) -> bytes:
    fc = ENCAPSULATED
    if len(pdu) != 4:
        return exception(fc, ILLEGAL_VALUE)
    code, first = pdu[2], pdu[3]
    objects = identity.objects()
    ids = [i for i, _ in objects]
    if code == 4:  # one object
        if first not in ids:
            return exception(fc, ILLEGAL_ADDRESS)
        chosen = [o for o in objects if o[0] == first]
    elif code in (1, 2, 3):
        # 1: basic (0 .. 2); 2: regular (up to 0x7F); 3: extended (none here: as 2).
        in_category = [o for o in objects if code == 1 and o[0] < 3 or code != 1]
        if first not in [i for i, _ in in_category]:
            first = 0  # the specification: an unknown object id restarts the stream
        chosen = [o for o in in_category if o[0] >= first]
    else:
        return exception(fc, ILLEGAL_VALUE)
    body, n, more, next_id = b"", 0, 0x00, 0x00
    for i, v in chosen:
        item = bytes((i, len(v))) + v
        if 7 + len(body) + len(item) > _MAX_PDU:  # the rest in a further transaction
            more, next_id = 0xFF, i
            break
        body, n = body + item, n + 1
    return bytes((fc, MEI_DEVICE_ID, code, CONFORMITY, more, next_id, n)) + body
