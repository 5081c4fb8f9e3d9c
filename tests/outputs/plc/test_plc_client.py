"""Client mode against the PLC stand-in: writes at once on a change, refreshes,
TCP_NODELAY, and survives a PLC that drops the connection and comes back."""

from __future__ import annotations

import socket
import time

from eskin_industrial.bridge.loop import NodeLoop
from eskin_industrial.bus.replay import ReplaySource
from eskin_industrial.calibration import Calibrator
from eskin_industrial.detect.state import GraspState
from eskin_industrial.outputs.plc.client import PlcWriter
from eskin_industrial.outputs.plc.image import REG, STATUS_COUNT, Status
from eskin_industrial.outputs.plc.image import decode_registers as decode
from eskin_industrial.sim.plc import PlcSimulator
from tests.helpers.modbus import free_port, slip_recording


def wait_for(cond, timeout_s: float = 5.0, step=None) -> None:
    deadline = time.monotonic() + timeout_s
    while not cond():
        assert time.monotonic() < deadline, "condition not met in time"
        if step is not None:
            step()
        else:
            time.sleep(0.005)


def test_writer_refreshes_and_writes_changes_at_once(paper_profile):
    port = free_port()
    plc = PlcSimulator(paper_profile.modbus.plc, "127.0.0.1", port, echo=None).start()
    writer = PlcWriter(paper_profile.modbus.plc, "127.0.0.1", port).start()
    try:
        writer.offer([1] + [0] * (STATUS_COUNT - 1))
        wait_for(lambda: plc.memory.writes >= 3)  # refresh without any change (every refresh_s)
        assert writer.master.sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY)
        # An urgent image does not wait for the refresh period.
        time.sleep(0.01)
        t0 = time.perf_counter()
        writer.offer([int(Status.SLIP)] + [0] * (STATUS_COUNT - 1), urgent=True, t_event=t0)
        wait_for(lambda: plc.first(Status.SLIP) is not None, timeout_s=1.0)
        assert plc.first(Status.SLIP) - t0 < 0.02  # far below refresh_s = 0.05 + the write
        # the PLC has the image; the writer counts it once the PLC's answer is back
        wait_for(lambda: writer.stats.writes and writer.flushed, timeout_s=1.0)
        assert writer.stats.urgent_writes == 1 and writer.stats.latencies_s[0] < 0.02
    finally:
        writer.stop()
        plc.stop()


def test_commands_from_the_plc_memory_reach_the_bridge(paper_profile):
    port = free_port()
    plc = PlcSimulator(paper_profile.modbus.plc, "127.0.0.1", port, echo=None).start()
    writer = PlcWriter(paper_profile.modbus.plc, "127.0.0.1", port).start()
    try:
        writer.offer([0] * STATUS_COUNT)
        plc.memory.regs[REG["COMMAND"].offset] = 1
        wait_for(lambda: plc.memory.regs[REG["COMMAND"].offset] == 0)  # handshake: cleared by the bridge
        names = [c.name for c in writer.take_commands()]
        assert "ack" in names and "enable" in names
        plc.memory.regs[REG["ENABLE"].offset] = 0
        wait_for(lambda: any(c.name == "disable" for c in writer.take_commands()))
    finally:
        writer.stop()
        plc.stop()


def test_plc_drops_and_comes_back_while_detection_runs(paper_profile):
    settings = paper_profile.modbus.plc
    port = free_port()
    t, f, onset = slip_recording(still_s=1.5, slip_s=0.3, after_s=1.0)
    raw = Calibrator.from_section(paper_profile.calibration, 25).to_raw(f)
    source = ReplaySource(paper_profile, t, raw, 1000.0)  # 10x real time
    writer = PlcWriter(settings, "127.0.0.1", port).start()
    bridge = NodeLoop(paper_profile, source, [writer])
    plc = PlcSimulator(settings, "127.0.0.1", port, echo=None).start()
    try:
        wait_for(lambda: plc.memory.writes > 0, step=bridge.step)
        plc.stop()  # the PLC goes away before the slip
        while not source.done:
            bridge.step()  # detection goes on: no stall while the PLC is away
        assert bridge.status.slip_events >= 1 and bridge.status.latched
        assert writer.stats.failures >= 1 and not writer.connected
        plc = PlcSimulator(settings, "127.0.0.1", port, echo=None)
        plc.gripper.heartbeat_timeout_s = 10.0
        plc.start()
        # The bridge keeps publishing (heartbeat); the writer reconnects within its backoff.
        wait_for(lambda: plc.memory.writes > 0, timeout_s=settings.backoff_max_s + 3, step=bridge.step)
        v = decode(plc.memory.regs, settings.word_order)
        # Nothing that could be kept is lost: the latch and the event count survive.
        assert v["STATUS"] & Status.SLIP_LATCHED and v["SLIP_EVENTS"] == bridge.status.slip_events >= 1
        assert writer.stats.connects == 2
        # The stand-in's gripper logic reacts to the latch and acknowledges it.
        wait_for(lambda: plc.gripper.raises == 1, step=bridge.step)
        wait_for(lambda: not bridge.status.latched, step=bridge.step)
        assert bridge.status.update.state != GraspState.SLIP
    finally:
        writer.stop()
        plc.stop()


def test_client_mode_over_rtu(paper_profile, tmp_path):
    from eskin_industrial.modbus.serial_line import SerialSettings
    from tests.helpers.modbus import pty_pair

    settings = paper_profile.modbus.plc
    with pty_pair(tmp_path) as (a, b):
        plc = PlcSimulator(settings, "", 0, echo=None, serial=SerialSettings(a, 115200)).start()
        writer = PlcWriter(settings, serial=SerialSettings(b, 115200)).start()
        try:
            image = [int(Status.SLIP | Status.DATA_VALID)] + list(range(1, STATUS_COUNT))
            writer.offer(image, urgent=True)
            wait_for(lambda: plc.memory.regs[:STATUS_COUNT] == image)
            plc.memory.regs[REG["COMMAND"].offset] = 1  # the PLC acknowledges
            wait_for(lambda: plc.memory.regs[REG["COMMAND"].offset] == 0)
            assert "ack" in [c.name for c in writer.take_commands()]
            assert writer.stats.failures == 0 and "rtu" in writer.where
        finally:
            writer.stop()
            plc.stop()
