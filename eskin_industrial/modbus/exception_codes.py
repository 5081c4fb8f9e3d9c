"""Modbus exception codes (Modbus Application Protocol V1.1b3, section 7): the
protocol's own numbers, for every register handler, server and master, and their
names for messages."""

from __future__ import annotations

ILLEGAL_FUNCTION = 1
ILLEGAL_ADDRESS = 2
ILLEGAL_VALUE = 3
DEVICE_FAILURE = 4
#: Gateway target device failed to respond: what a Modbus TCP server answers for a
#: unit id it does not serve.
GATEWAY_TARGET_FAILED = 0x0B

NAMES = {1: "illegal function", 2: "illegal data address", 3: "illegal data value",
         4: "server device failure", 5: "acknowledge", 6: "server device busy", 8: "memory parity error",
         10: "gateway path unavailable", 11: "gateway target device failed to respond"}


def exception_name(code: int) -> str:
    return NAMES.get(code, "unknown exception")
