"""Nothing grows without bound in a bridge that runs for months: a flood of frames
fills a small receive queue, which drops and counts instead of growing, and the
bridge still answers; a log stream that blocks costs dropped log lines, counted,
never a blocked caller."""

from __future__ import annotations

import os
import threading
import time

from eskin_industrial.bridge.logs import QUEUE_RECORDS, EventLog
from eskin_industrial.bus.can.layout import CanLayout
from eskin_industrial.bus.can.reader import open_bus
from eskin_industrial.modbus.pymodbus_io import TcpMaster
from eskin_industrial.outputs.plc.image import IMAGE_COUNT
from eskin_industrial.outputs.plc.image import decode_registers as decode
from eskin_industrial.sim.can_node import CanNode
from tests.helpers.bridge import can_node, channel, hold_raw, running_bridge, server_config, wait_for

QUEUE_FRAMES = 50


def test_a_flood_fills_a_small_queue_which_drops_and_counts(paper_profile):
    ch = channel()
    layout = CanLayout.from_profile(paper_profile)
    sent: list[int] = []
    peak: list[int] = [0]

    def flood(bridge) -> None:
        # Buses are open, threads not yet running: 2000 scans wait on the bus for the
        # reader, which then takes them far faster than the loop can detect.
        with open_bus("virtual", ch) as tx:
            sent.append(CanNode(layout, tx, hold_raw(paper_profile, 2000), 1000.0, burst=True).run().frames_sent)

    with running_bridge(server_config(can_node("grip", ch), queue_frames=QUEUE_FRAMES), before_start=flood) as run:
        reader = run.bridge.groups[0][0].reader
        stop = threading.Event()

        def watch() -> None:
            while not stop.wait(0.0005):
                peak[0] = max(peak[0], len(reader.queue))

        watcher = threading.Thread(target=watch, daemon=True)
        watcher.start()
        try:
            wait_for(lambda: (lambda c: c["frames"] + c["rx_queue_drops"] == sent[0])(run.counters("grip")),
                     timeout_s=20, what="every frame processed or dropped")
        finally:
            stop.set()
            watcher.join(5)
        # the bridge still answers, with a heartbeat that moves
        plc = TcpMaster("127.0.0.1", run.bridge.server.server.tcp[1], timeout_s=1.0)  # type: ignore[union-attr]
        plc.connect()
        try:
            beat = decode(plc.read_holding(0, IMAGE_COUNT), "big")["HEARTBEAT"]
            wait_for(lambda: decode(plc.read_holding(0, IMAGE_COUNT), "big")["HEARTBEAT"] != beat,
                     what="the heartbeat going on")
        finally:
            plc.close()
        c = run.counters("grip")
    assert c["rx_queue_drops"] > 0 and peak[0] <= QUEUE_FRAMES
    # what was dropped shows as torn scans and scans lost, never as a mixed scan
    assert c["scans"] < 2000 and c["scans"] + c["lost_scans"] <= 2000 and c["lost_scans"] > 0
    assert not run.bridge.failure


class _Drain(threading.Thread):
    def __init__(self, fd: int) -> None:
        super().__init__(daemon=True)
        self.fd = fd
        self.data = bytearray()

    def run(self) -> None:
        while chunk := os.read(self.fd, 65536):
            self.data += chunk


def test_a_blocked_log_stream_drops_lines_and_never_blocks_the_caller():
    r, w = os.pipe()  # a pipe nobody reads: its buffer fills, then every write blocks
    stream = os.fdopen(w, "w")
    log = EventLog(stream, "json")
    extra = 500
    total = QUEUE_RECORDS + extra + 2000  # the pipe's buffer takes some lines first
    worst = 0.0
    t0 = time.perf_counter()
    for i in range(total):
        t = time.perf_counter()
        log.event("state", node="grip", state="stable", seq=i, padding="x" * 200)
        worst = max(worst, time.perf_counter() - t)
    elapsed = time.perf_counter() - t0
    # A blocking call would wait here for ever (nobody reads the pipe); the bound only
    # allows for a thread descheduled on a loaded machine (0.64 s once, a CI run beside
    # three other workers on two cores)
    assert worst < 2.0 and elapsed < 10.0
    assert log.drops >= extra, log.drops
    drain = _Drain(r)
    drain.start()  # someone reads at last: what was queued is written out
    log.close()
    stream.close()
    drain.join(10)
    os.close(r)
    lines = drain.data.decode().splitlines()
    assert len(lines) == total - log.drops
    assert '"seq": 0,' in lines[0] and '"level": "info"' in lines[0]


def test_closing_the_log_of_a_stream_that_never_moves_gives_up_in_time():
    """SIGTERM with stderr stuck (a stopped reader of the journal pipe): the shutdown
    neither raises on the full queue nor waits for ever."""
    r, w = os.pipe()
    stream = os.fdopen(w, "w")
    log = EventLog(stream, "json")
    for i in range(QUEUE_RECORDS + 2000):
        log.event("state", seq=i, padding="x" * 200)
    t0 = time.perf_counter()
    log.close(timeout_s=0.3)
    assert time.perf_counter() - t0 < 2.0
    drain = _Drain(r)
    drain.start()  # the stream moves again: a second close writes the rest and ends the thread
    log.close(timeout_s=10)
    stream.close()
    drain.join(10)
    os.close(r)
    assert log.drops > 0
