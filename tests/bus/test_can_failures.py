"""Failures that name their cause: a kernel without SocketCAN, a channel nobody sends
on; each one line with an exit code of its own, the codes listed in docs/cli.md."""
from __future__ import annotations

import errno
import re
import socket
import subprocess
import sys

import can
import pytest

from eskin_industrial import errors
from eskin_industrial.bus.can.reader import open_bus
from eskin_industrial.errors import EskinError, NothingReceived, SocketCanMissing
from tests.helpers.paths import ROOT


def eskin_bus(*args: str, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "eskin_industrial", *args], capture_output=True, text=True,
                          timeout=timeout)


def kernel_has_socketcan() -> bool:
    try:
        socket.socket(socket.PF_CAN, socket.SOCK_RAW, socket.CAN_RAW).close()
    except OSError as exc:
        return exc.errno != errno.EAFNOSUPPORT
    return True


def assert_no_socketcan_line(stderr: str) -> None:
    assert stderr.count("\n") == 1 and stderr.startswith("eskin-bus: error: cannot open CAN bus"), stderr
    assert "this kernel has no SocketCAN" in stderr and "modprobe can" in stderr and "modprobe vcan" in stderr
    assert "valid interfaces" not in stderr  # the name was right


@pytest.mark.skipif(kernel_has_socketcan(), reason="this kernel has SocketCAN: its absence cannot be shown here")
@pytest.mark.parametrize("command", [["receive"], ["node", "--scene", "case2"], ["monitor", "--plain"]])
def test_a_kernel_without_socketcan_is_named_as_such(command):
    res = eskin_bus(command[0], "-p", "paper-5x5", "-i", "socketcan", "-c", "vcan0", *command[1:])
    assert res.returncode == SocketCanMissing.exit_code == 5, res.stderr
    assert_no_socketcan_line(res.stderr)


def test_the_missing_address_family_is_told_from_a_wrong_name(monkeypatch):
    """Whatever the kernel: python-can's socketcan failing with EAFNOSUPPORT (raw, or
    wrapped in its own error) is SocketCanMissing; an unknown name still lists the names."""
    def no_af_can(**kwargs):
        raise OSError(errno.EAFNOSUPPORT, "Address family not supported by protocol")

    def wrapped(**kwargs):
        try:
            no_af_can()
        except OSError as exc:
            raise can.CanInitializationError(str(exc)) from exc

    for fake in (no_af_can, wrapped):
        monkeypatch.setattr(can, "Bus", fake)
        with pytest.raises(SocketCanMissing) as caught:
            open_bus("socketcan", "vcan0")
        assert_no_socketcan_line(f"eskin-bus: error: {caught.value}\n")
    monkeypatch.undo()
    with pytest.raises(errors.CanBusError) as caught:
        open_bus("nosuchbus", "x")
    assert not isinstance(caught.value, SocketCanMissing) and "valid interfaces" in str(caught.value)


@pytest.mark.parametrize("command", [["monitor", "--plain"], ["receive", "-q"]])
def test_idle_exit_counts_from_the_start(command):
    """A channel that never sends ends the run after --idle-exit, in one line, exit 6
    (it used to wait for a first scan for ever)."""
    res = eskin_bus(command[0], "-p", "paper-5x5", "-i", "virtual", "-c", "nobody-sends-here", "--idle-exit", "0.5",
                    *command[1:])
    assert res.returncode == NothingReceived.exit_code == 6, res.stderr
    last = res.stderr.splitlines()[-1]
    assert re.fullmatch(r"eskin-bus: error: no scan of profile paper-5x5's node on .*nobody-sends-here in 0\.5 s "
                        r"\(--idle-exit\): nothing sent there on IDs 0x200-0x20f; .*", last), last


def _subclasses(cls: type) -> list[type]:
    return [cls, *(s for sub in cls.__subclasses__() for s in _subclasses(sub))]


def test_every_exit_code_is_distinct_in_its_cause_and_listed_in_cli_md():
    table = (ROOT / "docs" / "cli.md").read_text().split("## Exit codes", 1)[1]
    listed = {int(m.group(1)): m.group(2) for m in re.finditer(r"^\| (\d+) \| (.+) \|$", table, re.M)}
    codes = {c.exit_code for c in _subclasses(EskinError) if c.__module__ == errors.__name__}
    assert codes <= set(listed), (codes, listed)
    assert "SocketCAN" in listed[5] and "modprobe" in listed[5]
    assert "--idle-exit" in listed[6]
    others = {c.exit_code for c in _subclasses(EskinError) if c not in (SocketCanMissing, NothingReceived)}
    assert not {5, 6} & others


@pytest.mark.parametrize("command", [["receive", "-q"], ["monitor", "--plain"]])
def test_a_reader_thread_that_dies_stops_the_command_in_one_line(monkeypatch, command):
    """The CAN reader ending by an exception no bus error explains (a bug, a library's
    surprise): the command stops at once with one line naming the thread and the
    error, exit 1, instead of running on with nothing behind its verdicts (the
    bridge's thread watch, in the commands that run one node in the foreground)."""
    import threading
    import time

    from click.testing import CliRunner

    from eskin_industrial.bus.can.reader import BusReader
    from eskin_industrial.cli import main

    def broken(self: BusReader) -> None:
        time.sleep(0.2)
        raise RuntimeError("reader broke")

    monkeypatch.setattr(BusReader, "_run", broken)
    hook = threading.excepthook
    start = time.monotonic()
    res = CliRunner().invoke(main, [command[0], "-p", "paper-5x5", "-i", "virtual", "-c", "dies-here", "--duration",
                                    "20", *command[1:]])
    assert time.monotonic() - start < 10, "it ran on"
    assert res.exit_code == EskinError.exit_code == 1, res.output
    assert threading.excepthook is hook  # (put back)
    last = res.output.strip().splitlines()[-1]
    assert last == (f"eskin-bus: error: {command[0]} stopped: thread can-reader died: RuntimeError: reader broke"), \
        res.output
