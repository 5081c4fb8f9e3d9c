"""The hot path's fast constructors of Frame and RawScan make the same records."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from eskin_industrial.frames import Frame, RawScan, _maker, new_frame, new_raw_scan


def test_new_frame_is_the_frame_the_dataclass_makes() -> None:
    forces = np.arange(25.0)
    made, slow = new_frame(7, 0.07, forces, 5), Frame(7, 0.07, forces, 5)
    assert type(made) is Frame
    assert made == slow and dataclasses.astuple(made)[0:2] == (7, 0.07) and made.forces is forces
    with pytest.raises(dataclasses.FrozenInstanceError):
        made.seq = 8  # type: ignore[misc]


def test_new_raw_scan_is_the_raw_scan_the_dataclass_makes() -> None:
    raw = np.ones(25)
    made = new_raw_scan(3, 0.03, raw, 1, 12.5)
    assert type(made) is RawScan
    assert (made.seq, made.t, made.raw, made.flags, made.rx_time) == (3, 0.03, raw, 1, 12.5)
    assert made == RawScan(3, 0.03, raw, 1, 12.5)
    assert math.isnan(RawScan(3, 0.03, raw).rx_time)  # (the dataclass keeps its defaults)


def test_a_record_of_another_size_has_no_fast_constructor() -> None:
    @dataclasses.dataclass(frozen=True, slots=True)
    class Pair:
        a: int
        b: int

    with pytest.raises(TypeError, match="2 fields"):
        _maker(Pair)
