"""A Modbus serial line, pure: its settings, and how long one transaction takes on it."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal


@dataclass(frozen=True)
class SerialSettings:
    port: str
    baudrate: int = 115200
    parity: Literal["N", "E", "O"] = "N"
    stopbits: int = 1


def rtu_transaction_s(count: int, baudrate: int, bits_per_char: int = 11) -> float:
    """The theoretical time of one read of ``count`` registers: an 8-byte request, a
    5 + 2·count byte response, each preceded by the 3.5-character silence (1.75 ms
    fixed above 19200 baud, as the Modbus serial line specification says)."""
    chars = 8 + 5 + 2 * count
    char_s = bits_per_char / baudrate
    gap = 1.75e-3 if baudrate > 19200 else 3.5 * char_s
    return chars * char_s + 2 * gap
