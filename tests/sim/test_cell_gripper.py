"""The closed loop's gripper as a Modbus TCP device (served by pymodbus), written and
read with the package's own Modbus TCP client, as the PLC stand-in does: its register
map, its refusals, and the requests it hands to the drive."""
from __future__ import annotations

import pytest

from eskin_industrial.errors import ModbusFault
from eskin_industrial.modbus.pymodbus_io import RegisterServer, TcpMaster
from eskin_industrial.modbus.tcp_master import PipelinedTcpMaster
from eskin_industrial.sim.cell.gripper import (
    GREG,
    GRIPPER_COUNT,
    Action,
    GripperRegisters,
    GripperState,
    GripperStatus,
    ObjectStatus,
)
from tests.helpers.modbus import free_port


@pytest.fixture
def gripper():
    state = GripperState()
    requests: list[tuple[float, float]] = []
    device = GripperRegisters(state, rated_n=100.0, on_request=lambda t, f: requests.append((t, f)))
    port = free_port()
    with RegisterServer(device, tcp=("127.0.0.1", port)):
        plc = PipelinedTcpMaster("127.0.0.1", port, unit_id=1, timeout_s=2.0)
        plc.connect()
        try:
            yield state, requests, plc, port
        finally:
            plc.close()


def test_the_plc_closes_the_gripper_and_changes_the_force_request(gripper):
    state, requests, plc, _ = gripper
    assert plc.read_holding(0, GRIPPER_COUNT)[GREG["OBJECT_STATUS"].offset] == ObjectStatus.OPEN
    plc.write_registers(GREG["ACTION"].offset, [int(Action.GO), 250])  # close at 2.50 N
    plc.write_registers(GREG["FORCE_REQUEST"].offset, [475])
    assert [f for _, f in requests] == [2.5, 4.75]
    assert requests[0][0] <= requests[1][0]
    regs = plc.read_holding(0, GRIPPER_COUNT)
    assert regs[GREG["FORCE_REQUEST"].offset] == 475 and regs[GREG["GRIPPER_STATUS"].offset] & GripperStatus.GO
    assert regs[GREG["GRIPPER_STATUS"].offset] & GripperStatus.MOVING  # the drive has not got there yet
    state.target_n = state.force_n = 4.75  # the drive (the world) reports its force
    state.holding = True
    regs = plc.read_holding(0, GRIPPER_COUNT)
    assert regs[GREG["ACTUAL_FORCE"].offset] == 475 and regs[GREG["FORCE_ECHO"].offset] == 475
    assert regs[GREG["OBJECT_STATUS"].offset] == ObjectStatus.HOLDING
    assert not regs[GREG["GRIPPER_STATUS"].offset] & GripperStatus.MOVING
    state.lost = True  # it slid out of the fingers
    assert plc.read_holding(GREG["OBJECT_STATUS"].offset, 1) == [ObjectStatus.NO_OBJECT]
    plc.write_registers(GREG["ACTION"].offset, [0])  # open: the drive is told to let go
    assert requests[-1][1] == 0.0


def test_a_request_above_the_rating_or_a_write_to_a_status_register_is_refused(gripper):
    state, requests, plc, port = gripper
    with pytest.raises(ModbusFault) as exc:
        plc.write_registers(GREG["FORCE_REQUEST"].offset, [10001])  # 100.01 N > 100 N
    assert exc.value.code == 3
    with pytest.raises(ModbusFault) as exc:
        plc.write_registers(GREG["ACTUAL_FORCE"].offset, [100])
    assert exc.value.code == 2
    with pytest.raises(ModbusFault) as exc:
        plc.write_registers(GREG["ACTION"].offset, [0x80])  # an action bit that does not exist
    assert exc.value.code == 3
    assert requests == []
    assert plc.read_holding(GREG["GRIPPER_STATUS"].offset, 1)[0] & GripperStatus.FAULT
    # pymodbus' client reads the same map (input registers too)
    other = TcpMaster("127.0.0.1", port, unit_id=1)
    other.connect()
    try:
        assert other.read_holding(0, GRIPPER_COUNT) == plc.read_holding(0, GRIPPER_COUNT)
        with pytest.raises(ModbusFault):
            other.read_holding(0, GRIPPER_COUNT + 1)
    finally:
        other.close()
