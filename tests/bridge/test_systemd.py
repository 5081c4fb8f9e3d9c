"""The bridge under systemd: the notification protocol on a real AF_UNIX datagram
socket that the test binds and names in ``$NOTIFY_SOCKET`` (READY, STATUS, WATCHDOG,
STOPPING), a watchdog that starves while a loop hangs, and the shipped service unit
checked by ``systemd-analyze verify`` and ``systemd-analyze security``."""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import time
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest

from eskin_industrial.bridge.notify import Notifier
from tests.helpers.bridge import can_node, channel, running_bridge, server_config, wait_for
from tests.helpers.modbus import free_port, need
from tests.helpers.paths import ROOT

UNIT = ROOT / "examples" / "deploy" / "eskin-bus-bridge.service"


class Listener:
    """systemd's side: a datagram socket, every message as a set of KEY=VALUE lines."""

    def __init__(self, address: str) -> None:
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.sock.bind("\0" + address[1:] if address.startswith("@") else address)
        self.address = address
        self.messages: list[tuple[float, list[str]]] = []

    def collect(self, timeout_s: float) -> None:
        """Receive for ``timeout_s``."""
        end = time.monotonic() + timeout_s
        while (left := end - time.monotonic()) > 0:
            self.sock.settimeout(left)
            try:
                data = self.sock.recv(4096)
            except TimeoutError:
                return
            self.messages.append((time.monotonic(), data.decode().split("\n")))

    def until(self, field: str, timeout_s: float) -> float:
        """Receive until a message carries ``field``; its arrival time."""
        end = time.monotonic() + timeout_s
        while True:
            for t, fields in self.messages:
                if field in fields:
                    return t
            assert time.monotonic() < end, f"no {field} within {timeout_s} s: {self.messages}"
            self.collect(min(0.05, max(end - time.monotonic(), 0.001)))

    def times(self, field: str, after: float = 0.0) -> list[float]:
        return [t for t, fields in self.messages if field in fields and t > after]

    def close(self) -> None:
        self.sock.close()


@contextlib.contextmanager
def listener(tmp_path: Path, abstract: bool = False) -> Iterator[Listener]:
    address = f"@eskin-test-{uuid.uuid4().hex[:12]}" if abstract else str(tmp_path / "notify.sock")
    lst = Listener(address)
    try:
        yield lst
    finally:
        lst.close()


# -- the protocol -------------------------------------------------------------------------
@pytest.mark.parametrize("abstract", [False, True], ids=["path", "abstract"])
def test_notifier_sends_datagrams_systemd_reads(tmp_path, abstract):
    with listener(tmp_path, abstract) as lst:
        n = Notifier.from_env({"NOTIFY_SOCKET": lst.address, "WATCHDOG_USEC": "3000000"})
        assert n.watchdog_interval_s == 1.5
        assert n.ready("running: 1 node(s)") and n.watchdog() and n.stopping("stopping: SIGTERM")
        lst.collect(0.2)
        n.close()
    assert [m for _, m in lst.messages] == [["READY=1", "STATUS=running: 1 node(s)"], ["WATCHDOG=1"],
                                            ["STOPPING=1", "STATUS=stopping: SIGTERM"]]


def test_notifier_outside_systemd_does_nothing_and_a_dead_socket_is_counted(tmp_path):
    assert not Notifier.from_env({}).ready() and Notifier.from_env({}).watchdog_interval_s is None
    # another process's watchdog (WATCHDOG_PID): not ours to feed
    assert Notifier.from_env({"NOTIFY_SOCKET": "/x", "WATCHDOG_USEC": "1000000", "WATCHDOG_PID": "1"},
                             pid=2).watchdog_interval_s is None
    gone = Notifier(str(tmp_path / "nobody-listens"))
    assert not gone.watchdog() and gone.failures == 1
    gone.close()


# -- the bridge as systemd runs it --------------------------------------------------------
@pytest.mark.slow
def test_the_bridge_says_ready_feeds_the_watchdog_and_says_stopping(tmp_path):
    with listener(tmp_path) as lst:
        env = {**os.environ, "NOTIFY_SOCKET": lst.address, "WATCHDOG_USEC": "1000000", "PYTHONPATH": os.getcwd()}
        env.pop("WATCHDOG_PID", None)
        proc = subprocess.Popen([sys.executable, "-m", "eskin_industrial", "bridge", "-p",
                                 str(ROOT / "profiles" / "paper-5x5.toml"), "--source", "scene:hold",
                                 "--plc", f"serve:127.0.0.1:{free_port()}", "--log-format", "json"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env)
        try:
            ready = lst.until("READY=1", 20)
            lst.collect(2.6)
            proc.send_signal(signal.SIGTERM)
            stopping = lst.until("STOPPING=1", 10)
            _, err = proc.communicate(timeout=15)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.communicate(timeout=5)
    assert proc.returncode == 0, err
    (status,) = [f for t, fields in lst.messages if t == ready for f in fields if f.startswith("STATUS=")]
    assert status.startswith("STATUS=running: 1 node(s) -> tcp 127.0.0.1:")
    feeds = lst.times("WATCHDOG=1", after=ready)
    assert len(feeds) >= 4  # 2.6 s at one every 0.5 s
    gaps = [b - a for a, b in zip(feeds, feeds[1:])]
    assert max(gaps) < 1.0, gaps  # always within systemd's period
    assert stopping > feeds[-1] - 0.01
    assert "watchdog_starved" not in err


@pytest.mark.slow
def test_a_hung_loop_starves_the_watchdog(tmp_path):
    """The CAN bus's loop thread blocked (its lock held elsewhere): no more WATCHDOG=1,
    one error line naming the loop; fed again once it turns."""
    config = server_config(can_node("grip", channel()))
    with listener(tmp_path) as lst:
        def notify(bridge) -> None:
            bridge.notifier = Notifier(lst.address, 200_000)  # fed every 0.1 s

        with running_bridge(config, before_start=notify) as run:
            lst.until("READY=1", 5)
            lst.collect(0.5)
            assert len(lst.times("WATCHDOG=1")) >= 3
            feeder = run.bridge.groups[0][0]
            with feeder.lock:  # the loop waits for it, as for a deadlock
                hung = time.monotonic()
                lst.collect(0.3)  # the feed under way when it hung may still come
                starved_from = time.monotonic()
                lst.collect(0.8)
                assert lst.times("WATCHDOG=1", after=starved_from) == []
            wait_for(lambda: run.log.events("watchdog_fed"), timeout_s=3, what="fed again")
            lst.collect(0.4)
            assert lst.times("WATCHDOG=1", after=starved_from)
    (starved,) = run.log.events("watchdog_starved")
    assert starved["level"] == "error" and starved["loops"].startswith("feed-grip")
    assert lst.times("WATCHDOG=1", after=hung)[-1] > starved_from


# -- the service unit ---------------------------------------------------------------------
def _unit_for_this_machine(tmp_path: Path) -> Path:
    """The shipped unit with ExecStart pointing at this checkout's command, since
    ``verify`` checks that the binary exists."""
    exe = shutil.which("eskin-bus", path=str(Path(sys.executable).parent)) or shutil.which("eskin-bus")
    assert exe, "eskin-bus is not installed next to this interpreter"
    text = UNIT.read_text().replace("/opt/eskin-bus/.venv/bin/eskin-bus", exe)
    out = tmp_path / UNIT.name
    out.write_text(text)
    return out


def test_the_service_unit_passes_systemd_analyze_verify(tmp_path):
    analyze = need("systemd-analyze")
    unit = _unit_for_this_machine(tmp_path)
    res = subprocess.run([analyze, "verify", str(unit)], capture_output=True, text=True, timeout=60)
    # verify also reports the units it pulls in; only lines about ours count
    ours = [line for line in (res.stdout + res.stderr).splitlines() if UNIT.name in line]
    assert res.returncode == 0 and not ours, res.stdout + res.stderr


def test_the_service_unit_exposure_is_at_most_3(tmp_path):
    analyze = need("systemd-analyze")
    unit = _unit_for_this_machine(tmp_path)
    res = subprocess.run([analyze, "security", "--offline=yes", str(unit)], capture_output=True, text=True,
                         timeout=60)
    match = re.search(r"Overall exposure level for \S+: ([0-9.]+)", res.stdout)
    assert match, res.stdout + res.stderr
    assert float(match.group(1)) <= 3.0, res.stdout


def test_the_service_unit_does_not_restart_a_bad_configuration():
    """exit 2 (a bad configuration) is final; the check runs in the main process,
    since RestartPreventExitStatus= does not apply to an ExecStartPre= (systemd
    issue 11868); the bridge is ready when it says so, and the watchdog is on."""
    keys: dict[str, list[str]] = {}
    for line in UNIT.read_text().splitlines():
        if "=" in line and not line.startswith(("#", "[")):
            key, _, value = line.partition("=")
            keys.setdefault(key.strip(), []).append(value.strip())
    assert keys["Restart"] == ["on-failure"] and "2" in keys["RestartPreventExitStatus"][0].split()
    assert not any("--check" in v for v in keys.get("ExecStartPre", []))
    assert keys["Type"] == ["notify"] and keys["WatchdogSec"]


@pytest.mark.slow
def test_a_bad_configuration_exits_2_before_anything_opens(tmp_path):
    cfg = tmp_path / "bridge.toml"
    cfg.write_text('[[node]]\nname = "a"\nprofile = "missing.toml"\nsource = "can"\n')
    res = subprocess.run([sys.executable, "-m", "eskin_industrial", "bridge", "--config", str(cfg)],
                         capture_output=True, text=True, timeout=60, env={**os.environ, "PYTHONPATH": os.getcwd()})
    assert res.returncode == 2 and "missing.toml" in res.stderr and "Traceback" not in res.stderr


# -- MemoryDenyWriteExecute=yes ----------------------------------------------------------
SANDBOX = ROOT / "tests" / "helpers" / "sandbox.py"


def _under_mdwe(mode: str, *args: str) -> subprocess.CompletedProcess:
    res = subprocess.run([sys.executable, str(SANDBOX), mode, "-m", "eskin_industrial", *args], capture_output=True,
                         text=True, timeout=60, env={**os.environ, "PYTHONPATH": os.getcwd()})
    if res.returncode == 77:
        pytest.skip(f"this kernel cannot restrict memory by {mode}")
    return res


@pytest.mark.parametrize("mode", ["prctl", "seccomp"])
def test_the_restriction_refuses_writable_executable_memory(mode):
    probe = ("import ctypes, mmap\n"
             "try:\n    mmap.mmap(-1, 4096, prot=7)\nexcept OSError:\n    pass\nelse:\n    raise SystemExit(1)\n"
             "mmap.mmap(-1, 4096, prot=3)\n")  # writable alone is fine
    res = subprocess.run([sys.executable, str(SANDBOX), mode, "-c", probe], capture_output=True, text=True, timeout=30)
    if res.returncode == 77:
        pytest.skip(f"this kernel cannot restrict memory by {mode}")
    assert res.returncode == 0, res.stderr


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["prctl", "seccomp"])
def test_the_bridge_and_every_wavelet_method_run_with_memory_deny_write_execute(tmp_path, mode):
    profile = str(ROOT / "profiles" / "paper-5x5.toml")
    res = _under_mdwe(mode, "bridge", "-p", profile, "--source", "scene:hold", "--plc",
                      f"serve:127.0.0.1:{free_port()}", "--duration", "3", "--log-format", "json")
    assert res.returncode == 0, res.stderr[-2000:]
    assert '"valid": 1' in res.stderr  # it decided, not only started
    rec = tmp_path / "case2.csv"
    subprocess.run([sys.executable, "-m", "eskin_industrial", "simulate", "case2", "-o", str(rec)], check=True,
                   capture_output=True, timeout=60, env={**os.environ, "PYTHONPATH": os.getcwd()})
    for method in ("paper", "learned"):  # PyWavelets; the shipped model (numpy)
        res = _under_mdwe(mode, "detect", "-p", profile, "--method", method, "--changes", str(rec))
        assert res.returncode == 0 and "slip" in res.stdout, (method, res.stderr[-2000:])


# -- SystemCallFilter= ---------------------------------------------------------------------
def _unit_syscalls(analyze: str) -> list[int]:
    """The x86-64 numbers of the system calls the unit's SystemCallFilter= lines allow
    (systemd's always-permitted @default, plus the allowed groups, minus the ~ ones),
    as ``systemd-analyze syscall-filter`` expands the groups."""
    def expand(name: str) -> set[str]:
        if not name.startswith("@"):
            return {name}
        out = subprocess.run([analyze, "syscall-filter", name], capture_output=True, text=True, timeout=30, check=True)
        names: set[str] = set()
        for line in out.stdout.splitlines()[1:]:
            item = line.strip()
            if item and not item.startswith("#"):
                names |= expand(item)
        return names

    allowed, denied = expand("@default"), set()
    for line in UNIT.read_text().splitlines():
        if line.startswith("SystemCallFilter="):
            value = line.partition("=")[2].strip()
            groups = value.lstrip("~").split()
            target = denied if value.startswith("~") else allowed
            for g in groups:
                target |= expand(g)
    header = Path("/usr/include/x86_64-linux-gnu/asm/unistd_64.h")
    if not header.exists():
        pytest.skip("no x86-64 system call table (linux-libc-dev)")
    numbers = dict(re.findall(r"#define __NR_(\w+) (\d+)", header.read_text()))
    assert {"read", "write", "clone3", "ioctl"} <= numbers.keys()
    return [int(numbers[n]) for n in allowed - denied if n in numbers]


@pytest.mark.slow
def test_the_bridge_runs_under_the_units_system_call_filter(tmp_path):
    """The unit's filter, EPERM for the rest as SystemCallErrorNumber= says: the bridge
    polls an RTU node over a serial line (pyserial's termios calls), writes the PLC over
    TCP, records to a file, then stops on SIGHUP with the PLC reading BRIDGE_OFFLINE."""
    import platform

    from pymodbus.client import ModbusTcpClient

    from tests.helpers.bridge import TimedPlc
    from tests.helpers.modbus import pty_pair

    if platform.machine() != "x86_64":
        pytest.skip("the filter is written for x86-64")
    allowed = ",".join(str(n) for n in _unit_syscalls(need("systemd-analyze")))
    profile = str(ROOT / "profiles" / "paper-5x5.toml")
    env = {**os.environ, "PYTHONPATH": os.getcwd()}
    rec = tmp_path / "hold.csv"
    subprocess.run([sys.executable, "-m", "eskin_industrial", "simulate", "hold", "-o", str(rec)], check=True,
                   capture_output=True, timeout=60, env=env)
    plc = TimedPlc(free_port()).start()
    updates = tmp_path / "updates.csv"
    try:
        with pty_pair(tmp_path) as (a, b):
            node = subprocess.Popen([sys.executable, "-m", "eskin_industrial", "modbus-node", "-p", profile, "--port",
                                     a, "--recording", str(rec)], stderr=subprocess.DEVNULL, env=env)
            bridge = subprocess.Popen([sys.executable, str(SANDBOX), f"syscalls={allowed}", "-m", "eskin_industrial",
                                       "bridge", "-p", profile, "--source", f"rtu:{b}", "--plc",
                                       f"tcp:127.0.0.1:{plc.port}", "--record", str(updates), "--log-format", "json",
                                       "--status-every", "0"], stderr=subprocess.PIPE, text=True, env=env)
            try:
                wait_for(lambda: (plc.last() or {}).get("STATUS", 0) & 0b100010 == 0b100010 or bridge.poll() is not None,
                         timeout_s=20, what="a valid stable image")  # STABLE and DATA_VALID
                assert bridge.poll() is None, bridge.communicate(timeout=5)[1][-3000:]
                bridge.send_signal(signal.SIGHUP)
                _, err = bridge.communicate(timeout=20)
            finally:
                for proc in (bridge, node):
                    if proc.poll() is None:
                        proc.kill()
                        proc.communicate(timeout=10)
        assert bridge.returncode == 0, err[-3000:]
        client = ModbusTcpClient("127.0.0.1", port=plc.port, timeout=2)
        assert client.connect()
        try:
            status = client.read_holding_registers(0, count=1).registers[0]
        finally:
            client.close()
    finally:
        plc.stop()
    assert status == 1 << 10  # BRIDGE_OFFLINE alone
    assert "Traceback" not in err and '"reason": "SIGHUP"' in err
    assert len(updates.read_text().splitlines()) > 50
