"""SIGTERM ends a long command as Ctrl-C does (``kill``, ``timeout``, ``systemctl
stop``): what it wrote is flushed and its counters printed, exit 0; Ctrl-C is a stop
as asked, not click's "Aborted!"."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from eskin_industrial.cli.console import HeldInterrupt, signals_ask
from tests.helpers.modbus import free_port
from tests.helpers.paths import PROFILES

pytestmark = pytest.mark.slow

PAPER = str(PROFILES / "paper-5x5.toml")
EXE = [sys.executable, "-m", "eskin_industrial"]


def stopped(proc: subprocess.Popen, sig: signal.Signals) -> tuple[str, str]:
    try:
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate(timeout=5)
    return out or "", err or ""


def test_receive_under_sigterm_writes_every_update_and_prints_the_counters(tmp_path: Path) -> None:
    log, out = tmp_path / "node.asc", tmp_path / "u.csv"
    subprocess.run([*EXE, "node", "-p", PAPER, "--scene", "case2", "--can-log", str(log)], check=True,
                   capture_output=True, timeout=60)
    proc = subprocess.Popen([*EXE, "receive", "-p", PAPER, "--can-log", str(log), "-o", str(out)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    assert proc.stderr is not None
    start = proc.stderr.readline()  # the log plays at its own pace: 14 s, stopped long before
    assert start.startswith("eskin-bus: receiving "), start
    time.sleep(1.5)  # some of it received
    _, err = stopped(proc, signal.SIGTERM)
    assert proc.returncode == 0, err
    counters = json.loads(err.strip().splitlines()[-1])
    rows = out.read_text().splitlines()[1:]
    assert 0 < counters["updates"] < 1400 and len(rows) == counters["updates"], err


def test_plc_sim_under_sigterm_prints_its_summary() -> None:
    proc = subprocess.Popen([*EXE, "plc-sim", "-p", PAPER, "--port", str(free_port()), "--duration", "60"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    assert proc.stderr is not None
    start = proc.stderr.readline()
    assert start.startswith("plc-sim: listening on "), start
    _, err = stopped(proc, signal.SIGTERM)
    assert proc.returncode == 0, err
    assert err.splitlines()[-1].startswith("plc-sim: 0 writes received, 0 slip reactions"), err


def test_node_on_ctrl_c_is_a_stop_with_its_summary() -> None:
    # Ctrl-C as a terminal's foreground job gets it: a runner that started the suite in the
    # background (SIGINT ignored, inherited across exec) must not make the node deaf to it
    proc = subprocess.Popen([*EXE, "node", "-p", PAPER, "--scene", "case2", "--can-log", "-", "--duration", "60"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    assert proc.stdout is not None
    first = proc.stdout.readline()  # candump -L lines, paced: the node runs
    assert first.startswith("("), first
    _, err = stopped(proc, signal.SIGINT)
    assert proc.returncode == 0, err
    assert "Aborted!" not in err and "Traceback" not in err, err
    assert err.splitlines()[-1].startswith("node: "), err


def test_a_live_detect_under_sigterm_ends_as_its_stream_would(tmp_path: Path) -> None:
    log, out = tmp_path / "node.log", tmp_path / "u.csv"
    subprocess.run([*EXE, "simulate", "case2", "--can-log", str(log), "-p", PAPER], check=True,
                   capture_output=True, timeout=60)
    lines = log.read_text().splitlines(keepends=True)[:900]  # about 100 scans; the stream stays open
    proc = subprocess.Popen([*EXE, "detect", "-p", PAPER, "--can-log", "-", "-o", str(out), "--json"],
                            stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    assert proc.stdin is not None
    proc.stdin.write("".join(lines))
    proc.stdin.flush()
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and (not out.exists() or len(out.read_text().splitlines()) < 50):
        time.sleep(0.05)
    _, err = stopped(proc, signal.SIGTERM)
    proc.stdin.close()
    assert proc.returncode == 0, err
    assert "Aborted!" not in err and "Traceback" not in err, err
    summary = json.loads(err.strip().splitlines()[-1])
    rows = out.read_text().splitlines()[1:]
    assert summary["updates"] == len(rows) >= 50, err


def test_a_finite_job_cut_short_says_so_in_one_line() -> None:
    proc = subprocess.Popen([*EXE, "evaluate", "--seeds", "0..39"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True)
    time.sleep(2.0)  # under way: the evaluation takes minutes
    _, err = stopped(proc, signal.SIGTERM)
    assert proc.returncode == 130, err
    assert err.strip().splitlines() == ["eskin-bus: interrupted"], err


def test_modbus_node_under_sigterm_prints_its_summary() -> None:
    master, slave = os.openpty()  # a serial line with nobody polling: the node serves, then is stopped
    try:
        proc = subprocess.Popen([*EXE, "modbus-node", "-p", PAPER, "--scene", "hold", "--port", os.ttyname(slave)],
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        assert proc.stderr is not None
        start = proc.stderr.readline()
        assert start.startswith("modbus-node: unit 1 on "), start
        time.sleep(1.0)  # (the line opened after the start line)
        _, err = stopped(proc, signal.SIGTERM)
    finally:
        os.close(master)
        os.close(slave)
    assert proc.returncode == 0, err
    assert err.splitlines()[-1] == "modbus-node: answered 0 reads", err


def test_a_stop_asked_by_signal_is_a_flag_and_a_second_signal_interrupts() -> None:
    """``receive``'s stop: the first Ctrl-C or SIGTERM only asks (no exception that could
    land between an update counted and the same update written), a second interrupts,
    and the handlers before are back after the block."""
    asked: list[int] = []
    before = signal.getsignal(signal.SIGTERM), signal.getsignal(signal.SIGINT)
    with signals_ask(lambda: asked.append(1)):
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(0.01)  # (the handler runs between two bytecodes of this thread)
        assert asked == [1]
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.5)
    assert asked == [1]
    assert (signal.getsignal(signal.SIGTERM), signal.getsignal(signal.SIGINT)) == before


def test_a_held_interrupt_waits_for_the_end_of_its_block_and_only_there() -> None:
    """``detect --can-log -``'s stop: outside a whole block (blocked on its input) a
    SIGTERM interrupts at once; inside one (an update counted and written) at its end."""
    held = HeldInterrupt()
    done: list[str] = []
    with held.installed():
        with pytest.raises(KeyboardInterrupt):
            with held.whole():
                os.kill(os.getpid(), signal.SIGTERM)
                time.sleep(0.05)
                done.append("written")  # (the block's own end is reached)
        assert done == ["written"]
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(0.5)
