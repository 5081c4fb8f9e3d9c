"""The RTU side: node simulator and poller on a socat pty pair, and the faults of a
serial line: a silent node, garbled frames, exception responses."""

from __future__ import annotations

import dataclasses
import threading
import time

import numpy as np
import pytest
import serial

from eskin_industrial.bridge.loop import NodeLoop
from eskin_industrial.bus.modbus.codec import decode_scans, encode_scan
from eskin_industrial.bus.modbus.rtu import RtuSource
from eskin_industrial.bus.source import Source
from eskin_industrial.calibration import Calibrator
from eskin_industrial.outputs.base import Sink
from eskin_industrial.outputs.plc.image import Status
from eskin_industrial.profile import ModbusNodeSection
from eskin_industrial.sim.modbus_node import NodeSimulator
from tests.helpers.modbus import mbpoll, mbpoll_values, pty_pair, slip_recording


def with_node(profile, **changes):
    node = dataclasses.replace(profile.modbus.node, **changes)
    return dataclasses.replace(profile, modbus=dataclasses.replace(profile.modbus, node=node))


def crc16(data: bytes) -> bytes:
    """Modbus CRC-16 (poly 0xA001, init 0xFFFF), low byte first: written here, from the spec."""
    crc = 0xFFFF
    for b in data:
        crc ^= b
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return bytes([crc & 0xFF, crc >> 8])


class RecordingSink(Sink):
    """Keeps every publication's registers, rendered as the PLC output renders them."""

    def __init__(self, settings=None):
        super().__init__()
        from eskin_industrial import load_profile
        from eskin_industrial.outputs.plc.image import PlcImage
        from tests.helpers.paths import PROFILES

        self.image = PlcImage(settings or load_profile(PROFILES / "paper-5x5.toml").modbus.plc)
        self.published: list[list[int]] = []

    def _publish(self, snapshot):
        self.published.append(self.image.render(snapshot))


@pytest.mark.parametrize("value_type", ["uint16", "int16", "uint32", "int32"])
@pytest.mark.parametrize("word_order", ["big", "little"])
def test_register_codec_round_trip(value_type, word_order):
    node = ModbusNodeSection(value_type=value_type, word_order=word_order)
    lo, hi = {"uint16": (0, 65535), "int16": (-32768, 32767), "uint32": (0, 2**32 - 1),
              "int32": (-(2**31), 2**31 - 1)}[value_type]
    raw = np.array([lo, hi, (lo + hi) // 2, lo + 1, 12345 % (hi + 1)], dtype=np.float64)
    regs = encode_scan(node, raw)
    assert len(regs) == 5 * node.words_per_taxel and all(0 <= r <= 0xFFFF for r in regs)
    np.testing.assert_array_equal(decode_scans(node, regs), raw)
    assert encode_scan(node, [hi + 10.0, lo - 10.0, np.nan])[: node.words_per_taxel] == encode_scan(node, [hi])


def test_poller_reads_the_node_and_mbpoll_agrees(paper_profile, tmp_path):
    t, f, _ = slip_recording(still_s=0.5, slip_s=0.0, after_s=0.0)
    cal = Calibrator.from_section(paper_profile.calibration, 25)
    with pty_pair(tmp_path) as (a, b):
        with NodeSimulator(paper_profile, a, f, 100.0) as node:
            expected = {tuple(s) for s in node.scans}
            # A generous timeout: a loaded test machine must not turn into bus errors here.
            poller = RtuSource(with_node(paper_profile, timeout_s=1.0), b).open()
            try:
                polled = [poller.poll_once() for _ in range(20)]
            finally:
                poller.close()
            # polled back to back, faster than the node scans: a scan polled again is used once
            scans = [s for s in polled if s is not None]
            assert poller.stats.scans == len(scans) >= 2 and poller.stats.scans + poller.stats.repeats == 20
            assert poller.stats.replays == 0 and not any(s.flags for s in scans)
            assert poller.stats.bus_errors == 0 and not poller.bus_fault
            for s in scans:
                assert tuple(int(v) for v in s.raw) in expected
            forces, flags = cal.to_newtons(scans[-1].raw)
            assert abs(forces.sum() - 6.0) < 0.2 and flags == 0
            assert [s.seq for s in scans] == list(range(len(scans)))  # none lost
            assert all(b_.rx_time > a_.rx_time for a_, b_ in zip(scans, scans[1:]))
            # libmodbus reads the same input registers (-t 3); the scene is frozen first.
            node._stop.set()
            node._thread.join()
            node.registers.scan = node.scans[0]
            out = mbpoll("-m", "rtu", "-b", "115200", "-P", "none", "-a", "1", "-t", "3", "-r", "1", "-c", "25", "-1", b)
            assert out.returncode == 0, out.stdout + out.stderr
            got = mbpoll_values(out.stdout)
            assert [got[i + 1] for i in range(25)] == node.scans[0]


def test_silent_node_sets_stale_and_fault_and_never_stalls(paper_profile, tmp_path):
    t, f, _ = slip_recording(still_s=1.0, slip_s=0.0, after_s=0.0)
    node_cfg = paper_profile.modbus.node
    with pty_pair(tmp_path) as (a, b):
        node = NodeSimulator(paper_profile, a, f, 100.0).start()
        poller = RtuSource(paper_profile, b).open()
        sink = RecordingSink()
        bridge = NodeLoop(paper_profile, poller, [sink])
        try:
            deadline = time.monotonic() + 5
            while not (bridge.pipeline.last_update is not None and bridge.pipeline.last_update.valid):
                assert time.monotonic() < deadline
                bridge.step()
            bridge.publish_if_due(True)
            assert Status(sink.published[-1][0]) & Status.DATA_VALID
            node.stop()  # the node stops answering
            budget = (node_cfg.retries + 1) * node_cfg.timeout_s
            t0 = time.monotonic()
            steps = 0
            while time.monotonic() - t0 < paper_profile.stale_s + 0.3:
                s0 = time.monotonic()
                bridge.step()
                assert time.monotonic() - s0 < budget + 0.1  # never stalls longer than the retry budget
                steps += 1
            bridge.publish_if_due(True)
            status = Status(sink.published[-1][0])
            assert status & Status.SENSOR_STALE and status & Status.BUS_FAULT
            assert not status & (Status.DATA_VALID | Status.STABLE | Status.SLIP | Status.CONTACT)
            c = poller.stats
            assert c.timeouts >= node_cfg.fault_after_failures and c.failed_polls >= steps - 1
            assert bridge.pipeline.counters.scans == c.scans  # failed polls are not scans
            assert bridge.counters()["rtu_timeouts"] == c.timeouts
            assert sink.published[-1][17] == c.bus_errors  # BUS_ERRORS, low word (big word order)
            # The node comes back: fault and stale clear at once, DATA_VALID after the warm-up.
            node = NodeSimulator(paper_profile, a, f, 100.0).start()
            deadline = time.monotonic() + 5
            while not Status(sink.published[-1][0]) & Status.DATA_VALID:
                assert time.monotonic() < deadline, Status(sink.published[-1][0])
                bridge.step()
            status = Status(sink.published[-1][0])
            assert not status & (Status.BUS_FAULT | Status.SENSOR_STALE) and status & Status.STABLE
        finally:
            poller.close()
            node.stop()


def test_garbled_frames_and_exceptions_are_counted_and_survived(paper_profile, tmp_path):
    prof = with_node(paper_profile, retries=0, timeout_s=0.1)
    with pty_pair(tmp_path) as (a, b):
        poller = RtuSource(prof, b).open()
        fake = serial.Serial(a, 115200, timeout=1.0)
        try:
            def answer(reply: bytes) -> None:
                request = fake.read(8)
                assert len(request) == 8 and request[:2] == b"\x01\x04" and crc16(request[:6]) == request[6:]
                fake.write(reply)

            payload = bytes([1, 4, 50]) + bytes(range(50))
            good = payload + crc16(payload)
            replies = [good[:-1] + bytes([good[-1] ^ 0xFF]),  # bad CRC
                       bytes([0xFF, 0x00, 0x13, 0x37]) * 8,  # line noise
                       bytes([1, 0x84, 2]) + crc16(bytes([1, 0x84, 2])),  # exception: illegal address
                       good]
            th = threading.Thread(target=lambda: [answer(r) for r in replies], daemon=True)
            th.start()
            results = [poller.poll_once() for _ in replies]
            th.join(timeout=5)
            c = poller.stats
            assert results[:3] == [None, None, None]
            assert results[3] is not None and list(results[3].raw[:3]) == [0x0001, 0x0203, 0x0405]
            assert c.crc_errors >= 1 and c.exceptions == 1
            assert c.crc_errors + c.timeouts == 2 and c.scans == 1 and c.failed_polls == 3
        finally:
            fake.close()
            poller.close()


def test_exception_responses_from_a_misconfigured_node(paper_profile, tmp_path):
    node_prof = with_node(paper_profile, start_address=100)
    with pty_pair(tmp_path) as (a, b):
        t, f, _ = slip_recording(still_s=0.2, slip_s=0.0, after_s=0.0)
        with NodeSimulator(node_prof, a, f, 100.0):
            poller = RtuSource(paper_profile, b).open()  # asks for address 0
            try:
                assert poller.poll_once() is None
                assert poller.stats.exceptions == paper_profile.modbus.node.retries + 1
                assert poller.stats.timeouts == 0
            finally:
                poller.close()


def test_hand_profile_holding_registers_unit_2(hand_profile, tmp_path):
    """The hand's node: function 3 (holding registers), unit 2, 12-bit ADC counts."""
    f = np.full((50, 20), 1.0)
    f[:, 7] = 4.0
    with pty_pair(tmp_path) as (a, b):
        with NodeSimulator(hand_profile, a, f, 100.0) as node:
            poller = RtuSource(hand_profile, b).open()
            try:
                scan = poller.poll_once()
            finally:
                poller.close()
            assert scan is not None and list(scan.raw) == node.scans[0] == [550] * 7 + [1300] + [550] * 12
            out = mbpoll("-m", "rtu", "-b", "115200", "-P", "none", "-a", "2", "-t", "4", "-r", "1", "-c", "20",
                         "-1", b)
            assert out.returncode == 0, out.stdout + out.stderr
            assert [mbpoll_values(out.stdout)[i + 1] for i in range(20)] == node.scans[0]
            out = mbpoll("-m", "rtu", "-b", "115200", "-P", "none", "-a", "2", "-t", "3", "-r", "1", "-1", b)
            assert out.returncode != 0  # input registers: not this node's function


def test_line_noise_never_becomes_data(paper_profile, tmp_path):
    """Bursts of noise on a live line: polls may fail (counted), but every scan that
    gets through is one the node really sent."""
    t, f, _ = slip_recording(still_s=1.0, slip_s=0.0, after_s=0.0)
    prof = with_node(paper_profile, timeout_s=0.2)
    rng = np.random.default_rng(3)
    with pty_pair(tmp_path) as (a, b):
        with NodeSimulator(prof, a, f, 100.0) as node:
            expected = {tuple(s) for s in node.scans}
            noise = serial.Serial(a, 115200)  # a second writer on the node's end of the line
            stop = threading.Event()

            def inject():
                while not stop.wait(0.013):
                    noise.write(rng.integers(0, 256, int(rng.integers(1, 40)), dtype=np.uint8).tobytes())

            th = threading.Thread(target=inject, daemon=True)
            th.start()
            poller = RtuSource(prof, b).open()
            try:
                scans = [poller.poll_once() for _ in range(60)]
            finally:
                stop.set()
                th.join(timeout=2)
                noise.close()
            failed, repeats = poller.stats.failed_polls, poller.stats.repeats
            try:
                stop.clear()
                after = [poller.poll() for _ in range(10)]  # quiet line again, at the node's pace
            finally:
                poller.close()
    good = [s for s in scans if s is not None]
    c = poller.stats
    # (a scan polled again, back to back, is used once: a repeat)
    assert c.failed_polls + c.repeats + c.scans == 70 and c.scans == len(good) + sum(s is not None for s in after)
    for s in good + [s for s in after if s is not None]:
        assert tuple(int(v) for v in s.raw) in expected
    # recovers once the noise stops: at most the noise's last bytes in flight fail a poll;
    # a repeat (the node's next scan not yet due, a loaded machine's pace) is no line fault
    failed_after, repeats_after = c.failed_polls - failed, c.repeats - repeats
    assert failed_after <= 2, (failed_after, repeats_after)
    assert sum(s is not None for s in after) >= 5


def test_stale_is_published_at_once_not_at_the_next_refresh(paper_profile):
    """A status bit that changes (here SENSOR_STALE) goes out in the step that sees it."""
    import dataclasses as dc

    slow = dc.replace(paper_profile, output=dc.replace(paper_profile.output, refresh_s=60.0, stale_s=0.05))

    class Frozen(Source):
        """A source whose one scan came just now, and then nothing."""

        def __init__(self):
            super().__init__()
            self._last_rx = time.monotonic()

        def _poll(self, timeout_s):
            time.sleep(0.005)
            return None

    sink = RecordingSink()
    bridge = NodeLoop(slow, Frozen(), [sink])
    bridge.step()
    assert len(sink.published) == 1 and not Status(sink.published[0][0]) & Status.SENSOR_STALE
    deadline = time.monotonic() + 1.0
    while not Status(sink.published[-1][0]) & Status.SENSOR_STALE:
        assert time.monotonic() < deadline
        bridge.step()
    assert len(sink.published) == 2  # no refresh in between (60 s), the change went out alone


def test_scan_counter_gives_node_time_and_drops_repeats(paper_profile, tmp_path):
    prof = with_node(paper_profile, counter_register=True, poll_hz=250.0, timeout_s=0.5)
    f = np.tile(np.linspace(0.5, 5.0, 40)[:, None], (1, 25))  # scan k is recognisable by its force
    with pty_pair(tmp_path) as (a, b):
        with NodeSimulator(prof, a, f, 100.0) as node:  # the node scans at 100 Hz, we poll at 250 Hz
            poller = RtuSource(prof, b).open()
            try:
                scans = [s for s in (poller.poll() for _ in range(150)) if s is not None]
            finally:
                poller.close()
            first_counter = poller._counter - scans[-1].seq
            table = node.scans
    c = poller.stats
    assert c.repeats > 0 and c.scans == len(scans) and c.failed_polls == 0
    seqs = [s.seq for s in scans]
    assert seqs == sorted(set(seqs))  # each node scan once, in order
    assert seqs[-1] - seqs[0] + 1 - len(seqs) <= max(3, len(seqs) // 10)  # 2.5x the node rate: few lost
    for s in scans:
        assert abs(s.t - s.seq / prof.sensor.rate_hz) < 1e-12  # node time
        assert [int(v) for v in s.raw] == table[(first_counter + s.seq) % len(table)]
