"""Receiver, node simulator and log replay on python-can's in-process virtual bus."""
from __future__ import annotations

import errno
import os
import subprocess
import sys
import threading
import time
import uuid

import can
import numpy as np
import pytest

from eskin_industrial.bus.can.layout import CanLayout
from eskin_industrial.bus.can.reader import BusReader, open_bus
from eskin_industrial.calibration import Calibrator
from eskin_industrial.detect import get_method
from eskin_industrial.detect.updates import UpdateTable
from eskin_industrial.errors import CanBusError
from eskin_industrial.recording import write_recording, write_updates
from eskin_industrial.sim.can_node import CanNode, Faults
from tests.helpers.can import Receiver
from tests.helpers.paths import PROFILES
from tests.helpers.scenes import grasp

PAPER = str(PROFILES / "paper-5x5.toml")


def cli(*args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "eskin_industrial", *args], capture_output=True, text=True,
                          timeout=120, env={**os.environ, **(env or {})})


def scene_raw(profile, k=600, seed=4):
    f = grasp(k, n=profile.taxels, seed=seed)
    f[:150] = 0.0
    cal = Calibrator.from_section(profile.calibration, profile.taxels)
    return np.rint(cal.to_raw(f))


def channel() -> str:
    # Not ending in digits: python-can's BLF writer takes trailing digits for a channel
    # number and fails past 65535 ("test-...99389").
    return f"test-{uuid.uuid4().hex[:8]}-bus"


def send_and_receive(profile, raw, faults=Faults(), fd=False, log=None, rate=100.0, ch: str | None = None):
    ch = ch or channel()
    layout = CanLayout.from_profile(profile, fd=fd)
    reader = BusReader(lambda: open_bus("virtual", ch))
    source = Receiver(profile, reader, layout, rate, log)
    with open_bus("virtual", ch) as tx:
        node = CanNode(layout, tx, raw, rate, profile.can.heartbeat_s, faults, burst=True)
        th = threading.Thread(target=node.run)
        th.start()
        source.run(idle_timeout_s=0.5, duration_s=30)
        th.join()
    return source, node.stats


@pytest.mark.parametrize("fd", [False, True])
def test_node_to_receiver_gives_the_offline_answer(paper_profile, fd):
    raw = scene_raw(paper_profile)
    source, stats = send_and_receive(paper_profile, raw, fd=fd)
    c = source.counters()
    assert stats.frames_sent == 600 * (1 if fd else 9) + 60
    assert source.pipeline.counters.scans == 600 and source.pipeline.counters.lost_scans == 0
    assert c["heartbeats"] == 60 and c["malformed_frames"] == c["torn_scans"] == c["rx_queue_drops"] == 0
    assert source.assembler.status.rate_hz == 100
    cal = Calibrator.from_section(paper_profile.calibration, 25)
    forces, flags = cal.to_newtons(raw)
    x, y = paper_profile.coordinates_mm
    method = get_method(paper_profile.detector.method)  # whatever the profile runs, offline and live agree
    offline = method.batch(paper_profile.detector, x, y, 100.0, np.arange(600) / 100.0, forces, flags)
    live = UpdateTable.from_updates(source.updates)
    np.testing.assert_array_equal(live.state, offline.state)
    np.testing.assert_allclose(live.r_coe, offline.r_coe, atol=1e-9)
    np.testing.assert_allclose(live.score_a, offline.score_a, atol=1e-9)
    np.testing.assert_allclose(live.t, offline.t, atol=1e-9)


def test_faults_are_counted_and_scans_never_mixed(hand_profile):
    raw = scene_raw(hand_profile, 1000)
    faults = Faults(drop=0.01, duplicate=0.01, reorder=0.01, corrupt=0.01, silent_at_s=5.0, silent_for_s=0.5, seed=2)
    source, stats = send_and_receive(hand_profile, raw, faults)
    c, p = source.counters(), source.pipeline.counters
    assert stats.dropped and stats.duplicated and stats.reordered and stats.corrupted and stats.silent_scans == 50
    # a corrupted frame may also have been duplicated
    assert stats.corrupted <= c["malformed_frames"] <= stats.corrupted + stats.duplicated
    assert c["torn_scans"] > 0 and p.lost_scans >= 50
    # every scan is either delivered or counted lost; none delivered twice
    last = source.pipeline.last_frame.seq
    assert p.scans + p.lost_scans == last + 1 and last >= 990
    assert p.dropped_by_detector == 0


@pytest.mark.parametrize("suffix", [".log", ".blf", ".asc"])
@pytest.mark.slow
def test_recorded_traffic_replays_to_the_live_output(paper_profile, tmp_path, suffix):
    raw = scene_raw(paper_profile)
    log_path = tmp_path / f"traffic{suffix}"
    log = can.Logger(log_path)
    source, _ = send_and_receive(paper_profile, raw, Faults(drop=0.005, duplicate=0.005, seed=1), log=log)
    log.stop()
    live = tmp_path / "live.csv"
    write_updates(live, UpdateTable.from_updates(source.shown))  # (the idle start's identical scans: FROZEN)
    res = cli("detect", "--profile", PAPER, "--can-log", str(log_path), "-o", str(tmp_path / "replay.csv"), "--json")
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "replay.csv").read_text() == live.read_text()
    assert f'"lost_scans": {source.pipeline.counters.lost_scans}' in res.stderr


class FlakyBus(can.BusABC):
    """A bus whose reads fail for a while (an interface going down), then work."""

    def __init__(self, inner, fail_reads):
        self.inner, self.fail_reads = inner, fail_reads
        super().__init__(channel=None)

    def _recv_internal(self, timeout):
        if self.fail_reads:
            self.fail_reads -= 1
            raise can.CanOperationError("interface down", errno.ENETDOWN)
        return self.inner._recv_internal(timeout)

    def send(self, msg, timeout=None):
        self.inner.send(msg, timeout)

    def shutdown(self):
        self.inner.shutdown()
        super().shutdown()


def test_receiver_survives_a_failing_bus_and_recovers(hand_profile):
    ch = channel()
    opens = []

    def open_():
        if len(opens) in (1, 2):  # the first two reopen attempts fail too
            opens.append("fail")
            raise CanBusError("no such device")
        opens.append("ok")
        return FlakyBus(open_bus("virtual", ch), fail_reads=1 if len(opens) == 1 else 0)

    layout = CanLayout.from_profile(hand_profile)
    reader = BusReader(open_, retry_s=0.02).start()
    source = Receiver(hand_profile, reader, layout, 100.0)
    deadline = time.monotonic() + 5
    while reader.counters["bus_reopens"] == 0 and time.monotonic() < deadline:
        time.sleep(0.01)
    assert reader.counters == {"rx_queue_drops": 0, "bus_errors": 3, "bus_reopens": 1} and reader.bus_up
    with open_bus("virtual", ch) as tx:
        CanNode(layout, tx, scene_raw(hand_profile, 50), 100.0, burst=True).run()
    source.run(idle_timeout_s=0.3, duration_s=10)
    assert source.pipeline.counters.scans == 50


def test_a_slow_consumer_drops_frames_and_counts_them(hand_profile):
    ch = channel()
    reader = BusReader(lambda: open_bus("virtual", ch), queue_frames=100).start()
    with open_bus("virtual", ch) as tx:
        for _ in range(300):
            tx.send(can.Message(arbitration_id=0x123, data=bytes(8), is_extended_id=False))
    deadline = time.monotonic() + 5
    while len(reader.queue) + reader.counters["rx_queue_drops"] < 300 and time.monotonic() < deadline:
        time.sleep(0.01)
    reader.stop()
    reader.stop()  # safe twice
    assert len(reader.queue) == 100 and reader.counters["rx_queue_drops"] == 200


def test_paced_node_keeps_absolute_deadlines(hand_profile):
    layout = CanLayout.from_profile(hand_profile)
    ch = channel()
    with open_bus("virtual", ch) as rx, open_bus("virtual", ch) as tx:
        node = CanNode(layout, tx, scene_raw(hand_profile, 100), 200.0, heartbeat_s=10.0)
        t0 = time.time()
        stats = node.run()
        first = []
        while (m := rx.recv(0.2)) is not None:
            if m.arbitration_id == layout.base_id:
                first.append(m.timestamp)
    assert stats.scans == 100 and len(first) == 100
    offsets = np.array(first) - t0 - np.arange(100) / 200.0
    # each scan leaves at start + k / rate: no accumulated drift, only scheduling jitter
    # (bounds loose enough for a loaded machine; a relative-sleep loop drifts by the
    # per-scan overhead times 100, and a burst would leave everything at offset <= 0)
    assert np.median(offsets) < 0.01 and np.median(offsets[-20:]) < 0.02
    assert offsets.min() > -0.002  # never early
    assert 0.49 < stats.elapsed_s < 0.8


@pytest.mark.slow
def test_bus_options_and_python_can_environment(tmp_path):
    rec = tmp_path / "rec.csv"
    write_recording(rec, np.arange(20) / 100.0, grasp(20))
    res = cli("node", "-p", PAPER, "-i", "virtual", "-c", "x", "--recording", str(rec), "--burst")
    assert res.returncode == 0, res.stderr
    assert "node: 20 scans, 182 frames" in res.stderr  # 20 x 9 segments + 2 heartbeats
    res = cli("node", "-p", PAPER, "--recording", str(rec), "--burst", "--fd", "-q",
              env={"CAN_INTERFACE": "virtual", "CAN_CHANNEL": "y"})
    assert res.returncode == 0 and res.stderr == ""
    res = cli("receive", "-p", PAPER, "--duration", "0.2", env={"CAN_INTERFACE": "virtual", "CAN_CHANNEL": "y"})
    assert res.returncode == 0 and '"scans": 0' in res.stderr
    res = cli("receive", "-p", PAPER, "-i", "nosuchbus", "-c", "x", "--duration", "0.1")
    assert res.returncode == 3 and res.stderr.count("\n") == 1
    assert "cannot open CAN bus (interface 'nosuchbus', channel 'x')" in res.stderr and "virtual" in res.stderr
    res = cli("node", "-p", PAPER, "-i", "virtual", "--recording", str(rec), "--drop", "2")
    assert res.returncode == 2 and "expected a probability" in res.stderr


def test_python_can_config_file_is_honoured(tmp_path):
    (tmp_path / ".canrc").write_text("[default]\ninterface = virtual\nchannel = from-config\n")
    env = {k: v for k, v in os.environ.items() if not k.startswith("CAN_")}
    res = subprocess.run([sys.executable, "-m", "eskin_industrial", "receive", "-p", PAPER, "--duration", "0.2"],
                         capture_output=True, text=True, timeout=120, env={**env, "HOME": str(tmp_path)})
    assert res.returncode == 0, res.stderr
    assert '"scans": 0' in res.stderr


def test_detect_needs_exactly_one_input(tmp_path):
    res = cli("detect", "-p", PAPER)
    assert res.returncode == 2 and "exactly one of INPUT.csv or --can-log" in res.stderr
    res = cli("detect", "-p", PAPER, "--can-log", str(tmp_path / "none.log"))
    assert res.returncode == 2 and "cannot read CAN log" in res.stderr
    bad = tmp_path / "bad.log"
    bad.write_text("(1.0) vcan0 200#0011\nnot a candump line at all\n")
    res = cli("detect", "-p", PAPER, "--can-log", str(bad))
    assert res.returncode == 2 and res.stderr.startswith("eskin-bus: error:") and res.stderr.count("\n") == 1


def test_one_scene_through_the_node(tmp_path):
    res = cli("node", "-p", PAPER, "-i", "virtual", "-c", "s", "--scene", "case2", "--burst", "--rate", "100")
    assert res.returncode == 0, res.stderr
    assert "node:" in res.stderr and "frames" in res.stderr


def test_fd_frames_use_bit_rate_switching(paper_profile):
    ch = channel()
    layout = CanLayout.from_profile(paper_profile, fd=True)
    with open_bus("virtual", ch) as rx, open_bus("virtual", ch) as tx:
        CanNode(layout, tx, scene_raw(paper_profile, 3), 100.0, burst=True).run()
        got = [m for m in iter(lambda: rx.recv(0.2), None)]
    data = [m for m in got if m.arbitration_id == layout.base_id]
    assert len(data) == 3 and all(m.is_fd and m.bitrate_switch and len(m.data) == 64 for m in data)


def test_a_recording_that_fails_to_write_never_stops_reception(paper_profile, tmp_path):
    """python-can's BLF writer cannot store this channel name (its trailing digits
    overflow the 16-bit channel field): every write fails, every scan still decodes."""
    raw = scene_raw(paper_profile)
    log = can.Logger(tmp_path / "traffic.blf")
    source, stats = send_and_receive(paper_profile, raw, log=log, ch=f"rec-{uuid.uuid4().hex[:6]}-99389")
    log.stop()
    c = source.counters()
    assert source.pipeline.counters.scans == stats.scans == len(raw)
    assert c["log_write_errors"] == c["frames"] + c["foreign_frames"] > 0
