"""On a real SocketCAN stack (vcan0): our node and receiver, and peers nobody here
wrote (can-utils' cansend, canplayer, candump)."""
from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import can
import numpy as np
import pytest

from eskin_industrial import Calibrator, load_profile
from eskin_industrial.bus.can.layout import CanLayout, NodeState, NodeStatus, decode_messages
from eskin_industrial.bus.can.log import read_can_log
from eskin_industrial.bus.can.reader import BusReader, open_bus
from eskin_industrial.detect import get_method
from eskin_industrial.recording import write_recording
from tests.helpers.can import Receiver

PROFILES = Path(__file__).resolve().parents[2] / "profiles"
PAPER, HAND = str(PROFILES / "paper-5x5.toml"), str(PROFILES / "hand-4x5.toml")


def forces(k: int, n: int, seed: int = 0) -> np.ndarray:
    """A grasp that presses, holds and slides: (k, n) newtons."""
    rng = np.random.default_rng(seed)
    t = np.arange(k) / k
    centre = 1.0 + 2.0 * t[:, None]
    col = np.arange(n) % 5
    f = 4.0 * np.exp(-((col[None, :] - centre) ** 2)) * np.minimum(1.0, 3 * t[:, None])
    return np.clip(f + rng.normal(0, 0.01, (k, n)), 0.0, 6.0)


# A command's start in the emulated machine (software emulation, numpy's import
# included) took over 60 s once while the other worker ran its tests: a bound, not a pace
def eskin(*args: str, timeout: float = 180) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "eskin_industrial", *args], capture_output=True, text=True,
                          timeout=timeout)


def start_source(profile, channel: str, fd: bool = False, rate: float = 100.0) -> Receiver:
    layout = CanLayout.from_profile(profile, fd=fd)
    reader = BusReader(lambda: open_bus("socketcan", channel, fd=fd)).start()
    return Receiver(profile, reader, layout, rate)


@pytest.mark.parametrize("fd", [False, True], ids=["classic", "fd"])
def test_node_simulator_to_receiver(vcan, tmp_path, fd):
    prof = load_profile(PAPER)
    f = forces(300, 25)
    rec = tmp_path / "rec.csv"
    write_recording(rec, np.arange(300) / 100.0, f)
    source = start_source(prof, vcan, fd)
    granted = source.reader.bus.socket.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
    res = eskin("node", "-p", PAPER, "-i", "socketcan", "-c", vcan, "--recording", str(rec), "--burst",
                *(["--fd"] if fd else []))
    assert res.returncode == 0, res.stderr
    source.run(idle_timeout_s=1.0, duration_s=30)
    c, counters = source.pipeline.counters, source.counters()
    assert granted >= 4 * 1024 * 1024  # the receive buffer was enlarged
    assert c.scans == 300 and c.lost_scans == 0 and counters["torn_scans"] == counters["malformed_frames"] == 0
    assert counters["heartbeats"] == 30
    np.testing.assert_allclose(source.pipeline.last_frame.forces, f[-1], atol=0.003)
    x, y = prof.coordinates_mm  # as many updates as the profile's method gives offline
    offline = get_method(prof.detector.method).batch(prof.detector, x, y, 100.0, np.arange(300) / 100.0, f)
    assert len(source.updates) == len(offline) > 0


def cansend(channel: str, can_id: int, data: bytes) -> None:
    frame = f"{can_id:03X}#{data.hex().upper()}"
    subprocess.run(["cansend", channel, frame], check=True, timeout=10)


def test_cansend_frames_are_decoded_and_bad_ones_counted(vcan):
    prof = load_profile(HAND)
    layout = CanLayout.from_profile(prof)
    cal = Calibrator.from_section(prof.calibration, 20)
    raw = np.rint(cal.to_raw(forces(3, 20, seed=1)))
    source = start_source(prof, vcan)
    frames = layout.encode(np.arange(3), raw)
    for k, scan in enumerate(frames):
        for can_id, data in scan:
            cansend(vcan, can_id, data)
        if k == 1:
            cansend(vcan, 0x281, b"\x01\x10\x00")  # a segment three bytes long
            cansend(vcan, 0x123, bytes(8))  # somebody else's frame
    cansend(vcan, 0x28F, layout.encode_status(NodeStatus(2, NodeState.RUNNING, 0, 0, 100, 2)))
    source.run(idle_timeout_s=1.0, duration_s=20)
    c = source.counters()
    assert source.pipeline.counters.scans == 3 and c["malformed_frames"] == 1 and c["foreign_frames"] == 1
    assert c["heartbeats"] == 1 and source.assembler.status.rate_hz == 100
    np.testing.assert_allclose(source.pipeline.last_frame.forces, cal.to_newtons(raw[2])[0])


def test_canplayer_replays_a_log_with_malformed_frames(vcan, tmp_path):
    prof = load_profile(HAND)
    layout = CanLayout.from_profile(prof)
    cal = Calibrator.from_section(prof.calibration, 20)
    raw = np.rint(cal.to_raw(forces(40, 20, seed=2)))
    lines, t = [], 1000.0
    for k, scan in enumerate(layout.encode(np.arange(40), raw)):
        for s, (can_id, data) in enumerate(scan):
            if k == 10 and s == 2:
                continue  # a lost segment: scan 10 is torn
            if k == 20 and s == 1:
                data = data[:5]  # a short frame
            if k == 30 and s == 0:
                data = bytes([data[0], 0x30]) + data[2:]  # header says segment 3
            t += 0.0005
            lines.append(f"({t:.6f}) can0 {can_id:03X}#{data.hex().upper()}")
    log = tmp_path / "bad.log"
    log.write_text("\n".join(lines) + "\n")
    source = start_source(prof, vcan)
    subprocess.run(["canplayer", "-I", str(log), f"{vcan}=can0"], check=True, timeout=30)
    source.run(idle_timeout_s=1.0, duration_s=20)
    c, p = source.counters(), source.pipeline.counters
    assert c["malformed_frames"] == 2 and c["torn_scans"] == 3 and p.scans == 37 and p.lost_scans == 3
    offline, _ = decode_messages(layout, read_can_log(log), 100.0)
    assert [s.seq for s in offline] == [k for k in range(40) if k not in (10, 20, 30)]


def test_candump_capture_of_the_node_decodes_to_the_scene(vcan, tmp_path):
    prof = load_profile(HAND)
    f = forces(100, 20, seed=3)
    rec = tmp_path / "scene.csv"
    write_recording(rec, np.arange(100) / 200.0, f)
    cap = tmp_path / "capture.log"
    with open(cap, "w") as out:
        dump = subprocess.Popen(["candump", "-L", vcan], stdout=out)
        time.sleep(0.5)
        res = eskin("node", "-p", HAND, "-i", "socketcan", "-c", vcan, "--recording", str(rec), "--rate", "200")
        time.sleep(0.5)
        dump.terminate()
        dump.wait(timeout=10)
    assert res.returncode == 0, res.stderr
    scans, asm = decode_messages(CanLayout.from_profile(prof), read_can_log(cap), 200.0)
    assert [s.seq for s in scans] == list(range(100)) and asm.counters["heartbeats"] == 5
    cal = Calibrator.from_section(prof.calibration, 20)
    decoded, _ = cal.to_newtons(np.array([s.raw for s in scans]))
    np.testing.assert_allclose(decoded, f, atol=0.5 / 250 + 1e-9)  # half a count of 250 per newton
    stamps = np.array([m.timestamp for m in read_can_log(cap) if m.arbitration_id == 0x280])
    # paced at 200 Hz (99 periods, 0.495 s), not a burst (a few ms): the node keeps an
    # absolute schedule, so a first frame sent late (the emulated machine) shortens the span
    assert 0.4 < stamps[-1] - stamps[0] < 2.0


def test_receiver_recovers_when_the_interface_comes_back(vcan):
    prof = load_profile(HAND)
    layout = CanLayout.from_profile(prof)
    cal = Calibrator.from_section(prof.calibration, 20)
    frames = layout.encode(np.arange(4), np.rint(cal.to_raw(forces(4, 20, seed=4))))
    source = start_source(prof, vcan)
    with can.Bus(interface="socketcan", channel=vcan) as tx:
        for scan in frames[:2]:
            for can_id, data in scan:
                tx.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))
        time.sleep(0.3)
        source.poll()
        subprocess.run(["ip", "link", "set", vcan, "down"], check=True, timeout=10)
        time.sleep(0.5)
        subprocess.run(["ip", "link", "set", vcan, "up"], check=True, timeout=10)
        time.sleep(0.5)
    with can.Bus(interface="socketcan", channel=vcan) as tx:
        for scan in frames[2:]:
            for can_id, data in scan:
                tx.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))
    source.run(idle_timeout_s=1.0, duration_s=10)
    r = source.reader.counters
    assert source.pipeline.counters.scans == 4
    assert r["bus_errors"] >= 1 and r["bus_reopens"] >= 1  # the down interface was noticed and reopened


def test_error_frames_and_bus_off_are_counted(vcan):
    prof = load_profile(HAND)
    source = start_source(prof, vcan)
    with can.Bus(interface="socketcan", channel=vcan) as tx:
        tx.send(can.Message(arbitration_id=0x040, is_error_frame=True, data=bytes(8), is_extended_id=False))
        tx.send(can.Message(arbitration_id=0x004, is_error_frame=True, data=bytes(8), is_extended_id=False))
    source.run(idle_timeout_s=1.0, duration_s=10)
    c = source.counters()
    assert c["error_frames"] == 2 and c["bus_off"] == 1


def test_live_receiver_and_its_log_replay_agree(vcan, tmp_path):
    """The whole path as a user runs it: eskin-bus receive (recording the traffic) and
    eskin-bus node with faults on vcan0, then eskin-bus detect --can-log."""
    f = forces(400, 25, seed=5)
    rec, log, live, replay = (tmp_path / n for n in ("rec.csv", "traffic.log", "live.csv", "replay.csv"))
    write_recording(rec, np.arange(400) / 100.0, f)
    with subprocess.Popen([sys.executable, "-m", "eskin_industrial", "receive", "-p", PAPER, "-i", "socketcan",
                           "-c", vcan, "--log", str(log), "-o", str(live), "--duration", "300"],
                          stderr=subprocess.PIPE, text=True) as rx:
        try:
            assert "receiving paper-5x5" in rx.stderr.readline()  # the bus is open
            res = eskin("node", "-p", PAPER, "-i", "socketcan", "-c", vcan, "--recording", str(rec), "--burst",
                        "--drop", "0.01", "--duplicate", "0.01", "--seed", "3")
            assert res.returncode == 0, res.stderr
            # Ctrl-C once the frames are in (--idle-exit counts from the receiver's start,
            # and the node's start here takes longer than a short bound)
            time.sleep(2.0)
            rx.send_signal(signal.SIGINT)
            counters = json.loads(rx.stderr.read().strip().splitlines()[-1])
            assert rx.wait(timeout=60) == 0
        finally:
            rx.kill()
    assert counters["duplicate_frames"] > 0 and counters["lost_scans"] + counters["torn_scans"] > 0
    assert counters["scans"] + counters["lost_scans"] >= 390
    res = eskin("detect", "-p", PAPER, "--can-log", str(log), "-o", str(replay))
    assert res.returncode == 0, res.stderr
    assert replay.read_text() == live.read_text() and live.read_text().count("\n") > 30
