"""Every signal an operator or a terminal can send to `eskin-bus bridge` and
`eskin-bus modbus-bridge` in client mode: each stopping one leaves the PLC reading
BRIDGE_OFFLINE, with the exit status docs/operations.md gives; USR1 logs the counters
and the bridge goes on; PIPE and a reader of stderr that went away kill nothing.

The PLC is a stand-in on loopback; what it holds at the end is read back with
pymodbus's client and checked against the register map of docs/plc.md (STATUS bit
10 alone, STATE 0, FRAME_AGE 65535), not with this package's decoder."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest
from pymodbus.client import ModbusTcpClient

from eskin_industrial.node import NodeSnapshot
from eskin_industrial.outputs.base import Sink
from tests.helpers.bridge import PAPER, TimedPlc, can_node, channel, client_config, running_bridge, wait_for
from tests.helpers.modbus import free_port
from tests.helpers.paths import ROOT

#: docs/plc.md: STATUS (offset 0) bit 10 BRIDGE_OFFLINE; bit 1 STABLE, bit 5 DATA_VALID.
OFFLINE, STABLE, DATA_VALID = 1 << 10, 1 << 1, 1 << 5


def documented_signals() -> dict[signal.Signals, tuple[str, str]]:
    """docs/operations.md, "Signals": what the bridge does on each, and the exit."""
    text = (ROOT / "docs" / "operations.md").read_text()
    table = text[text.index("### Signals"):text.index("### Exit codes")]
    rows = {}
    for line in table.splitlines():
        cells = [c.strip() for c in line.strip("|").split("|")]
        if len(cells) == 4 and cells[0].isupper() and cells[0].isalnum():
            rows[signal.Signals[f"SIG{cells[0]}"]] = (cells[2], cells[3])
    return rows


DOCUMENTED = documented_signals()
#: The stopping signals and the exit status the docs give each.
STOPPING = {sig: int(code) for sig, (does, code) in DOCUMENTED.items() if does.startswith("stops cleanly")}


def test_the_signal_table_in_the_docs_is_the_code():
    from eskin_industrial.bridge import signals

    assert set(STOPPING) == set(signals.STOPPING) and len(STOPPING) >= 6
    assert {sig for sig, code in STOPPING.items() if code == signals.EXIT_FAILED} == set(signals.FAILING)
    assert {sig for sig, code in STOPPING.items() if code == 0} == set(signals.STOPPING) - set(signals.FAILING)
    assert DOCUMENTED[signals.COUNTERS][0].startswith("logs a `counters` event")
    assert DOCUMENTED[signal.SIGPIPE][0].startswith("ignored")
    assert DOCUMENTED[signal.SIGKILL][1] == str(128 + signal.SIGKILL)


def test_the_handlers_set_plain_flags_and_are_restored():
    """In this process: the first stopping signal is the reason, USR1s are counted,
    PIPE is ignored, and the handlers before the block are back after it."""
    from eskin_industrial.bridge.signals import handled_signals

    before = {sig: signal.getsignal(sig) for sig in (*STOPPING, signal.SIGUSR1, signal.SIGPIPE)}
    with handled_signals() as flags:
        assert not flags.stopping
        for sig in (signal.SIGUSR1, signal.SIGPIPE, signal.SIGHUP, signal.SIGTERM, signal.SIGUSR1):
            os.kill(os.getpid(), sig)
            time.sleep(0.01)  # the handler runs in this thread at its next bytecode
        assert flags.reason == "SIGHUP" and flags.counters == 2 and not flags.failing
    assert {sig: signal.getsignal(sig) for sig in before} == before


def _env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("NOTIFY_SOCKET", "WATCHDOG_USEC", "WATCHDOG_PID")}
    return {**env, "PYTHONUNBUFFERED": "1", "PYTHONPATH": os.getcwd()}


def bridge_cmd(port: int, *extra: str) -> list[str]:
    return [sys.executable, "-m", "eskin_industrial", "bridge", "-p", PAPER, "--source", "scene:hold",
            "--plc", f"tcp:127.0.0.1:{port}", "--log-format", "json", "--status-every", "0", *extra]


def read_block(port: int) -> list[int]:
    """Registers 0..19 of the stand-in, through pymodbus."""
    client = ModbusTcpClient("127.0.0.1", port=port, timeout=2)
    try:
        assert client.connect()
        reply = client.read_holding_registers(0, count=20)
        assert not reply.isError(), reply
        return list(reply.registers)
    finally:
        client.close()


def assert_offline(regs: list[int]) -> None:
    assert regs[0] == OFFLINE, f"STATUS {regs[0]:#06x}"
    assert regs[1] == 0 and regs[9] == 0xFFFF and regs[4:6] == [0, 0], regs


def valid_stable(plc: TimedPlc) -> bool:
    last = plc.last()
    return last is not None and last["STATUS"] & (STABLE | DATA_VALID) == STABLE | DATA_VALID


def events(stderr: str) -> list[dict]:
    return [json.loads(line) for line in stderr.splitlines() if line.startswith("{")]


def finish(proc: subprocess.Popen, timeout_s: float = 15) -> str:
    try:
        _, err = proc.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate(timeout=5)
        raise AssertionError(f"still running {timeout_s} s after the signal") from None
    return err or ""


@pytest.fixture
def plc():
    stand_in = TimedPlc(free_port()).start()
    yield stand_in
    stand_in.stop()


@pytest.mark.slow
@pytest.mark.parametrize("sig", list(STOPPING), ids=lambda s: s.name)
def test_every_stopping_signal_leaves_the_plc_reading_offline(plc, sig):
    proc = subprocess.Popen(bridge_cmd(plc.port), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            env=_env())
    try:
        wait_for(lambda: valid_stable(plc), timeout_s=15, what="a valid stable image")
        assert_valid = read_block(plc.port)[0]
        assert assert_valid & (STABLE | DATA_VALID) == STABLE | DATA_VALID  # what the PLC must not keep
        proc.send_signal(sig)
        err = finish(proc)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate(timeout=5)
    assert proc.returncode == STOPPING[sig], err[-2000:]
    assert_offline(read_block(plc.port))
    log = events(err)
    (stopped,) = [e for e in log if e["event"] == "stopped"]
    assert stopped["reason"] == sig.name and stopped["offline_written"] == "node"
    assert "Traceback" not in err


@pytest.mark.slow
def test_usr1_logs_the_counters_and_the_bridge_goes_on(plc):
    proc = subprocess.Popen(bridge_cmd(plc.port), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            env=_env())
    try:
        wait_for(lambda: valid_stable(plc), timeout_s=15, what="a valid stable image")
        for _ in range(2):
            proc.send_signal(signal.SIGUSR1)
            time.sleep(0.5)
        writes = len(plc.images())
        wait_for(lambda: len(plc.images()) > writes + 5, timeout_s=5, what="writes after USR1")
        assert proc.poll() is None
        # still deciding, not stopped (a loaded host may show one stale image in between)
        wait_for(lambda: valid_stable(plc), timeout_s=5, what="a valid stable image after USR1")
        proc.send_signal(signal.SIGTERM)
        err = finish(proc)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate(timeout=5)
    assert proc.returncode == 0
    log = events(err)
    counters = [e for e in log if e["event"] == "counters"]
    assert len(counters) == 2  # --status-every 0: only the two asked for
    assert counters[0]["scans"] > 0 and counters[1]["scans"] > counters[0]["scans"]
    assert counters[0]["node"] == "node" and "plc_writes" in counters[0]
    assert_offline(read_block(plc.port))


@pytest.mark.slow
def test_pipe_and_a_vanished_stderr_reader_kill_nothing(plc):
    """A closed SSH session: the reader of stderr is gone (EPIPE on every log line),
    SIGPIPE comes, then SIGHUP: the bridge stops cleanly all the same."""
    proc = subprocess.Popen(bridge_cmd(plc.port), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=_env())
    try:
        wait_for(lambda: valid_stable(plc), timeout_s=15, what="a valid stable image")
        assert proc.stderr is not None
        proc.stderr.close()  # every line the bridge logs from now on fails
        proc.send_signal(signal.SIGPIPE)
        proc.send_signal(signal.SIGUSR1)  # a log line into the dead pipe
        writes = len(plc.images())
        wait_for(lambda: len(plc.images()) > writes + 5, timeout_s=5, what="writes after SIGPIPE")
        # still detecting (a loaded machine may show one stale image in between: wait for a valid one)
        wait_for(lambda: valid_stable(plc), timeout_s=5, what="a valid stable image after SIGPIPE")
        assert proc.poll() is None
        proc.send_signal(signal.SIGHUP)
        proc.wait(15)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(5)
    assert proc.returncode == 0
    assert_offline(read_block(plc.port))


# -- modbus-bridge ------------------------------------------------------------------------
def modbus_bridge_cmd(recording: str, port: int, *extra: str) -> list[str]:
    return [sys.executable, "-m", "eskin_industrial", "modbus-bridge", "-p", PAPER, "--recording", recording,
            "--plc-host", "127.0.0.1", "--plc-port", str(port), *extra]


@pytest.fixture(scope="module")
def hold_csv(tmp_path_factory):
    path = tmp_path_factory.mktemp("rec") / "hold.csv"
    subprocess.run([sys.executable, "-m", "eskin_industrial", "simulate", "hold", "-o", str(path)], check=True,
                   env=_env(), capture_output=True, timeout=60)
    return str(path)


@pytest.mark.slow
@pytest.mark.parametrize("how", ["duration", "SIGHUP", "SIGTERM", "SIGQUIT", "SIGABRT"])
def test_modbus_bridge_leaves_the_plc_reading_offline(plc, hold_csv, how):
    extra = ("--duration", "4") if how == "duration" else ("--duration", "60")
    proc = subprocess.Popen(modbus_bridge_cmd(hold_csv, plc.port, *extra), stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True, env=_env())
    try:
        wait_for(lambda: valid_stable(plc), timeout_s=15, what="a valid stable image")
        if how != "duration":
            proc.send_signal(signal.SIGUSR1)  # the counters, and it goes on
            time.sleep(0.3)
            assert proc.poll() is None
            proc.send_signal(getattr(signal, how))
        err = finish(proc)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate(timeout=5)
    assert proc.returncode == (0 if how == "duration" else STOPPING[getattr(signal, how)]), err
    assert_offline(read_block(plc.port))
    # the bridge's log lines (modbus-bridge runs the bridge), as plain key=value
    assert f"stopped reason={'end' if how == 'duration' else how} offline_written=node" in err
    assert len([line for line in err.splitlines() if " final node=node scans=" in line]) == 1
    usr1 = [line for line in err.splitlines() if " counters node=node scans=" in line]
    assert len(usr1) == (0 if how == "duration" else 1)


# -- an output that fails on the way out ------------------------------------------------
class _BrokenOutput(Sink):
    """An output whose last image and flush raise (a disk gone, a library's bug)."""

    def _publish(self, snapshot: NodeSnapshot) -> None:
        if snapshot.offline:
            raise OSError("the output is gone")

    def flush(self, timeout_s: float = 1.0) -> bool:
        raise OSError("the output is gone")


def test_an_output_failing_at_the_stop_does_not_keep_the_plc_online(plc):
    """The broken output comes first: the PLC behind it still gets BRIDGE_OFFLINE,
    the failure is logged, and the stop completes."""
    config = client_config(can_node("grip", channel()), port=plc.port)

    def broken_first(bridge) -> None:
        bridge.runs[0].loop.sinks.insert(0, _BrokenOutput())

    with running_bridge(config, before_start=broken_first) as run:
        wait_for(lambda: plc.last() is not None, timeout_s=5, what="a first write")
    assert plc.last()["STATUS"] == OFFLINE  # type: ignore[index]
    failures = run.log.events("stop_failed")
    assert len(failures) == 2 and all("the output is gone" in e["error"] for e in failures)
    (stopped,) = run.log.events("stopped")
    assert stopped["offline_written"] == "-"  # the broken output did not take it: not every output is offline
