"""The sensor node's scan register codec, pure: a scan's raw values to registers and
back.

The node keeps its newest scan in ``taxels x words`` registers from the profile's
``[modbus.node] start_address`` (input registers for function 4, holding registers
for function 3), row-major, each the calibration's raw value as ``value_type``;
with ``counter_register`` the node's scan counter comes first.  The RTU source and
the node simulator share :func:`encode_scan` / :func:`decode_scans`; a 32-bit value
is split and joined by the protocol package's word helpers.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ...modbus.words import join32, split32
from ...profile import ModbusNodeSection

_LIMITS = {"uint16": (0, 0xFFFF), "int16": (-0x8000, 0x7FFF), "uint32": (0, 0xFFFFFFFF),
           "int32": (-0x80000000, 0x7FFFFFFF)}


def register_count(node: ModbusNodeSection, taxels: int) -> int:
    """Registers of one scan, the scan counter (if any) included."""
    return taxels * node.words_per_taxel + int(node.counter_register)


def encode_scan(node: ModbusNodeSection, raw: Sequence[float] | np.ndarray) -> list[int]:
    """Registers for one scan of raw values (rounded, clipped to the value type)."""
    lo, hi = _LIMITS[node.value_type]
    v = np.clip(np.rint(np.nan_to_num(np.asarray(raw, dtype=np.float64), nan=0.0)), lo, hi).astype(np.int64)
    if node.words_per_taxel == 1:
        return (v & 0xFFFF).tolist()
    return np.stack(split32(v, node.word_order), axis=-1).reshape(-1).tolist()


def decode_scans(node: ModbusNodeSection, registers: Sequence[int] | np.ndarray) -> np.ndarray:
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
