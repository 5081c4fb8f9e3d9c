"""`eskin-bus demo`: node on the virtual CAN bus -> bridge -> Modbus TCP -> PLC stand-in."""
from __future__ import annotations

import re
import subprocess
import sys

import pytest

from tests.helpers.scenes import press_scene

SCENE = press_scene("short-slide", 5.0, press_t=0.5, press_s=0.4, force_n=8.0, slide_t=3.0)


@pytest.mark.slow
def test_demo_runs_the_whole_chain_and_the_plc_sees_the_slip(tmp_path):
    scene = tmp_path / "short.toml"
    scene.write_text(SCENE)
    res = subprocess.run([sys.executable, "-m", "eskin_industrial", "demo", "--scene", str(scene), "--plc-log", "--seed", "1001"],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    out = res.stdout
    assert re.search(r"^\s+3\.\d\d s  slip ", out, re.M), out  # detected during the slide
    assert "slip events 1, found 1, false alarms 0" in out
    assert "PLC" in out and "SLIP" in out  # the stand-in read the slip bit over Modbus TCP
    assert "grip force raised 1 times" in out or "grip force raised 2 times" in out
    assert re.search(r"scans 500, lost 0, torn 0, malformed 0, rx queue drops 0", out)
    p99 = float(re.search(r"p99 ([0-9.]+) ms", out).group(1))
    assert p99 < 50.0  # loopback write, generous for a loaded machine (the benchmark holds the 5 ms figure)


QUICK = press_scene("quick-press", 2.0, press_t=0.3, press_s=0.3, force_n=6.0)


def run_in_terminal(args: list[str], cols: int = 80, rows: int = 24, timeout_s: float = 60.0):
    """Run ``eskin-bus ARGS`` with its stdout on a pseudo-terminal of the given size;
    returns (exit code, everything written to the terminal, stderr, seconds)."""
    import fcntl
    import os
    import select
    import struct
    import termios
    import time

    master, slave = os.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", rows, cols, 0, 0))
    env = {k: v for k, v in os.environ.items() if k not in ("COLUMNS", "LINES", "NO_COLOR")}
    env["TERM"] = "xterm-256color"
    start = time.monotonic()
    proc = subprocess.Popen([sys.executable, "-m", "eskin_industrial", *args], stdin=slave, stdout=slave,
                            stderr=subprocess.PIPE, env=env)
    os.close(slave)
    out = b""
    try:
        while time.monotonic() - start < timeout_s:
            ready, _, _ = select.select([master], [], [], 0.5)
            if not ready:
                if proc.poll() is not None:
                    break
                continue
            try:
                chunk = os.read(master, 65536)
            except OSError:  # the child closed the terminal
                break
            if not chunk:
                break
            out += chunk
    finally:
        os.close(master)
        if proc.poll() is None:
            proc.kill()
    code = proc.wait(timeout=10)
    with proc.stderr:
        err = proc.stderr.read().decode()
    return code, out.decode(errors="replace").replace("\r\n", "\n"), err, time.monotonic() - start


@pytest.mark.slow
def test_demo_in_a_terminal_shows_the_live_view_then_the_summary(tmp_path):
    scene = tmp_path / "quick.toml"
    scene.write_text(QUICK)
    code, out, err, seconds = run_in_terminal(["demo", "--scene", str(scene), "--seed", "3"])
    assert code == 0, err
    enter, leave = out.find("\x1b[?1049h"), out.find("\x1b[?1049l")
    assert 0 <= enter < leave and out.count("\x1b[?1049h") == 1 and out.count("\x1b[?1049l") == 1
    assert out.rfind("\x1b[?25h") > out.rfind("\x1b[?25l")  # the cursor is back
    live, after = out[enter:leave], out[leave:]
    frames = live.count("\x1b[H")
    assert 5 <= frames <= seconds * 20 + 5  # redrawn at a capped rate, not once per scan (200 scans)
    plain = re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", live)
    for part in ("eskin-bus demo", "taxels, N", "R_coe", "PLC registers, as the PLC reads them", "counters"):
        assert part in plain, part
    assert "\x1b[48;5;" in live  # the heat map in colour
    assert out.index("demo: scene quick-press") < enter  # the first line stays on the shell's screen
    assert re.search(r"^\s+0\.\d\d s  (no_contact|stable) ", after, re.M)  # the state changes, after the view
    assert "summary:" in after and "scans 200, lost 0, torn 0, malformed 0, rx queue drops 0" in after
    assert "\x1b[" not in after.replace("\x1b[?1049l", "", 1)  # plain lines once the view has gone


@pytest.mark.slow
def test_demo_plain_in_a_terminal_has_no_live_view(tmp_path):
    scene = tmp_path / "quick.toml"
    scene.write_text(QUICK)
    code, out, err, _ = run_in_terminal(["demo", "--scene", str(scene), "--plain"])
    assert code == 0, err
    assert "\x1b[" not in out and "summary:" in out
