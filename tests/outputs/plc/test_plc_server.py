"""Server mode, read and written by mbpoll (libmodbus): a Modbus stack we did not write."""

from __future__ import annotations

import time

import numpy as np
import pytest

from eskin_industrial.bridge.loop import NodeLoop
from eskin_industrial.bus.replay import ReplaySource
from eskin_industrial.calibration import Calibrator
from eskin_industrial.detect.state import GraspState
from eskin_industrial.modbus.serial_line import SerialSettings
from eskin_industrial.outputs.plc.image import IMAGE_COUNT, REG, STATUS_COUNT, Status
from eskin_industrial.outputs.plc.server import PlcServer
from tests.helpers.modbus import free_port, mbpoll, mbpoll_values, pty_pair, slip_recording


def run_bridge(bridge: NodeLoop, until, timeout_s: float = 10.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not until():
        assert time.monotonic() < deadline, "bridge did not reach the expected state"
        bridge.step()


def still_bridge(profile, sink):
    t, f, _ = slip_recording()
    k = int(1.4 * 100)  # the still part only
    raw = Calibrator.from_section(profile.calibration, profile.taxels).to_raw(f[:k])
    return NodeLoop(profile, ReplaySource(profile, t[:k], raw, 400.0, loop=True), [sink.block(0)])


def settle(bridge) -> None:
    """Run until the detector gives a valid stable verdict, then publish once more."""
    run_bridge(bridge, lambda: bridge.pipeline.last_update is not None and bridge.pipeline.last_update.valid)
    bridge.publish_if_due(True)


def test_mbpoll_reads_the_served_registers_over_tcp(paper_profile):
    port = free_port()
    server = PlcServer(paper_profile.modbus.plc, tcp=("127.0.0.1", port)).start()
    try:
        bridge = still_bridge(paper_profile, server)
        settle(bridge)
        expected = list(server.handler.registers)
        out = mbpoll("-m", "tcp", "-p", str(port), "-a", "1", "-r", "1", "-c", str(STATUS_COUNT + 2), "-1",
                     "127.0.0.1")
        assert out.returncode == 0, out.stderr
        got = mbpoll_values(out.stdout)
        assert [got[i + 1] for i in range(STATUS_COUNT)] == expected
        status = Status(got[1])
        assert got[REG["STATE"].offset + 1] == bridge.pipeline.last_update.state == GraspState.STABLE
        assert status & (Status.CONTACT | Status.STABLE | Status.DATA_VALID | Status.ENABLED) == (
            Status.CONTACT | Status.STABLE | Status.DATA_VALID | Status.ENABLED)
        assert not status & (Status.SLIP | Status.SENSOR_STALE | Status.BUS_FAULT)
        assert got[REG["ENABLE"].offset + 1] == 1
        # The same bits as discrete inputs (-t 1), 1-based references.
        out = mbpoll("-m", "tcp", "-p", str(port), "-a", "1", "-t", "1", "-r", "1", "-c", "10", "-1", "127.0.0.1")
        assert out.returncode == 0, out.stderr
        bits = mbpoll_values(out.stdout)
        assert [bits[i + 1] for i in range(10)] == [int(bool(got[1] & (1 << i))) for i in range(10)]
        # Reading past the image is refused.
        out = mbpoll("-m", "tcp", "-p", str(port), "-a", "1", "-r", str(IMAGE_COUNT - 2), "-c", "5", "-1", "127.0.0.1")
        assert out.returncode != 0 and "Illegal data address" in out.stderr
    finally:
        server.stop()


def test_commands_by_mbpoll_and_refused_writes(paper_profile):
    port = free_port()
    server = PlcServer(paper_profile.modbus.plc, tcp=("127.0.0.1", port)).start()
    tcp = ("-m", "tcp", "-p", str(port), "-a", "1")
    try:
        bridge = still_bridge(paper_profile, server)
        settle(bridge)
        # A write to a read-only register: ILLEGAL DATA ADDRESS, nothing changes.
        out = mbpoll(*tcp, "-r", str(REG["STATE"].offset + 1), "-1", "127.0.0.1", "3")
        assert out.returncode != 0 and "Illegal data address" in out.stderr
        assert server.handler.refused == 1 and not server.take_commands()
        # ENABLE = 0 (1-based reference 22): detection disabled.
        out = mbpoll(*tcp, "-r", str(REG["ENABLE"].offset + 1), "-1", "127.0.0.1", "0")
        assert out.returncode == 0, out.stderr
        bridge.step()
        assert not bridge.status.enabled
        assert not Status(server.handler.registers[0]) & (Status.ENABLED | Status.DATA_VALID)
        # Enable again by coil 3.
        out = mbpoll(*tcp, "-t", "0", "-r", "3", "-1", "127.0.0.1", "1")
        assert out.returncode == 0, out.stderr
        bridge.step()
        assert bridge.status.enabled
        # Latch a slip by hand, acknowledge it through COMMAND bit 0.
        bridge.status.latched = True
        bridge.publish_if_due(True)
        assert Status(server.handler.registers[0]) & Status.SLIP_LATCHED
        out = mbpoll(*tcp, "-r", str(REG["COMMAND"].offset + 1), "-1", "127.0.0.1", "1")
        assert out.returncode == 0, out.stderr
        bridge.step()
        assert not bridge.status.latched and not Status(server.handler.registers[0]) & Status.SLIP_LATCHED
        out = mbpoll(*tcp, "-r", str(REG["COMMAND"].offset + 1), "-c", "1", "-1", "127.0.0.1")
        assert mbpoll_values(out.stdout)[REG["COMMAND"].offset + 1] == 0  # handshake: done
        # Tare through COMMAND bit 1 while the grasp holds: refused (SERVER DEVICE
        # FAILURE), the zero stays (a tare with the gripper open: tests/modbus/test_modbus_server.py).
        zero_before = bridge.pipeline.calibrator.zero.copy()
        out = mbpoll(*tcp, "-r", str(REG["COMMAND"].offset + 1), "-1", "127.0.0.1", "2")
        assert out.returncode != 0 and "Slave device or server failure" in out.stderr
        bridge.step()
        assert bridge.tares == 0 and np.array_equal(bridge.pipeline.calibrator.zero, zero_before)
        assert server.handler.tares_refused == 1
        # Unknown command bits: ILLEGAL DATA VALUE.
        out = mbpoll(*tcp, "-r", str(REG["COMMAND"].offset + 1), "-1", "127.0.0.1", "8")
        assert out.returncode != 0 and "Illegal data value" in out.stderr
    finally:
        server.stop()


def test_mbpoll_reads_the_registers_over_rtu(paper_profile, tmp_path):
    with pty_pair(tmp_path) as (a, b):
        server = PlcServer(paper_profile.modbus.plc, serial=SerialSettings(a, 115200)).start()
        try:
            bridge = still_bridge(paper_profile, server)
            settle(bridge)
            expected = list(server.handler.registers)
            out = mbpoll("-m", "rtu", "-b", "115200", "-P", "none", "-a", "1", "-r", "1", "-c", str(STATUS_COUNT),
                         "-1", b)
            assert out.returncode == 0, out.stdout + out.stderr
            got = mbpoll_values(out.stdout)
            assert [got[i + 1] for i in range(STATUS_COUNT)] == expected
            assert got[REG["STATE"].offset + 1] == GraspState.STABLE
            # Another unit id on the line: no answer (a shared RS-485 line).
            out = mbpoll("-m", "rtu", "-b", "115200", "-P", "none", "-a", "7", "-o", "0.2", "-r", "1", "-1", b)
            assert out.returncode != 0
        finally:
            server.stop()


def test_server_port_in_use_is_one_line_error(paper_profile):
    port = free_port()
    first = PlcServer(paper_profile.modbus.plc, tcp=("127.0.0.1", port)).start()
    try:
        from eskin_industrial.errors import EskinError

        with pytest.raises(EskinError, match="cannot listen"):
            PlcServer(paper_profile.modbus.plc, tcp=("127.0.0.1", port)).start()
    finally:
        first.stop()
