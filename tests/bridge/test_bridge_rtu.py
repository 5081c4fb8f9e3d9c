"""`eskin-bus bridge --source rtu:PORT` as a user runs it: the node simulator on one end
of a socat pseudo-terminal pair, the bridge polling the other, mbpoll reading the
registers the bridge serves, then SIGTERM."""
from __future__ import annotations

import json
import signal
import subprocess
import sys
import time

import pytest

from eskin_industrial.outputs.plc.image import REG, Status, join32
from eskin_industrial.recording import write_recording
from tests.helpers.modbus import free_port, mbpoll, mbpoll_values, pty_pair, slip_recording
from tests.helpers.paths import PROFILES

PAPER = str(PROFILES / "paper-5x5.toml")


def registers(port: int) -> list[int]:
    out = mbpoll("-m", "tcp", "-a", "1", "-r", "1", "-c", str(REG["FLAGS"].offset), "-1", "-p", str(port), "127.0.0.1")
    assert out.returncode == 0, out.stdout + out.stderr
    values = mbpoll_values(out.stdout)
    return [values[i + 1] for i in range(REG["FLAGS"].offset)]


@pytest.mark.slow
def test_bridge_polls_an_rtu_node_and_serves_what_mbpoll_reads(tmp_path):
    t, f, _onset = slip_recording(still_s=2.0, slip_s=0.3, after_s=1.5)
    rec = tmp_path / "slip.csv"
    write_recording(rec, t, f)
    port = free_port()
    events = tmp_path / "events.jsonl"
    with pty_pair(tmp_path) as (a, b):
        node = subprocess.Popen([sys.executable, "-m", "eskin_industrial", "modbus-node", "-p", PAPER, "--port", str(a),
                                 "--recording", str(rec), "--once"], stderr=subprocess.DEVNULL)
        with events.open("w") as err:
            bridge = subprocess.Popen([sys.executable, "-m", "eskin_industrial", "bridge", "-p", PAPER,
                                       "--source", f"rtu:{b}", "--plc", f"serve:127.0.0.1:{port}",
                                       "--log-format", "json", "--status-every", "0.5"], stderr=err)
        try:
            # The node plays once and keeps its last scan: wait until the slide has been
            # polled through (SLIP_EVENTS counts it), then read what a PLC would.
            deadline = time.monotonic() + t[-1] + 20
            regs, at = None, REG["SLIP_EVENTS"].offset
            while time.monotonic() < deadline:
                time.sleep(0.5)
                assert bridge.poll() is None, events.read_text()[-2000:]
                try:
                    regs = registers(port)
                except AssertionError:
                    continue  # the server is not up yet
                if join32(regs[at: at + 2], "big") >= 1:
                    break
            assert regs is not None and join32(regs[at: at + 2], "big") >= 1, regs
            hb = regs[REG["HEARTBEAT"].offset]
            time.sleep(0.3)
            later = registers(port)
            assert later[REG["HEARTBEAT"].offset] != hb  # published on refresh, node or not
            status = Status(later[REG["STATUS"].offset])
            assert not status & Status.BUS_FAULT  # the node answers (its last scan, again and again)
            bridge.send_signal(signal.SIGTERM)
            assert bridge.wait(timeout=20) == 0
        finally:
            for proc in (bridge, node):
                if proc.poll() is None:
                    proc.kill()
                    proc.wait(timeout=10)
    log = [json.loads(line) for line in events.read_text().splitlines() if line.startswith("{")]
    assert any(e["event"] == "state" and e["state"] == "slip" for e in log)
    final = next(e for e in log if e["event"] == "final")
    assert final["rtu_polls"] > 100 and final["rtu_crc_errors"] == 0
    assert next(e for e in log if e["event"] == "stopped")["reason"] == "SIGTERM"
