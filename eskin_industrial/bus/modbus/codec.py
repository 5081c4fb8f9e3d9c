"""Pure Modbus pieces, no I/O: the exception codes, and the sensor node's scan register codec.

The node keeps its newest scan in ``taxels x words`` registers from the profile's
``[modbus.node] start_address`` (input registers for function 4, holding registers
for function 3), row-major, each the calibration's raw value as ``value_type``;
with ``counter_register`` the node's scan counter comes first.  The RTU source and
the node simulator share :func:`encode_scan` / :func:`decode_scans`.
"""

from __future__ import annotations

import numpy as np

from ...profile import ModbusNodeSection

#: Modbus exception codes (the protocol's own numbers), for every handler and check.
ILLEGAL_FUNCTION = 1
ILLEGAL_ADDRESS = 2
ILLEGAL_VALUE = 3
DEVICE_FAILURE = 4

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
    v &= 0xFFFFFFFF
    hi_w, lo_w = v >> 16, v & 0xFFFF
    pair = np.stack([hi_w, lo_w] if node.word_order == "big" else [lo_w, hi_w], axis=-1)
    return pair.reshape(-1).tolist()


def decode_scans(node: ModbusNodeSection, registers) -> np.ndarray:
    """Raw values (float) from registers of one scan, shape ``(taxels,)``; or of many,
    ``(..., registers)``."""
    r = np.asarray(registers, dtype=np.int64)
    if node.words_per_taxel == 2:
        r = r.reshape(*r.shape[:-1], -1, 2)
        hi, lo = (r[..., 0], r[..., 1]) if node.word_order == "big" else (r[..., 1], r[..., 0])
        v = (hi << 16) | lo
        if node.value_type == "int32":
            v = np.where(v >= 1 << 31, v - (1 << 32), v)
    else:
        v = r
        if node.value_type == "int16":
            v = np.where(v >= 1 << 15, v - (1 << 16), v)
    return v.astype(np.float64)


