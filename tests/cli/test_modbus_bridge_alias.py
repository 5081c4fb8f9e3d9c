"""`eskin-bus modbus-bridge` is an alias of `eskin-bus bridge --source rtu:PORT` (or
`recording:FILE`): each old option maps to the bridge's own, one deprecation line
names the equivalent command, and the bridge's own code path runs (its log lines, its
signals, its exit codes: tests/bridge/test_signals.py, tests/bridge/test_modbus_e2e.py)."""

from __future__ import annotations

import shlex
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from eskin_industrial.cli import main
from tests.helpers.modbus import free_port
from tests.helpers.paths import PROFILES

PAPER = str(PROFILES / "paper-5x5.toml")
WARNING = "eskin-bus: warning: modbus-bridge is deprecated; it runs: "


@pytest.fixture(scope="module")
def rec(tmp_path_factory: pytest.TempPathFactory) -> str:
    path = tmp_path_factory.mktemp("rec") / "hold.csv"
    res = CliRunner().invoke(main, ["simulate", "hold", "-o", str(path)])
    assert res.exit_code == 0, res.output
    return str(path)


@pytest.mark.parametrize("old, new", [
    (["--rtu", "/dev/ttyUSB0"], ["--source", "rtu:/dev/ttyUSB0"]),
    (["--rtu", "/dev/ttyUSB0", "--baud", "57600"], ["--source", "rtu:/dev/ttyUSB0@57600"]),
    (["--recording", "r.csv"], ["--source", "recording:r.csv"]),
    (["--rtu", "COM3", "--plc-host", "10.0.0.5", "--plc-port", "502"],
     ["--source", "rtu:COM3", "--plc", "tcp:10.0.0.5:502"]),
    (["--rtu", "COM3", "--plc-host", "::1"], ["--source", "rtu:COM3", "--plc", "tcp:[::1]"]),
    (["--rtu", "COM3", "--plc-port", "1502"], ["--source", "rtu:COM3", "--plc", "tcp::1502"]),
    (["--rtu", "COM3", "--plc-timeout", "0.5"], ["--source", "rtu:COM3", "--plc", "tcp:", "--plc-timeout", "0.5"]),
    (["--rtu", "COM3", "--plc-rtu", "/dev/ttyS1", "--plc-baud", "19200"],
     ["--source", "rtu:COM3", "--plc", "rtu:/dev/ttyS1", "--plc-baud", "19200"]),
    (["--rtu", "COM3", "--serve", "127.0.0.1:1502"], ["--source", "rtu:COM3", "--plc", "serve:127.0.0.1:1502"]),
    (["--rtu", "COM3", "--serve", ":1502"], ["--source", "rtu:COM3", "--plc", "serve::1502"]),
    (["--rtu", "COM3", "--serve-rtu", "/dev/ttyS2", "--serve-baud", "9600"],
     ["--source", "rtu:COM3", "--plc", "serve-rtu:/dev/ttyS2", "--plc-baud", "9600"]),
    (["--rtu", "COM3", "--status-every", "5", "--duration", "2.5"],
     ["--source", "rtu:COM3", "--status-every", "5", "--duration", "2.5"]),
])
def test_each_old_option_maps_to_the_bridges_own(old: list[str], new: list[str]) -> None:
    from eskin_industrial.cli.modbus_cmd import modbus_bridge

    ctx = modbus_bridge.make_context("modbus-bridge", ["-p", "paper-5x5", *old])
    args = ctx.invoke(_args_of, **ctx.params)
    assert args == ["-p", "paper-5x5", *new]


def _args_of(**params: object) -> list[str]:
    from eskin_industrial.cli.modbus_cmd import _word, bridge_args

    return [w for flag, _, value in bridge_args(**params) for w in (flag, _word(value))]  # type: ignore[arg-type]


@pytest.mark.parametrize("old, why", [
    ([], "give one of --rtu PORT or --recording REC.csv"),
    (["--recording", "r.csv", "--baud", "9600"], "--baud is the node's serial line"),
    (["--rtu", "COM3", "--serve", "1502", "--serve-rtu", "/dev/ttyS2"], "--serve and --serve-rtu exclude each other"),
    (["--rtu", "COM3", "--plc-host", "10.0.0.5", "--serve", "1502"], "client options (--plc-*) and server options"),
    (["--rtu", "COM3", "--plc-host", "10.0.0.5", "--plc-rtu", "/dev/ttyS1"], "--plc-rtu and --plc-host/--plc-port"),
    (["--rtu", "COM3", "--serve", "127.0.0.1"], "HOST:PORT, :PORT or PORT"),
])
def test_what_the_old_command_refused_is_refused_before_the_bridge_starts(old: list[str], why: str) -> None:
    res = CliRunner().invoke(main, ["modbus-bridge", "-p", PAPER, *old])
    assert res.exit_code == 2 and why in res.output, res.output
    assert WARNING not in res.output


def test_the_printed_command_line_is_one_the_bridge_accepts(rec: str) -> None:
    """The deprecation line, run as it stands (with --check), is a valid bridge."""
    port = free_port()
    res = CliRunner().invoke(main, ["modbus-bridge", "-p", PAPER, "--recording", rec, "--serve", f"127.0.0.1:{port}",
                                    "--duration", "0"])
    assert res.exit_code == 0, res.output
    (line,) = [line for line in res.output.splitlines() if line.startswith(WARNING)]
    words = shlex.split(line.removeprefix(WARNING))
    assert words[:2] == ["eskin-bus", "bridge"]
    checked = CliRunner().invoke(main, [*words[1:], "--check"])
    assert checked.exit_code == 0, checked.output
    assert f"recording {rec} -> PLC server block at 0" in checked.output


@pytest.mark.slow
def test_the_run_is_the_bridges_one_deprecation_line_then_its_log(rec: str, tmp_path: Path) -> None:
    port = free_port()
    proc = subprocess.run([sys.executable, "-m", "eskin_industrial", "modbus-bridge", "-p", PAPER, "--recording", rec,
                           "--serve", f"127.0.0.1:{port}", "--duration", "1"],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    first, *rest = proc.stderr.splitlines()
    assert first == (f"{WARNING}eskin-bus bridge -p {PAPER} --source recording:{rec} "
                     f"--plc serve:127.0.0.1:{port} --duration 1")
    assert not any(line.startswith(("eskin-bus: warning", "modbus-bridge:")) for line in rest), proc.stderr
    events = [line.split()[2] for line in rest]  # TIME LEVEL EVENT key=value ...
    assert events[0] == "start" and events[-2:] == ["stopped", "final"], proc.stderr


def test_quiet_leaves_out_the_deprecation_line(rec: str) -> None:
    res = CliRunner().invoke(main, ["-q", "modbus-bridge", "-p", PAPER, "--recording", rec,
                                    "--serve", f"127.0.0.1:{free_port()}", "--duration", "0"])
    assert res.exit_code == 0 and WARNING not in res.output, res.output
