"""What a subscribed client is told, against what the loop handed the server: the
slip with Good quality and the deciding scan's time as its source timestamp, a
sensor that goes silent (UncertainLastUsableValue, then BadNoCommunication, then
Good again when it speaks), a source that fails (BadDeviceFailure), and the taxel
frame as a Float matrix.  The bridge runs in this process on a CAN node of
python-can's virtual bus; the clients are node-opcua and asyncua's."""

from __future__ import annotations

import asyncio
import math
import time
from pathlib import Path

import numpy as np
import pytest

from eskin_industrial.bridge.config import NodeConfig
from eskin_industrial.outputs.opcua import model
from eskin_industrial.sim.can_node import Faults
from tests.helpers.bridge import PAPER, can_node, channel, node_thread, running_bridge, slip_raw, wait_for
from tests.helpers.opcua import NAMESPACE_URI, Capture, node_peer, opcua_config

pytestmark = pytest.mark.slow


def _url(config) -> str:
    return config.outputs["opcua"].endpoint


def test_the_slip_arrives_good_with_the_deciding_scans_time_and_silence_turns_bad(paper_profile) -> None:
    ch = channel()
    config = opcua_config(can_node("grip", ch), bad_after_s=0.5)
    capture = Capture()
    raw, _ = slip_raw(paper_profile)  # still 1.5 s, the slip, still again until 2.8 s
    raw = np.concatenate([raw, np.repeat(raw[-1:], 250, axis=0)])  # ... and on to 5.3 s
    silence = Faults(silent_at_s=2.4, silent_for_s=1.5)  # after the slip, 1.5 s of nothing, then on
    with running_bridge(config, before_start=lambda b: b.runs[0].loop.add_sink(capture)) as run, \
            node_peer() as peer:
        peer.ask("connect", url=_url(config))
        ns = peer.ask("namespace", uri=NAMESPACE_URI)["index"]
        state, force = f"ns={ns};s=grip.GraspState", f"ns={ns};s=grip.TotalForce"
        peer.ask("subscribe", nodeIds=[state, force], publishingInterval=10)
        first = peer.wait_event(lambda e: e["event"] == "data" and e["nodeId"] == state, 10, "the first value")
        assert first["status"] == "BadWaitingForInitialData" and first["value"] is None  # no scan yet
        with node_thread(paper_profile, ch, raw, faults=silence) as node:
            node.start()
            slip = peer.wait_event(lambda e: e["event"] == "data" and e["nodeId"] == state and e["value"] == 3,
                                   20, "the slip")
            assert slip["status"] == "Good"
            deciding = next(s for s in capture.snapshots if s.state == 3)
            client_ms = slip["sourceTimestamp"] + slip["sourcePicoseconds"] / 1e9
            assert abs(client_ms - deciding.wall_time_s * 1000.0) < 0.01  # the deciding scan's arrival, to 10 us

            # the node falls silent: the last value, uncertain; then no value, bad; the counts stay good
            uncertain = peer.wait_event(lambda e: e["event"] == "data" and e["nodeId"] == force
                                        and e["status"] == "UncertainLastUsableValue", 5, "UncertainLastUsableValue")
            assert uncertain["value"] is not None and uncertain["value"] > 1.0
            bad = peer.wait_event(lambda e: e["event"] == "data" and e["nodeId"] == state
                                  and e["status"] == "BadNoCommunication", 5, "BadNoCommunication")
            assert bad["value"] is None
            assert (bad["sourceTimestamp"] - uncertain["sourceTimestamp"]) / 1000 >= 0.5 - 0.1
            read = peer.ask("read", nodeIds=[f"ns={ns};s=grip.Health.SensorStale",
                                             f"ns={ns};s=grip.MachineryBuildingBlocks.MachineryItemState.CurrentState"])["values"]
            assert (read[0]["value"], read[0]["status"], read[1]["value"]) == (True, "Good", "OutOfService")

            # it speaks again: Good
            peer.wait_event(lambda e: e["event"] == "data" and e["nodeId"] == force and e["status"] == "Good",
                            10, "Good again")
            node.join(20)
        assert run.counters("grip")["opcua_handover_dropped"] == 0


def test_the_asyncua_client_reads_what_node_opcua_reads(paper_profile) -> None:
    """A second client stack: the same values, statuses, units and enumeration."""
    from asyncua import Client, ua

    ch = channel()
    config = opcua_config(can_node("grip", ch))
    raw, _ = slip_raw(paper_profile)

    async def read_all(url: str) -> dict[str, ua.DataValue]:
        async with Client(url, timeout=10) as client:
            ns = await client.get_namespace_index(NAMESPACE_URI)
            # the server shows a scan at the output's next publication, not the instant
            # the loop counts it: wait for the last one to be shown (a loaded host read 146)
            scans = client.get_node(f"ns={ns};s=grip.Counters.Scans")
            deadline = time.monotonic() + 10
            while (await scans.read_value()) != 150 and time.monotonic() < deadline:
                await asyncio.sleep(0.05)
            out = {}
            for v in model.VARIABLES:
                out[v.path] = await client.get_node(f"ns={ns};s=grip.{v.path.replace('/', '.')}").read_data_value(
                    raise_on_bad_status=False)
            unit = await client.get_node(f"ns={ns};s=grip.TotalForce.EngineeringUnits").read_value()
            out["unit"] = unit
            enum = await client.get_node(f"ns={ns};i={model.TYPE_IDS['GraspStateEnumeration']}").read_attribute(
                ua.AttributeIds.DataTypeDefinition)
            out["enum"] = enum
            return out

    with running_bridge(config) as run, node_thread(paper_profile, ch, raw[:150]) as node:
        node.start()
        node.join(20)
        wait_for(lambda: run.counters("grip")["scans"] == 150, what="every scan taken")
        got = asyncio.run(asyncio.wait_for(read_all(_url(config)), 60))
    assert got["GraspState"].StatusCode.name in ("Good", "UncertainLastUsableValue", "BadNoCommunication")
    assert got["Counters/Scans"].Value.Value == 150 and got["Counters/Scans"].StatusCode.is_good()
    assert got["Method"].Value.Value == "cof-track"
    assert got["unit"].DisplayName.Text == "N" and got["unit"].UnitId == model.UNITS["N"][0]
    assert [f.Name for f in got["enum"].Value.Value.Fields] == list(model.STATE_NAMES)


def test_a_source_that_fails_reads_bad_device_failure(tmp_path: Path) -> None:
    """A CAN log that is not one (a replay that fails): its node's values turn
    BadDeviceFailure, and the bridge goes on serving."""
    log = tmp_path / "broken.log"
    log.write_text("this is not a CAN log\n" * 3)
    config = opcua_config(NodeConfig.of("replay", PAPER, "can-log", path=str(log)))
    with node_peer() as peer:
        with running_bridge(config) as run:
            peer.ask("connect", url=_url(config))
            ns = peer.ask("namespace", uri=NAMESPACE_URI)["index"]
            wait_for(lambda: run.bridge.failed_sources, 10, "the replay failed")
            deadline = time.monotonic() + 10
            while True:
                (value,) = peer.ask("read", nodeIds=[f"ns={ns};s=replay.GraspState"])["values"]
                if value["status"] == "BadDeviceFailure" or time.monotonic() > deadline:
                    break
                time.sleep(0.05)
            assert value["status"] == "BadDeviceFailure"
            run.bridge.failure = ""  # (the failed replay is the point here)


def test_the_taxel_frame_is_a_float_matrix_of_the_frames_handed_over(paper_profile) -> None:
    ch = channel()
    config = opcua_config(can_node("grip", ch), frame_interval_s=0.1)
    capture = Capture(frame_every_s=0.1)
    raw, _ = slip_raw(paper_profile)
    with running_bridge(config, before_start=lambda b: b.runs[0].loop.add_sink(capture)), node_peer() as peer:
        peer.ask("connect", url=_url(config))
        ns = peer.ask("namespace", uri=NAMESPACE_URI)["index"]
        taxels = f"ns={ns};s=grip.Taxels"
        peer.ask("subscribe", nodeIds=[taxels], publishingInterval=10)
        with node_thread(paper_profile, ch, raw[:100]) as node:
            node.start()
            frame = peer.wait_event(lambda e: e["event"] == "data" and e["status"] == "Good"
                                    and e["value"] is not None, 10, "a frame")
            node.join(10)
        nodes = {n["path"]: n for n in peer.ask("browse", nodeId=f"ns={ns};s=grip")["nodes"]}
    assert frame["dataType"] == "Float" and frame["dimensions"] == [5, 5] and len(frame["value"]) == 25
    sent = np.asarray(frame["value"], dtype=np.float32)
    assert any(np.array_equal(sent, f) for f in capture.frames), "not a frame the loop handed over"
    info = nodes["Taxels"]
    assert info["valueRank"] == 2 and info["arrayDimensions"] == [5, 5] and info["dataTypeId"] == "ns=0;i=10"
    unit = nodes["Taxels/EngineeringUnits"]["value"]
    assert unit["displayName"]["text"] == "N" and not math.isnan(nodes["Taxels/EURange"]["value"]["high"])
