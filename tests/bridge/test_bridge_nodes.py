"""Several nodes in one bridge: two CAN nodes on one bus, routed by arbitration ID,
each into its own register block of one Modbus TCP server."""

from __future__ import annotations

import threading

import can
import pytest

from eskin_industrial.bus.can.reader import open_bus
from eskin_industrial.modbus.pymodbus_io import TcpMaster
from eskin_industrial.outputs.plc.image import IMAGE_COUNT, Status
from eskin_industrial.outputs.plc.image import decode_registers as decode
from tests.helpers.bridge import (
    can_node,
    channel,
    hold_raw,
    node_thread,
    running_bridge,
    server_config,
    slip_raw,
    wait_for,
)

RIGHT_BASE = 100


@pytest.mark.slow
def test_two_nodes_on_one_bus_each_in_its_own_block(paper_profile):
    ch = channel()
    cfg = server_config(can_node("left", ch), can_node("right", ch, base_id=0x210, node_id=2,
                                                         base_address=RIGHT_BASE))
    slipping, _ = slip_raw(paper_profile)
    holding = hold_raw(paper_profile, len(slipping), seed=3)
    seen: dict[int, list[int]] = {0: [], RIGHT_BASE: []}
    with running_bridge(cfg) as run:
        port = run.bridge.server.server.tcp[1]  # type: ignore[union-attr]
        plc = TcpMaster("127.0.0.1", port, timeout_s=1.0)
        plc.connect()
        stop = threading.Event()

        def poll() -> None:  # a PLC reading both blocks, as a real one would, every 10 ms
            while not stop.wait(0.01):
                for base in seen:
                    seen[base].append(plc.read_holding(base, IMAGE_COUNT)[0])

        poller = threading.Thread(target=poll, daemon=True)
        try:
            with node_thread(paper_profile, ch, slipping) as left, \
                    node_thread(paper_profile, ch, holding, base_id=0x210, node_id=2) as right, \
                    open_bus("virtual", ch) as stranger:
                poller.start()
                left.start()
                right.start()
                # a node the bridge does not know, on the same bus: counted, never routed
                for i in range(25):
                    stranger.send(can.Message(arbitration_id=0x300 + i % 16, data=bytes(8), is_extended_id=False))
                stranger.send(can.Message(arbitration_id=0x200, data=bytes(8), is_extended_id=True))  # 29-bit ID
                left.join(10)
                right.join(10)
            n = len(slipping)
            wait_for(lambda: run.counters("left")["scans"] == n and run.counters("right")["scans"] == n,
                     what="every scan of both nodes decoded")
        finally:
            stop.set()
            if poller.is_alive():
                poller.join(5)
            plc.close()
        left_now, right_now = run.block(0), run.block(1)
        c_left, c_right = run.counters("left"), run.counters("right")

    # the slip shows in the slipping node's block only, and is counted there
    assert any(s & Status.SLIP for s in seen[0]), [Status(s) for s in seen[0][::10]]
    assert not any(s & Status.SLIP or s & Status.SLIP_LATCHED for s in seen[RIGHT_BASE])
    assert left_now["SLIP_EVENTS"] >= 1 and right_now["SLIP_EVENTS"] == 0
    assert left_now["STATUS"] & Status.SLIP_LATCHED and not right_now["STATUS"] & Status.SLIP_LATCHED
    # the holding node's block reads a valid stable grasp
    assert any(s & Status.STABLE and s & Status.DATA_VALID for s in seen[RIGHT_BASE])
    # the holding node's last verdict before its silence: the block read after the nodes
    # stopped may already be stale (stale_max_s after its last scan, on a loaded host)
    live = [s for s in seen[RIGHT_BASE] if not s & Status.SENSOR_STALE]
    assert live and live[-1] & Status.STABLE and live[-1] & Status.DATA_VALID
    # each block has its own heartbeat, frames and counters
    assert left_now["HEARTBEAT"] > 10 and right_now["HEARTBEAT"] > 10
    for c in (c_left, c_right):
        assert c["lost_scans"] == 0 and c["malformed_frames"] == 0 and c["foreign_frames"] == 0
        assert c["frames"] == n * 9 + c["heartbeats"] and c["heartbeats"] >= n // 10 - 1
        assert c["node_id_mismatch"] == 0
        assert c["unrouted_frames"] == 26  # the stranger's frames, on the shared bus's count
    assert c_left["plc_reads"] > 10 and c_right["plc_reads"] > 10


def test_unknown_block_addresses_are_refused(paper_profile):
    ch = channel()
    cfg = server_config(can_node("a", ch), can_node("b", ch, base_id=0x220, base_address=RIGHT_BASE))
    with running_bridge(cfg) as run:
        plc = TcpMaster("127.0.0.1", run.bridge.server.server.tcp[1], timeout_s=1.0)  # type: ignore[union-attr]
        plc.connect()
        try:
            assert len(plc.read_holding(RIGHT_BASE, IMAGE_COUNT)) == IMAGE_COUNT
            for at, count in ((50, 2), (RIGHT_BASE - 1, 2), (IMAGE_COUNT - 1, 2)):  # between and across blocks
                try:
                    plc.read_holding(at, count)
                except Exception as exc:  # noqa: BLE001 - the Modbus exception reply
                    assert "llegal" in str(exc) or "exception" in str(exc).lower(), exc
                else:
                    raise AssertionError(f"a read at {at} (+{count}) was answered")
            # no frame yet: every block reads stale, no verdict
            for base in (0, RIGHT_BASE):
                v = decode(plc.read_holding(base, IMAGE_COUNT), "big")
                assert v["STATUS"] & Status.SENSOR_STALE and not v["STATUS"] & Status.DATA_VALID
        finally:
            plc.close()
