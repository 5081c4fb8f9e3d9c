"""Frames: one calibrated scan of the taxel array, and what is wrong with it.

A :class:`Frame` is what every source produces and every detector consumes: a scan
sequence number, a timestamp in seconds, the taxel forces in newtons in the layout's
row-major order, and :class:`FrameFlag` bits.  Flags are plain ints on the hot path
(an ``IntFlag`` costs microseconds per operation); :class:`FrameFlag` names them.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable
from dataclasses import dataclass, fields
from typing import Any

import numpy as np


class FrameFlag(enum.IntFlag):
    """What is wrong with a frame, or with a detector update (OR of its frames)."""

    SATURATED = 1  #: a taxel at or beyond full scale, or the raw reading at a rail
    INVALID = 2  #: a non-finite or out-of-range value, replaced by that taxel's last good one
    GAP_BEFORE = 4  #: frames were missing before this one (timestamps jump)
    NEGATIVE = 8  #: a negative force, clipped to 0 N
    FILLED = 16  #: synthesized by holding the previous frame across a short gap
    DUPLICATE = 32  #: a timestamp not after the previous frame's: the frame was dropped
    RESET = 64  #: the detector restarted here (a gap longer than ``max_gap_s``)
    SHORT_WINDOW = 128  #: the window is shorter than the wavelet filter: R_dw not computed
    WARMUP = 256  #: not enough history yet since start or reset: indicators not valid
    #: in contact, but the torsion channel cannot see a turn here (a contact on about one
    #: taxel, a very light or noisy grip; or it has not judged this contact yet): a turn
    #: would read ``stable``.  cof-track's only (detect/torsion.py, ``TurnFlow.blind``)
    TURN_UNSEEN = 512
    # The sensor's faults (detect/integrity.py): while one is set the node claims no
    # state and DATA_VALID is clear, whatever the detector says.
    #: too many taxels invalid at once (more than ``[output] hold_share`` of them), or
    #: one invalid for longer than ``[output] hold_s``: open lines, shorts, NaN
    DEAD_TAXELS = 1024
    #: the scans have been identical, every taxel to the bit, for longer than
    #: ``[output] frozen_s``: a hung node repeating its last scan
    FROZEN = 2048
    #: the scans' own timestamps show a rate more than ``[output] rate_tolerance`` times
    #: away from the rate the detector assumes
    RATE = 4096
    #: the transport's frames are not one sensor's fresh scans: two scan counters at
    #: once, a sustained rate of late or torn frames, a heartbeat naming another node
    #: (CAN, bus/can/stream.py); an answer repeated to the bit (Modbus RTU)
    STREAM = 8192

    @classmethod
    def describe(cls, value: int) -> str:
        """``"SATURATED|GAP_BEFORE"`` for the bits set, ``""`` for none."""
        return "|".join(f.name for f in cls if value & f and f.name)


#: The sensor-fault bits: any of them makes a state no verdict.
SENSOR_FAULTS = int(FrameFlag.DEAD_TAXELS | FrameFlag.FROZEN | FrameFlag.RATE | FrameFlag.STREAM)


@dataclass(frozen=True, slots=True)
class Frame:
    """One scan, calibrated: forces in newtons, row-major taxel order."""

    seq: int
    t: float
    forces: np.ndarray
    flags: int = 0


@dataclass(frozen=True, slots=True)
class RawScan:
    """One scan as a transport delivered it, before calibration.

    ``t`` is the scan's time on the node's clock when the transport carries one
    (sequence counter x scan period), otherwise the receipt time; ``rx_time`` is
    always the host's monotonic receipt time (for staleness and latency).
    """

    seq: int
    t: float
    raw: np.ndarray
    flags: int = 0
    rx_time: float = math.nan


def _maker(cls: type) -> Callable[..., Any]:
    """A constructor of the frozen slotted record ``cls`` from all its fields in order,
    for the one or two made per scan on the hot path: the generated ``__init__`` of a
    frozen dataclass sets each field through ``object.__setattr__``, about half a
    microsecond a field; the slots' own setters take a fifth of that.  The same object
    (``new_frame(*astuple(f)) == f``, tests/test_frames.py)."""
    names = tuple(f.name for f in fields(cls))
    setters = tuple(getattr(cls, n).__set__ for n in names)
    new = object.__new__
    if len(names) == 4:
        s0, s1, s2, s3 = setters

        def make4(a: Any, b: Any, c: Any, d: Any) -> Any:
            obj: Any = new(cls)
            s0(obj, a), s1(obj, b), s2(obj, c), s3(obj, d)
            return obj
        return make4
    if len(names) == 5:
        s0, s1, s2, s3, s4 = setters

        def make5(a: Any, b: Any, c: Any, d: Any, e: Any) -> Any:
            obj: Any = new(cls)
            s0(obj, a), s1(obj, b), s2(obj, c), s3(obj, d), s4(obj, e)
            return obj
        return make5
    raise TypeError(f"no fast constructor for {len(names)} fields")


#: ``Frame(seq, t, forces, flags)``, every field given, faster (the pipeline's, a scan).
new_frame: Callable[[int, float, np.ndarray, int], Frame] = _maker(Frame)
#: ``RawScan(seq, t, raw, flags, rx_time)``, every field given, faster (a CAN scan's assembly).
new_raw_scan: Callable[[int, float, np.ndarray, int, float], RawScan] = _maker(RawScan)
