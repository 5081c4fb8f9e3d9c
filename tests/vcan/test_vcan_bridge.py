"""`eskin-bus bridge` on a real SocketCAN stack, between peers nobody here wrote:
can-utils' canplayer plays the node, mbpoll reads the PLC registers the bridge serves."""
from __future__ import annotations

import json
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from eskin_industrial import Calibrator, load_profile
from eskin_industrial.bus.can.layout import CanLayout
from eskin_industrial.outputs.plc.image import REG, Status, join32
from eskin_industrial.scenes import render

PAPER = str(Path(__file__).resolve().parents[2] / "profiles" / "paper-5x5.toml")

#: Press, hold 3 s (the detector learns the noise), slide 6 mm at 10 mm/s.
SCENE = """
[scene]
name = "short-slip"
profile = "paper-5x5"
duration_s = 6.0

[footprint]
size_mm = [20.0, 20.0]
centre_mm = [10.0, 10.0]
gradient_per_mm = [0.01, 0.0]

[[events]]
kind = "press"
t_s = 0.3
duration_s = 0.5
force_n = 8.0

[[events]]
kind = "slide"
t_s = 4.0
distance_mm = [6.0, 0.0]
speed_mm_s = 10.0
"""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def mbpoll_registers(port: int, count: int) -> list[int]:
    """Holding registers 0..count-1 of the bridge, read by mbpoll (one poll)."""
    out = subprocess.run([shutil.which("mbpoll") or "mbpoll", "-m", "tcp", "-a", "1", "-r", "1", "-c", str(count),
                          "-1", "-p", str(port), "127.0.0.1"], capture_output=True, text=True, timeout=30)
    assert out.returncode == 0, out.stdout + out.stderr
    values = {}
    for line in out.stdout.splitlines():
        line = line.strip()
        if line.startswith("[") and "]:" in line:
            ref, _, value = line[1:].partition("]:")
            values[int(ref)] = int(value.split()[0])
    return [values[i + 1] for i in range(count)]


def read_events(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines() if line.startswith("{") and line.endswith("}")]


def scene_log(tmp_path: Path) -> Path:
    """The scene as a candump log, plus one short frame of the node and one frame of
    no node: the bridge must count both and carry on."""
    prof = load_profile(PAPER)
    (tmp_path / "short.toml").write_text(SCENE)
    rec = render(str(tmp_path / "short.toml"), 100.0, 1)
    layout = CanLayout.from_profile(prof, fd=False)
    raw = np.rint(Calibrator.from_section(prof.calibration, prof.taxels).to_raw(rec.forces))
    lines, t0 = [], 1000.0
    for k, scan in enumerate(layout.encode(np.arange(len(raw)), raw)):
        t = t0 + k / 100.0
        for s, (can_id, data) in enumerate(scan):
            lines.append(f"({t + s * 1e-4:.6f}) can0 {can_id:03X}#{data.hex().upper()}")
        if k == 100:
            lines.append(f"({t + 0.002:.6f}) can0 {layout.data_id(0):03X}#0102")  # too short
            lines.append(f"({t + 0.003:.6f}) can0 7F0#DEADBEEF")  # no node's ID
    log = tmp_path / "scene.log"
    log.write_text("\n".join(lines) + "\n")
    return log


def test_bridge_between_canplayer_and_mbpoll(vcan, tmp_path):
    if shutil.which("canplayer") is None or shutil.which("mbpoll") is None:
        pytest.fail("canplayer (can-utils) and mbpoll are needed (scripts/setup installs them)")
    log = scene_log(tmp_path)
    port = free_port()
    events_file = tmp_path / "events.jsonl"
    with events_file.open("w") as err:
        proc = subprocess.Popen([sys.executable, "-m", "eskin_industrial", "bridge", "-p", PAPER, "--source", "can",
                                 "-i", "socketcan", "-c", vcan, "--plc", f"serve:127.0.0.1:{port}",
                                 "--log-format", "json", "--status-every", "1"], stderr=err, stdout=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 60
        while '"event": "start"' not in events_file.read_text():
            assert proc.poll() is None, events_file.read_text()
            assert time.monotonic() < deadline, "the bridge did not start"
            time.sleep(0.2)
        subprocess.run(["canplayer", "-I", str(log), f"{vcan}=can0"], check=True, timeout=90)
        # The emulated machine is slower than the bus: the bridge catches up from its
        # queue (its counters, logged every second, say when).
        deadline = time.monotonic() + 90
        while not any(e["event"] == "counters" and e["scans"] == 600 for e in read_events(events_file)):
            assert time.monotonic() < deadline, events_file.read_text()[-3000:]
            time.sleep(0.2)
        time.sleep(0.5)  # the node is silent: stale after 2.5 scan periods
        first = mbpoll_registers(port, REG["FLAGS"].offset)
        second = mbpoll_registers(port, REG["FLAGS"].offset)
        at = REG["SLIP_EVENTS"].offset
        assert join32(first[at: at + 2], "big") >= 1, (first, events_file.read_text()[-3000:])  # the slide was a slip
        status = Status(second[REG["STATUS"].offset])
        # The node is silent now: stale, no verdict; the bridge's heartbeat goes on.
        assert status & Status.SENSOR_STALE and not status & (Status.DATA_VALID | Status.STABLE | Status.SLIP)
        assert second[REG["HEARTBEAT"].offset] != first[REG["HEARTBEAT"].offset]
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=30) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)
    events = read_events(events_file)
    names = [e["event"] for e in events]
    assert "sensor_stale" in names and any(e["event"] == "state" and e["state"] == "slip" for e in events)
    stopped = next(e for e in events if e["event"] == "stopped")
    assert stopped["reason"] == "SIGTERM" and stopped["offline_written"] == "node"
    final = next(e for e in events if e["event"] == "final")
    assert final["scans"] == 600 and final["lost_scans"] == 0
    assert final["malformed_frames"] == 1 and final["unrouted_frames"] == 1
