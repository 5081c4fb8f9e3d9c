"""A replayed CAN log whose clock jumps, or whose timestamps are no numbers: the jump
is one log line and the replay paces on from the new clock (never the rest of the
log in a burst); a frame with a NaN or infinite time is dropped and counted, and the
replay goes on (never an OverflowError that ends the source)."""

from __future__ import annotations

import logging
import math
import time
from pathlib import Path

import can
import numpy as np
import pytest

from eskin_industrial.bridge.config import NodeConfig
from eskin_industrial.bus.can.layout import CanLayout
from eskin_industrial.bus.can.log import LogPlayer
from tests.helpers.bridge import PAPER, hold_raw, running_bridge, server_config, wait_for
from tests.helpers.can_frames import scans_to_messages

RATE_HZ = 100.0


def messages(paper_profile, scans: int, t0: float, first_seq: int = 0) -> list[can.Message]:
    layout = CanLayout.from_profile(paper_profile)
    msgs = scans_to_messages(layout, (np.arange(scans) + first_seq) % 4096, hold_raw(paper_profile, scans), RATE_HZ)
    for m in msgs:
        m.timestamp += t0 - first_seq / RATE_HZ
    return msgs


def play(msgs: list[can.Message], timeout_s: float = 10.0) -> LogPlayer:
    player = LogPlayer("traffic.log", iter(msgs)).start()
    deadline = time.monotonic() + timeout_s
    while not player.done:
        assert time.monotonic() < deadline, "the replay did not end"
        time.sleep(0.01)
    player.stop()
    return player


def test_a_clock_jump_back_is_one_line_and_the_replay_paces_on(paper_profile, caplog):
    # 0.6 s of traffic, then the clock set back 30 s and 0.6 s more
    msgs = messages(paper_profile, 60, 1000.0) + messages(paper_profile, 60, 970.6, first_seq=60)
    with caplog.at_level(logging.WARNING, logger="eskin_industrial"):
        player = play(msgs)
    times = [m.timestamp for m in player.queue]
    assert len(times) == len(msgs)
    span = times[-1] - times[0]
    assert span >= 1.15, f"the 1.2 s of traffic replayed in {span:.3f} s"
    assert np.all(np.diff(times) >= 0)  # the replay's clock never goes back
    jumps = [r for r in caplog.records if r.getMessage() == "can_log_clock_jump"]
    assert len(jumps) == 1 and player.counters["log_clock_jumps"] == 1
    assert jumps[0].fields["jump_s"] == pytest.approx(-30.0, abs=0.02)  # type: ignore[attr-defined]


def test_frames_a_few_milliseconds_out_of_order_are_no_jump(paper_profile, caplog):
    msgs = messages(paper_profile, 30, 1000.0)
    msgs[40].timestamp -= 0.004  # as a multi-channel log interleaves its channels
    with caplog.at_level(logging.WARNING, logger="eskin_industrial"):
        player = play(msgs)
    assert player.counters["log_clock_jumps"] == 0 and not caplog.records


def test_nan_and_infinite_times_are_dropped_frame_by_frame(paper_profile, caplog):
    msgs = messages(paper_profile, 30, 1000.0)
    for i, bad in ((5, math.nan), (100, math.inf), (101, -math.inf), (200, math.nan)):
        msgs[i].timestamp = bad
    with caplog.at_level(logging.WARNING, logger="eskin_industrial"):
        player = play(msgs)
    assert not player.last_error and player.counters["bus_errors"] == 0
    assert player.counters["log_bad_times"] == 4 and len(player.queue) == len(msgs) - 4
    assert all(math.isfinite(m.timestamp) for m in player.queue)
    assert [r.getMessage() for r in caplog.records] == ["can_log_bad_time"]  # one line, at the first


def write_log(path: Path, msgs: list[can.Message]) -> Path:
    """A candump -L log as a clock that jumps leaves it (python-can's writer holds a
    time that goes back at the one before: it cannot write such a log)."""
    lines = [f"({m.timestamp:.6f}) can0 {m.arbitration_id:03X}#{bytes(m.data).hex().upper()}\n" for m in msgs]
    path.write_text("".join(lines), encoding="ascii")
    return path


@pytest.mark.slow
def test_the_bridge_replays_a_jumping_log_with_bad_times_to_its_end(paper_profile, tmp_path):
    """A candump log: 1 s of traffic, an infinite time, the clock 30 s back, a NaN, 1 s
    more.  The node's scans all decoded, paced (about 2 s), one clock-jump line, the
    source never failed."""
    msgs = messages(paper_profile, 100, 1.7e9) + messages(paper_profile, 100, 1.7e9 - 29.0, first_seq=100)
    msgs[300].timestamp, msgs[1200].timestamp = math.inf, math.nan
    path = write_log(tmp_path / "jumps.log", msgs)
    node = NodeConfig.of("grip", PAPER, "can-log", path=str(path), outputs={"plc": {"base_address": 0}})
    with running_bridge(server_config(node)) as run:
        start = time.monotonic()
        wait_for(lambda: run.bridge.runs[0].loop.source.done, timeout_s=10, what="the end of the replay")
        took = time.monotonic() - start
        counters = run.counters("grip")
        events = run.log.events()
    names = [e["event"] for e in events]
    assert "source_failed" not in names, [e for e in events if e["event"] == "source_failed"]
    assert names.count("can_log_clock_jump") == 1 and names.count("can_log_bad_time") == 1
    assert counters["log_clock_jumps"] == 1 and counters["log_bad_times"] == 2
    # two scans lost with their frames (the bad times), every other one decoded
    assert counters["scans"] == 198 and counters["torn_scans"] == 2
    assert took >= 1.8, f"2 s of traffic replayed in {took:.2f} s"
