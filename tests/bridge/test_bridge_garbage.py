"""Random and malformed frames on the bus of a running bridge, interleaved with a
node's valid traffic and a silence: the bridge keeps running, the valid scans give
the right state, every bad frame is counted where it belongs, and no image claims a
verdict while there is no valid data.  (The decoders alone are fuzzed in
tests/bus/test_fuzz_*.py and tests/outputs/plc/test_fuzz_plc.py; this is the bridge's input, end to end.)"""

from __future__ import annotations

import threading
import time
from collections import Counter

import can
import pytest
from hypothesis import given
from hypothesis import strategies as st

from eskin_industrial import load_profile
from eskin_industrial.bus.can.layout import HEADER_BYTES, ID_RANGE, SEQ_BITS, STATUS_LENGTH, CanLayout
from eskin_industrial.bus.can.reader import open_bus
from eskin_industrial.outputs.plc.image import Status
from eskin_industrial.sim.can_node import Faults
from tests.helpers.bridge import (
    CLAIMS,
    PAPER,
    TimedPlc,
    can_node,
    channel,
    client_config,
    hold_raw,
    node_thread,
    running_bridge,
    wait_for,
)
from tests.helpers.fuzz import fuzz
from tests.helpers.modbus import free_port
from tests.helpers.stalls import StallMeter

PROFILE = load_profile(PAPER)
LAYOUT = CanLayout.from_profile(PROFILE)
LO = LAYOUT.base_id
DATA_IDS = [LAYOUT.data_id(s) for s in range(LAYOUT.segments)]
UNUSED_IDS = [i for i in range(LO, LO + ID_RANGE) if i not in DATA_IDS and i != LAYOUT.status_id]
RATE_HZ = 100.0
#: After the last valid frame, the stale limit (stale_s, learnt from the arrivals up to
#: stale_max_s: docs/plc.md) + 15 ms of scheduling on a loaded machine: from then on no
#: image may claim a verdict (the silence test times the fixed limit exactly).
INVALID_AFTER_S = PROFILE.stale_max_s + 0.015

# Each garbage frame with the counter it must land in ("malformed": the node's
# malformed_frames; "error": error_frames; "unrouted": frames of no node).


def _header(segment: int, seq: int) -> bytes:
    return ((segment << SEQ_BITS) | seq).to_bytes(HEADER_BYTES, LAYOUT.byte_order)


@st.composite
def wrong_length(draw) -> tuple[str, can.Message]:
    """A data frame, or the heartbeat, one or more bytes off its length."""
    segment = draw(st.integers(0, LAYOUT.segments))  # == segments: the heartbeat
    if segment == LAYOUT.segments:
        can_id, length = LAYOUT.status_id, STATUS_LENGTH
    else:
        can_id, length = DATA_IDS[segment], LAYOUT.frame_length(segment)
    n = draw(st.integers(0, 8).filter(lambda k: k != length))
    return "malformed", can.Message(arbitration_id=can_id, data=draw(st.binary(min_size=n, max_size=n)),
                                    is_extended_id=False)


@st.composite
def wrong_segment(draw) -> tuple[str, can.Message]:
    """The right length at a data ID, but the header names another segment."""
    segment = draw(st.integers(0, LAYOUT.segments - 1))
    claimed = draw(st.integers(0, 15).filter(lambda s: s != segment))
    length = LAYOUT.frame_length(segment)
    body = draw(st.binary(min_size=length - HEADER_BYTES, max_size=length - HEADER_BYTES))
    data = _header(claimed, draw(st.integers(0, (1 << SEQ_BITS) - 1))) + body
    return "malformed", can.Message(arbitration_id=DATA_IDS[segment], data=data, is_extended_id=False)


@st.composite
def unused_id(draw) -> tuple[str, can.Message]:
    """An ID of the node's range that carries nothing."""
    n = draw(st.integers(0, 8))
    return "malformed", can.Message(arbitration_id=draw(st.sampled_from(UNUSED_IDS)),
                                    data=draw(st.binary(min_size=n, max_size=n)), is_extended_id=False)


@st.composite
def remote(draw) -> tuple[str, can.Message]:
    return "malformed", can.Message(arbitration_id=draw(st.integers(LO, LO + ID_RANGE - 1)), is_remote_frame=True,
                                    dlc=draw(st.integers(0, 8)), is_extended_id=False)


@st.composite
def error_frame(draw) -> tuple[str, can.Message]:
    return "error", can.Message(arbitration_id=draw(st.integers(0, 0x1FF)), is_error_frame=True,
                                data=draw(st.binary(min_size=8, max_size=8)))


@st.composite
def foreign(draw) -> tuple[str, can.Message]:
    """Another node's frame: an 11-bit ID outside the range, or any 29-bit ID."""
    n = draw(st.integers(0, 8))
    data = draw(st.binary(min_size=n, max_size=n))
    if draw(st.booleans()):
        can_id = draw(st.integers(0, 0x7FF).filter(lambda i: not LO <= i < LO + ID_RANGE))
        return "unrouted", can.Message(arbitration_id=can_id, data=data, is_extended_id=False)
    return "unrouted", can.Message(arbitration_id=draw(st.integers(0, 0x1FFFFFFF)), data=data, is_extended_id=True)


GARBAGE = st.lists(st.one_of(wrong_length(), wrong_segment(), unused_id(), remote(), error_frame(), foreign()),
                   min_size=20, max_size=200)


@pytest.mark.slow
@fuzz(max_examples=4)
@given(garbage=GARBAGE)
def test_garbage_on_the_bus_of_a_running_bridge(garbage):
    ch, port = channel(), free_port()
    plc = TimedPlc(port).start()
    raw = hold_raw(PROFILE, 150)  # 0.6 s of a still grasp, 0.4 s of silence, 0.5 s again
    try:
        with StallMeter() as stalls, running_bridge(client_config(can_node("grip", ch), port=port)) as run, \
                node_thread(PROFILE, ch, raw, RATE_HZ, faults=Faults(silent_at_s=0.6, silent_for_s=0.4)) as node, \
                open_bus("virtual", ch) as noise:

            def inject() -> None:  # spread over the node's whole run, silence included
                pause = 1.4 / len(garbage)
                for _, msg in garbage:
                    noise.send(msg)
                    time.sleep(pause)

            injector = threading.Thread(target=inject, daemon=True)
            node.start()
            injector.start()
            injector.join(10)
            node.join(10)
            assert not injector.is_alive()
            wait_for(lambda: run.counters("grip")["scans"] == 110, what="every valid scan decoded")
            wait_for(lambda: sum(run.counters("grip")[k] for k in ("malformed_frames", "error_frames"))
                     + run.counters("grip")["unrouted_frames"] == len(garbage), what="every bad frame counted")
            alive = all(t.is_alive() for t in run.bridge._threads)
            counters = run.counters("grip")
            images = plc.images()  # before the stop: its BRIDGE_OFFLINE image is tested elsewhere
            last, resumed = max(zip(node.tx.sent, node.tx.sent[1:]), key=lambda p: p[1] - p[0])
    finally:
        plc.stop()
    assert alive and not run.bridge.failure
    expected = Counter(kind for kind, _ in garbage)
    assert counters["malformed_frames"] == expected["malformed"]
    assert counters["error_frames"] == expected["error"]
    assert counters["unrouted_frames"] == expected["unrouted"]
    assert counters["bus_off"] == sum(1 for k, m in garbage if k == "error" and m.arbitration_id & 0x40)
    # garbage never tore, reordered or repeated a valid scan; only the silence is lost
    assert counters["torn_scans"] == counters["late_frames"] == counters["duplicate_frames"] == 0
    assert counters["lost_scans"] == 40 and counters["foreign_frames"] == 0
    assert not any(v["STATUS"] & Status.SLIP for _, v in images)  # a still grasp, whatever the noise
    # a pause of this whole process (bridge and PLC stand-in alike) delays the writes'
    # arrival, not the bridge's verdict: it is allowed, and nothing more
    allowed = INVALID_AFTER_S + stalls.longest(last, resumed)
    silent = [(t, v) for t, v in images if last + allowed < t < resumed]
    assert len(silent) >= 4 or allowed > 0.25, (allowed, len(silent))
    assert not any(v["STATUS"] & CLAIMS for _, v in silent), [
        round(allowed, 3), [(round(1000 * (t - last), 1), Status(v["STATUS"])) for t, v in images
                            if last - 0.05 < t < resumed]]
    # the valid traffic after the silence is a stable grasp again, up to its last frame
    end = node.tx.sent[-1]
    # (the verdict on the last frames may reach the PLC after the node's last send on a
    # loaded host; no image before end + stale_max_s can be the stale one)
    final = [v["STATUS"] for t, v in images if resumed < t < end + PROFILE.stale_max_s][-1]
    assert final & Status.STABLE and final & Status.DATA_VALID and not final & Status.SENSOR_STALE
