"""The conventions docs/cli.md and the README promise, for every command: a usage error
is one line on stderr (exit 2), -q/-v are accepted everywhere (the groups `examples`
and `plc` too), `-m` is the method wherever there is one and offers every method, and
the exit codes are the documented ones (3: a transport that cannot be opened, 2: a
port in use)."""

from __future__ import annotations

import socket
import subprocess
import sys
from pathlib import Path

import click
import pytest
from click.testing import CliRunner

from eskin_industrial.cli import main
from eskin_industrial.methods import method_names
from tests.helpers.paths import PROFILES

PAPER = str(PROFILES / "paper-5x5.toml")


def run(*args: str):
    return CliRunner().invoke(main, list(args), prog_name="eskin-bus")


@pytest.mark.parametrize("args, expected", [
    (["--bogus"], "No such option '--bogus'"),
    (["nosuch"], "No such command 'nosuch'; help: eskin-bus -h"),
    (["detect"], "Missing option '-p' / '--profile'; help: eskin-bus detect -h"),
    (["detect", "-p", PAPER, "x.csv", "--engine", "nope"], "Invalid value for '--engine'"),
    (["plc", "nosuch"], "No such command 'nosuch'; help: eskin-bus plc -h"),
    (["bridge", "-p", PAPER, "--source", "x:y"], "Invalid value for --source: unknown source kind 'x'"),
    (["simulate"], "give a SCENE (see --list); help: eskin-bus simulate -h"),
])
def test_a_usage_error_is_one_line(args: list[str], expected: str) -> None:
    res = run(*args)
    lines = [line for line in res.stderr.splitlines() if line]
    assert res.exit_code == 2 and len(lines) == 1, res.output
    assert lines[0].startswith("eskin-bus: error: ") and expected in lines[0], res.output
    assert " -h" in lines[0].rpartition("; help: ")[2], res.output  # the help page to see


def test_a_group_without_its_command_still_shows_its_help() -> None:
    res = run("plc")
    assert "Usage: eskin-bus plc" in res.output and "map" in res.output


@pytest.mark.parametrize("args", [
    ["examples", "-q"], ["examples", "-v"], ["-q", "examples"],
    ["plc", "-q", "map", "-p", PAPER, "--format", "csv"], ["plc", "-v", "map", "-p", PAPER, "--format", "csv"],
    ["plc", "map", "-p", PAPER, "--format", "csv", "-q"],
])
def test_every_command_takes_q_and_v(args: list[str]) -> None:
    res = run(*args)
    assert res.exit_code == 0, res.output
    assert res.stdout.strip(), res.output


def test_detect_takes_m_for_its_method(tmp_path: Path) -> None:
    rec = tmp_path / "r.csv"
    assert run("simulate", "case2", "-o", str(rec)).exit_code == 0
    res = run("detect", "-p", PAPER, str(rec), "-m", "cof-step", "--changes")
    assert res.exit_code == 0, res.output
    assert "method cof-step" in res.stderr


def _commands(cmd: click.Command, path: tuple[str, ...] = ()) -> list[tuple[str, click.Command]]:
    if isinstance(cmd, click.Group):
        return [c for name, sub in cmd.commands.items() for c in _commands(sub, (*path, name))]
    return [(" ".join(path), cmd)]


def test_every_method_option_is_m_and_offers_every_method() -> None:
    found = {}
    for name, cmd in _commands(main):
        for p in cmd.params:
            if isinstance(p, click.Option) and "--method" in p.opts:
                found[name] = p
    assert {"detect", "evaluate", "demo", "plot", "monitor"} <= set(found), sorted(found)
    for name, option in found.items():
        assert "-m" in option.opts, f"{name}: {option.opts}"
        if isinstance(option.type, click.Choice):
            assert set(method_names()) <= set(option.type.choices), name  # (evaluate: the baselines too)


def test_demo_offers_every_method() -> None:
    from eskin_industrial.cli.demo_cmd import demo

    (option,) = [p for p in demo.params if "-m" in getattr(p, "opts", [])]
    assert list(option.type.choices) == method_names()  # type: ignore[attr-defined]
    assert "cof-step" in method_names()


def test_modbus_node_on_a_port_that_is_not_there_exits_3(tmp_path: Path) -> None:
    res = subprocess.run([sys.executable, "-m", "eskin_industrial", "modbus-node", "-p", PAPER, "--port",
                          str(tmp_path / "ttyNOPE"), "--scene", "case2", "--duration", "1"],
                         capture_output=True, text=True, timeout=60)
    assert res.returncode == 3, res.stderr
    assert res.stderr.splitlines()[-1].startswith("eskin-bus: error: cannot open serial port "), res.stderr


def test_plc_sim_on_a_port_in_use_exits_2() -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        res = subprocess.run([sys.executable, "-m", "eskin_industrial", "plc-sim", "-p", PAPER, "--port", str(port),
                              "--duration", "1"], capture_output=True, text=True, timeout=60)
    assert res.returncode == 2, res.stderr
    assert res.stderr.strip() == f"eskin-bus: error: modbus server: cannot listen on 127.0.0.1:{port}: " \
                                 "address already in use"
