"""Pure Modbus pieces, no I/O: the exception codes, the 32-bit word split, and the
sensor node's scan register codec.

The node keeps its newest scan in ``taxels x words`` registers from the profile's
``[modbus.node] start_address`` (input registers for function 4, holding registers
for function 3), row-major, each the calibration's raw value as ``value_type``;
with ``counter_register`` the node's scan counter comes first.  The RTU source and
the node simulator share :func:`encode_scan` / :func:`decode_scans`.

:func:`split32` / :func:`join32` are the one place a 32-bit value meets two
registers: the scan codec and the PLC register image (``plc/image.py``) both use them.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal, TypeVar

import numpy as np

from ...profile import ModbusNodeSection

#: Modbus exception codes (the protocol's own numbers), for every handler and check.
ILLEGAL_FUNCTION = 1
ILLEGAL_ADDRESS = 2
ILLEGAL_VALUE = 3
DEVICE_FAILURE = 4

WordOrder = Literal["big", "little"]

#: An int, or an int64 array for a whole scan at once: the same shifts and masks serve both.
W = TypeVar("W", int, np.ndarray)


def split32(value: W, word_order: WordOrder) -> list[W]:
    """The two registers of a 32-bit value, in ``word_order`` ("big": high word
    first); bits above 32 are dropped, a negative value is two's complement."""
    value = value & 0xFFFFFFFF
    hi, lo = value >> 16, value & 0xFFFF
    return [hi, lo] if word_order == "big" else [lo, hi]


def join32(words: Sequence[W], word_order: WordOrder) -> W:
    """The unsigned 32-bit value of two registers in ``word_order`` (the inverse of
    :func:`split32` for 0 .. 2**32 - 1)."""
    hi, lo = (words[0], words[1]) if word_order == "big" else (words[1], words[0])
    return (hi << 16) | lo


_LIMITS = {"uint16": (0, 0xFFFF), "int16": (-0x8000, 0x7FFF), "uint32": (0, 0xFFFFFFFF),
           "int32": (-0x80000000, 0x7FFFFFFF)}


def register_count(node: ModbusNodeSection, taxels: int) -> int:
    """Registers of one scan, the scan counter (if any) included."""
    return taxels * node.words_per_taxel + int(node.counter_register)


def encode_scan(node: ModbusNodeSection, raw: np.ndarray) -> list[int]:
    """Registers for one scan of raw values (rounded, clipped to the value type)."""
    lo, hi = _LIMITS[node.value_type]
    v = np.clip(np.rint(np.nan_to_num(np.asarray(raw, dtype=np.float64), nan=0.0)), lo, hi).astype(np.int64)
    if node.words_per_taxel == 1:
        return (v & 0xFFFF).tolist()
    return np.stack(split32(v, node.word_order), axis=-1).reshape(-1).tolist()


def decode_scans(node: ModbusNodeSection, registers) -> np.ndarray:
    """Raw values (float) from registers of one scan, shape ``(taxels,)``; or of many,
    ``(..., registers)``."""
    r = np.asarray(registers, dtype=np.int64)
    if node.words_per_taxel == 2:
        pairs = r.reshape(*r.shape[:-1], -1, 2)
        v = join32((pairs[..., 0], pairs[..., 1]), node.word_order)
        if node.value_type == "int32":
            v = np.where(v >= 1 << 31, v - (1 << 32), v)
    else:
        v = r
        if node.value_type == "int16":
            v = np.where(v >= 1 << 15, v - (1 << 16), v)
    return v.astype(np.float64)


