"""Counters and status bits that tell the truth: a CAN bus-off or a storm of error
frames sets BUS_FAULT and counts in BUS_ERRORS (an error frame is no sign of life);
STATE_CHANGES and the ``state_changes`` counter are one count."""
from __future__ import annotations

import time

import can
import numpy as np
import pytest

from eskin_industrial.bus.can.layout import ERROR_RUN_FAULT, CanLayout, ScanAssembler
from eskin_industrial.bus.can.reader import open_bus
from eskin_industrial.calibration import Calibrator
from eskin_industrial.frames import RawScan
from eskin_industrial.node import Health
from eskin_industrial.outputs.plc.image import Status, decode_registers
from eskin_industrial.pipeline import Pipeline
from tests.helpers.bridge import can_node, channel, hold_raw, running_bridge, server_config, wait_for
from tests.helpers.can_frames import msg, scans_to_messages
from tests.helpers.scenes import grasp
from tests.helpers.snapshots import StatusImage

BUS_OFF = 0x040  # linux/can/error.h CAN_ERR_BUSOFF


def error_frame(t: float = 0.0, bus_off: bool = False) -> can.Message:
    return can.Message(arbitration_id=BUS_OFF if bus_off else 0x004, is_error_frame=True, timestamp=t, dlc=8)


def test_the_assembler_faults_on_bus_off_or_a_run_of_error_frames_until_the_node_is_heard(paper_profile):
    layout = CanLayout.from_profile(paper_profile)
    asm = ScanAssembler(layout, 100.0)
    frames = scans_to_messages(layout, np.arange(3), hold_raw(paper_profile, 3))
    for m in frames[:9]:
        asm.feed(m)
    asm.feed(error_frame())  # one error frame between scans is noise
    assert not asm.error_fault
    for m in frames[9:18]:
        asm.feed(m)
    for _ in range(ERROR_RUN_FAULT - 1):
        asm.feed(error_frame())
    assert not asm.error_fault
    asm.feed(error_frame())
    assert asm.error_fault  # a run of them and nothing else
    asm.feed(frames[18])
    assert not asm.error_fault  # the node is heard again
    asm.feed(error_frame(bus_off=True))
    assert asm.error_fault  # bus-off: at once
    assert asm.counters["error_frames"] == 1 + ERROR_RUN_FAULT + 1 and asm.counters["bus_off"] == 1


def send_scans(bus: can.BusABC, layout: CanLayout, seqs: np.ndarray, raw: np.ndarray, period_s: float) -> None:
    start = time.monotonic()
    for i, (_seq, scan) in enumerate(zip(seqs, layout.encode(seqs, raw))):
        time.sleep(max(0.0, start + i * period_s - time.monotonic()))
        for can_id, data in scan:
            bus.send(msg(can_id, data))


@pytest.mark.slow
def test_bus_off_sets_bus_fault_and_counts_in_bus_errors(paper_profile):
    """1 s of data, 0.5 s of bus-off error frames and nothing else, then data again.
    Before: STATUS said stale only, BUS_ERRORS 0, while error_frames counted them."""
    ch = channel()
    layout = CanLayout.from_profile(paper_profile)
    raw = hold_raw(paper_profile, 200)
    with running_bridge(server_config(can_node("grip", ch))) as run:
        tx = open_bus("virtual", ch)
        try:
            send_scans(tx, layout, np.arange(100), raw[:100], 0.01)
            wait_for(lambda: run.block(0)["STATUS"] & Status.DATA_VALID, what="valid data before the fault")
            for _ in range(50):
                tx.send(error_frame(bus_off=True))
                time.sleep(0.01)
            wait_for(lambda: run.block(0)["STATUS"] & Status.BUS_FAULT, what="BUS_FAULT")
            during = run.block(0)
            wait_for(lambda: run.log.events("bus_fault"), what="the bus_fault event")
            send_scans(tx, layout, np.arange(100, 200), raw[100:], 0.01)
            wait_for(lambda: run.block(0)["STATUS"] & Status.DATA_VALID and not run.block(0)["STATUS"] & Status.BUS_FAULT,
                     what="valid data after the fault")
            wait_for(lambda: run.log.events("bus_ok"), what="the bus_ok event")
            counters = run.counters("grip")
            after = run.block(0)
        finally:
            tx.shutdown()
    fault = run.log.events("bus_fault")[0]
    assert "error frames in a row" in fault["error"] and "bus-off reported" in fault["error"], fault
    assert during["STATUS"] & Status.SENSOR_STALE and not during["STATUS"] & Status.DATA_VALID
    assert during["BUS_ERRORS"] >= 1
    assert counters["error_frames"] == 50 and counters["bus_off"] == 50
    assert after["BUS_ERRORS"] == 50 == counters["bus_errors"] + counters["error_frames"]


def test_state_changes_is_one_count_in_the_register_and_the_counter(paper_profile):
    """A grasp, a 1 s gap in the log (the detector restarts: validity drops and comes
    back), the grasp again.  Before: the register counted the validity changes too, the
    counter counted the first state as a change (5 against 4 in the reported run)."""
    f = grasp(800, seed=5)
    f[:150] = 0.0
    f[650:] = 0.0
    raw = Calibrator.from_section(paper_profile.calibration, 25).to_raw(f)
    pipe, image = Pipeline(paper_profile), StatusImage(paper_profile.modbus.plc, paper_profile.stale_s)
    updates = []
    for k in range(800):
        seq = k + (100 if k >= 400 else 0)  # 1 s missing in the middle of the hold
        for u in pipe.push(RawScan(seq, seq / 100.0, raw[k])):
            image.observe(u)  # as the node loop hands them on
            updates.append(u)
    states = [u.state for u in updates]
    valid = [u.valid for u in updates]
    expected = sum(a != b for a, b in zip(states, states[1:]))
    assert any(a != b for a, b in zip(valid, valid[1:]))  # validity did change: the case at stake
    assert expected >= 2
    assert pipe.counters.state_changes == image.state_changes == expected
    assert decode_registers(image.render(Health(frame_age_s=0.0)), "big")["STATE_CHANGES"] == expected


@pytest.mark.slow
def test_lost_scans_grow_while_an_rtu_outage_lasts(paper_profile, tmp_path):
    """Before: the failed polls reached LOST_SCANS only once a poll succeeded again
    (BUS_ERRORS 44 and LOST_SCANS 0 at a frame age of 2.2 s)."""
    from eskin_industrial.bridge.loop import NodeLoop
    from eskin_industrial.bus.modbus.rtu import RtuSource
    from eskin_industrial.outputs.base import Sink
    from eskin_industrial.outputs.plc.image import PlcImage
    from eskin_industrial.sim.modbus_node import NodeSimulator
    from tests.helpers.modbus import pty_pair

    class Keep(Sink):
        def __init__(self):
            super().__init__()
            self.values: list[dict[str, int]] = []
            self.image = PlcImage(paper_profile.modbus.plc)

        def _publish(self, snapshot):
            self.values.append(decode_registers(self.image.render(snapshot), "big"))

    f = grasp(300, seed=2)
    with pty_pair(tmp_path) as (a, b):
        node = NodeSimulator(paper_profile, a, f, 100.0).start()
        poller = RtuSource(paper_profile, b).open()
        sink = Keep()
        loop = NodeLoop(paper_profile, poller, [sink])
        try:
            deadline = time.monotonic() + 5
            while not poller.stats.scans >= 20:
                assert time.monotonic() < deadline
                loop.step()
            node.stop()  # the node falls silent
            t0 = time.monotonic()
            while time.monotonic() - t0 < 0.8:
                loop.step()
            loop.publish_if_due(True)
            during = sink.values[-1]
            failed = poller.stats.failed_polls
            node = NodeSimulator(paper_profile, a, f, 100.0).start()
            deadline = time.monotonic() + 5
            while poller.consecutive_failures or not poller.stats.scans > 25:
                assert time.monotonic() < deadline
                loop.step()
            loop.publish_if_due(True)
            after = sink.values[-1]
        finally:
            poller.close()
            node.stop()
    assert during["STATUS"] & Status.BUS_FAULT and failed >= 5
    assert during["LOST_SCANS"] == failed  # every failed poll, while the outage lasts
    assert during["BUS_ERRORS"] >= failed
    shown = [v["LOST_SCANS"] for v in sink.values]
    assert shown == sorted(shown)  # never back
    assert after["LOST_SCANS"] == loop.pipeline.counters.lost_scans == poller.stats.failed_polls
    assert loop.counters()["lost_scans"] == after["LOST_SCANS"]
