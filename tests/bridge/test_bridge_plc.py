"""Client mode with a PLC that is down at start, goes away during the run, comes
back, or hangs: detection never waits for it, the writer counts its failures, the
log says plc_unreachable / plc_connected, and the PLC gets the present image as soon
as it answers."""

from __future__ import annotations

import socket
import time

import pytest

from eskin_industrial.outputs.plc.image import Status
from tests.helpers.bridge import (
    TimedPlc,
    can_node,
    channel,
    client_config,
    hold_raw,
    node_thread,
    running_bridge,
    wait_for,
)
from tests.helpers.modbus import free_port

RATE_HZ = 100.0
#: Scans in flight between the node's counter and the bridge's (routing, one loop
#: round), plus scheduling on a loaded machine; a loop that waited on a PLC write
#: timeout (0.5 s) would be 50 scans behind.
PACE_SCANS = 10


def keeps_pace(run, node) -> None:
    sent, decoded = node.node.stats.scans, run.counters("grip")["scans"]
    assert sent - decoded <= PACE_SCANS, f"the bridge decoded {decoded} of {sent} scans"


def valid_images(plc: TimedPlc) -> list[dict[str, int]]:
    return [v for _, v in plc.images() if v["STATUS"] & Status.DATA_VALID and v["STATUS"] & Status.STABLE]


@pytest.mark.slow
def test_plc_down_at_start_then_up_then_away_and_back(paper_profile):
    ch, port = channel(), free_port()
    plcs: list[TimedPlc] = []
    try:
        with running_bridge(client_config(can_node("grip", ch), port=port)) as run, \
                node_thread(paper_profile, ch, hold_raw(paper_profile, 700), RATE_HZ) as node:
            node.start()
            # nobody listens: detection goes on, the writer fails and says so
            wait_for(lambda: run.log.events("plc_unreachable"), what="plc_unreachable")
            wait_for(lambda: run.counters("grip")["scans"] >= 50, what="scans while the PLC is down")
            keeps_pace(run, node)
            down = run.counters("grip")
            assert down["plc_write_failures"] >= 1 and down["plc_writes"] == 0 and down["plc_connects"] == 0
            unreachable = run.log.events("plc_unreachable")[0]
            assert unreachable["level"] == "warning" and str(port) in unreachable["plc"]
            assert unreachable["error"] != "-"

            plcs.append(TimedPlc(port).start())  # the PLC comes up
            wait_for(lambda: valid_images(plcs[0]), timeout_s=5, what="a valid image in the PLC")
            wait_for(lambda: run.log.events("plc_connected"), what="plc_connected")
            keeps_pace(run, node)
            assert run.counters("grip")["plc_connects"] == 1

            plcs[0].stop()  # the PLC goes away during the run
            failures = run.counters("grip")["plc_write_failures"]
            wait_for(lambda: len(run.log.events("plc_unreachable")) == 2, what="plc_unreachable again")
            wait_for(lambda: run.counters("grip")["plc_write_failures"] > failures, what="failures counted")
            scans = run.counters("grip")["scans"]
            wait_for(lambda: run.counters("grip")["scans"] >= scans + 30, what="scans while the PLC is away")
            keeps_pace(run, node)

            plcs.append(TimedPlc(port).start())  # and comes back
            wait_for(lambda: valid_images(plcs[1]), timeout_s=5, what="a valid image in the returned PLC")
            wait_for(lambda: len(run.log.events("plc_connected")) == 2, what="plc_connected again")
            keeps_pace(run, node)
            end = run.counters("grip")
            assert end["plc_connects"] == 2 and end["lost_scans"] == 0
            # the returned PLC gets the present: a heartbeat that went on while it was away
            assert valid_images(plcs[1])[0]["HEARTBEAT"] > max(v["HEARTBEAT"] for _, v in plcs[0].images())
    finally:
        for p in plcs:
            p.stop()
    assert not run.bridge.failure


@pytest.mark.slow
def test_a_plc_that_accepts_and_never_answers_does_not_stall_detection(paper_profile):
    """A hung PLC: the connection is accepted (by the kernel's backlog) but no request
    is ever answered, so every write waits for the writer's timeout."""
    ch = channel()
    with socket.socket() as hung:
        hung.bind(("127.0.0.1", 0))
        hung.listen(8)
        port = hung.getsockname()[1]
        with running_bridge(client_config(can_node("grip", ch), port=port)) as run, \
                node_thread(paper_profile, ch, hold_raw(paper_profile, 200), RATE_HZ) as node:
            node.start()
            t0 = time.monotonic()
            wait_for(lambda: run.counters("grip")["plc_write_failures"] >= 2, what="write timeouts counted")
            keeps_pace(run, node)
            node.join(10)
            wait_for(lambda: run.counters("grip")["scans"] == 200, what="every scan decoded")
            assert time.monotonic() - t0 < 5
            c = run.counters("grip")
            assert c["plc_writes"] == 0 and c["plc_superseded"] > 0  # the newest image replaces the waiting one
            assert c["publications"] >= 20
