"""`eskin-bus modbus-bridge` reports what the bridge's log reports: the PLC writer's
outages (client mode) and the Modbus server's refusals (server mode), a line each on
stderr, and takes the writer's timeout from --plc-timeout."""

from __future__ import annotations

import socket
import struct
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.helpers.bridge import PAPER
from tests.helpers.modbus import free_port
from tests.helpers.plc_standin import PlcStandIn

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def hold_csv(tmp_path_factory: pytest.TempPathFactory) -> str:
    path = tmp_path_factory.mktemp("rec") / "hold.csv"
    subprocess.run([sys.executable, "-m", "eskin_industrial", "simulate", "hold", "-o", str(path)], check=True,
                   capture_output=True, timeout=60)
    return str(path)


def test_an_outage_of_a_silent_plc_is_two_lines_with_the_timeout_given(hold_csv: str) -> None:
    with PlcStandIn("silent") as plc:
        proc = subprocess.Popen([sys.executable, "-m", "eskin_industrial", "modbus-bridge", "-p", PAPER,
                                 "--recording", hold_csv, "--plc-host", "127.0.0.1", "--plc-port", str(plc.port),
                                 "--plc-timeout", "0.05", "--duration", "6"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        # the outage counts from the first request the bridge sends, however long the
        # process takes to start on a loaded machine
        deadline = time.monotonic() + 30
        while not plc.seen.requests:
            assert time.monotonic() < deadline and proc.poll() is None, "no request from the bridge"
            time.sleep(0.01)
        time.sleep(1.5)
        plc.mode = "ok"  # it answers again: the outage ends
        _, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    down = [line for line in err.splitlines() if " plc_unreachable " in line]
    up = [line for line in err.splitlines() if " plc_connected " in line and "outage_s=" in line]
    assert len(down) == 1 and "cause=timeout" in down[0], err
    assert up and float(up[-1].split("outage_s=")[1].split()[0]) > 0.5, err


def test_a_refused_write_of_the_server_is_a_line(hold_csv: str, tmp_path: Path) -> None:
    profile = tmp_path / "ro.toml"
    profile.write_text(Path(PAPER).read_text().replace("[modbus.plc]", "[modbus.plc]\nread_only = true", 1))
    port = free_port()
    proc = subprocess.Popen([sys.executable, "-m", "eskin_industrial", "modbus-bridge", "-p", str(profile),
                             "--recording", hold_csv, "--serve", f"127.0.0.1:{port}", "--duration", "3"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 10
        while True:
            try:
                sock = socket.create_connection(("127.0.0.1", port), timeout=1)
                break
            except OSError:
                assert time.monotonic() < deadline, "the server did not come up"
                time.sleep(0.1)
        with sock:  # FC6 to register 0 by hand: a read-only server refuses it (exception 01)
            sock.sendall(struct.pack(">HHHBBHH", 1, 0, 6, 1, 6, 0, 1))
            answer = sock.recv(64)
        assert answer[7] == 0x86 and answer[8] == 1
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate(timeout=5)
    # the bridge's log lines (modbus-bridge runs the bridge): TIME LEVEL EVENT key=value ...
    refusals = [line for line in err.splitlines() if " modbus_write_denied " in line and "reason=read_only" in line]
    assert refusals, err
