"""A 32-bit value in two 16-bit registers, pure.

Modbus registers are 16 bits; the protocol says nothing of wider values, so each
device chooses which word comes first (``word_order``).  :func:`split32` /
:func:`join32` are the one place a 32-bit value meets two registers: the sensor
node's scan codec (``bus/modbus/codec.py``) and the PLC register image
(``outputs/plc/image.py``) both use them.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal, TypeVar

import numpy as np

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
