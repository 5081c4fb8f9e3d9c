"""One rule for a row and a snapshot: under a sensor fault an update shows no verdict
(`node/verdict.py`), exactly what the node's snapshot claims of it (`NodeStatus`)."""

from __future__ import annotations

import math

import pytest

from eskin_industrial.detect.state import GraspState
from eskin_industrial.detect.updates import Update
from eskin_industrial.frames import SENSOR_FAULTS, FrameFlag
from eskin_industrial.node import Health, NodeStatus
from eskin_industrial.node.verdict import shown

STABLE = Update(2.5, 0.01, 0.2, int(GraspState.STABLE), True, 8.06, 10.4, 9.9, int(FrameFlag.INVALID), 0.3, 0.1)


def test_without_a_fault_the_update_is_itself() -> None:
    assert shown(STABLE, 0) is STABLE
    assert shown(STABLE, int(FrameFlag.SATURATED | FrameFlag.WARMUP)) is STABLE  # (no sensor fault among them)


@pytest.mark.parametrize("fault", [FrameFlag.DEAD_TAXELS, FrameFlag.FROZEN, FrameFlag.RATE, FrameFlag.STREAM,
                                   FrameFlag.DEAD_TAXELS | FrameFlag.FROZEN])
def test_under_a_fault_the_row_claims_what_the_snapshot_claims(fault: FrameFlag) -> None:
    row = shown(STABLE, int(fault))
    status = NodeStatus(stale_s=0.05)
    status.observe(STABLE)
    snap = status.snapshot(Health(frame_age_s=0.0, fault=int(fault)), scans=1, t_event=0.0, wall_time_s=0.0,
                           urgent=False)
    assert snap.state is None and row.state == 0 == int(GraspState.NO_CONTACT)  # STATE 0, as the PLC reads it
    assert row.valid is snap.valid is False
    assert row.flags == snap.flags == STABLE.flags | int(fault) and row.flags & SENSOR_FAULTS == int(fault)
    for name, value in (("r_coe", snap.r_coe), ("r_dw", snap.r_dw), ("f_sum", snap.f_sum_n),
                        ("score_a", snap.score_a), ("score_b", snap.score_b)):
        assert value is None and math.isnan(getattr(row, name)), name  # none: NaN in a row
    assert (row.xc, row.yc) == (snap.xc_mm, snap.yc_mm) == (STABLE.xc, STABLE.yc)  # held, as the snapshot holds it
    assert row.t == snap.t == STABLE.t
    assert snap.detected_state == STABLE.state  # the detector's own state goes on behind it
