"""`eskin-bus bridge` as a process, stopped by SIGTERM or SIGINT mid-run: the PLC is
left reading BRIDGE_OFFLINE (never a stale "stable"), the exit code is 0, and the log
(JSON here) says why it stopped."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time

import pytest

from eskin_industrial.errors import ModbusFault
from eskin_industrial.modbus.pymodbus_io import TcpMaster
from eskin_industrial.outputs.plc.image import IMAGE_COUNT, Status
from tests.helpers.bridge import PAPER, TimedPlc, wait_for
from tests.helpers.modbus import free_port


def start_bridge(*args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "eskin_industrial", "bridge", "-p", PAPER, "--source",
                             "scene:case2", "--log-format", "json", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=dict(os.environ, PYTHONUNBUFFERED="1"))


def finish(proc: subprocess.Popen) -> tuple[str, str]:
    """The process's output; killed if it did not stop by itself (a test failure)."""
    try:
        return proc.communicate(timeout=20)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate(timeout=10)
        raise AssertionError("the bridge did not stop within 20 s of the signal") from None


def json_events(stderr: str) -> list[dict]:
    events = []
    for line in stderr.splitlines():
        e = json.loads(line)  # every line: one JSON object
        assert {"ts", "level", "event"} <= e.keys(), line
        events.append(e)
    return events


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
@pytest.mark.slow
def test_a_signal_in_client_mode_leaves_the_plc_reading_offline(sig):
    port = free_port()
    plc = TimedPlc(port).start()
    proc = start_bridge("--plc", f"tcp:127.0.0.1:{port}", "--duration", "60")
    try:
        # case2 grips and holds: wait for the verdict the PLC must not keep
        wait_for(lambda: any(v["STATUS"] & Status.STABLE and v["STATUS"] & Status.DATA_VALID
                             for _, v in plc.images()), timeout_s=30, what="a valid stable image")
        proc.send_signal(sig)
        out, err = finish(proc)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate(timeout=10)
        plc.stop()
    assert proc.returncode == 0, err
    last = plc.last()
    assert last is not None and last["STATUS"] == Status.BRIDGE_OFFLINE, Status(last["STATUS"]) if last else None
    assert last["STATE"] == 0 and last["FRAME_AGE"] == 0xFFFF and last["F_SUM"] == 0
    events = json_events(err)
    stopped = [e for e in events if e["event"] == "stopped"]
    assert len(stopped) == 1 and stopped[0]["reason"] == sig.name and stopped[0]["offline_written"] == "node"
    final = [e for e in events if e["event"] == "final"]
    assert final and final[0]["scans"] > 100 and final[0]["plc_writes"] > 0
    assert events[0]["event"] == "start" and "Traceback" not in err and out == ""


def test_sigterm_in_server_mode_serves_offline_then_closes():
    port = free_port()
    proc = start_bridge("--plc", f"serve:127.0.0.1:{port}", "--duration", "60")
    reads: list[tuple[float, int]] = []
    ended = threading.Event()
    signalled: list[float] = []
    try:
        plc = TcpMaster("127.0.0.1", port, timeout_s=1.0)
        deadline = time.monotonic() + 30
        while True:  # the server comes up once the process has started
            try:
                plc.connect()
                break
            except ModbusFault:
                assert time.monotonic() < deadline and proc.poll() is None, "the bridge never listened"
                time.sleep(0.05)

        def poll() -> None:  # a PLC polling every 10 ms until the connection goes
            try:
                while True:
                    reads.append((time.monotonic(), plc.read_holding(0, IMAGE_COUNT)[0]))
                    time.sleep(0.01)
            except ModbusFault:
                ended.set()
            finally:
                plc.close()

        poller = threading.Thread(target=poll, daemon=True)
        poller.start()
        wait_for(lambda: reads and reads[-1][1] & Status.DATA_VALID, timeout_s=30, what="a valid image")
        signalled.append(time.monotonic())
        proc.send_signal(signal.SIGTERM)
        assert ended.wait(20), "the connection outlived the bridge"
        poller.join(5)
        out, err = finish(proc)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate(timeout=10)
    assert proc.returncode == 0, err
    after = [s for t, s in reads if t > signalled[0]]
    # the polling PLC read "offline" (and nothing else) before the connection went
    assert after and after[-1] == Status.BRIDGE_OFFLINE, [Status(s) for s in after]
    assert sum(1 for s in after if s == Status.BRIDGE_OFFLINE) >= 3  # the linger (0.5 s) at 10 ms polls
    again = TcpMaster("127.0.0.1", port, timeout_s=1.0)
    with pytest.raises(ModbusFault):
        again.connect()
    again.close()
    stopped = [e for e in json_events(err) if e["event"] == "stopped"]
    assert stopped and stopped[0]["reason"] == "SIGTERM"
