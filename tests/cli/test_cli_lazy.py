"""The top-level commands are imported when named: a start pays for its own
command's modules only, and every command of the table loads as the eager group did."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import click
import pytest

from eskin_industrial.cli import COMMANDS, main
from eskin_industrial.cli.lazy import LazyCommands
from tests.helpers.paths import ROOT

_PROBE = r"""
import json, sys
from eskin_industrial.cli import main
try:
    main(sys.argv[1:], prog_name="eskin-bus")
except SystemExit:
    pass
print(json.dumps(sorted(m for m in sys.modules if m.startswith("eskin_industrial.cli."))), file=sys.stderr)
"""


def _cli_modules_after(*args: str) -> list[str]:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    run = subprocess.run([sys.executable, "-c", _PROBE, *args], capture_output=True, text=True, cwd=ROOT, env=env,
                         timeout=60)
    return json.loads(run.stderr.strip().splitlines()[-1])


def test_a_command_line_imports_its_own_command_only():
    base = {"eskin_industrial.cli.console", "eskin_industrial.cli.docs_cmd", "eskin_industrial.cli.help_tail",
            "eskin_industrial.cli.lazy"}
    assert set(_cli_modules_after("--version")) <= base
    loaded = set(_cli_modules_after("plc", "map", "-p", "paper-5x5", "--json"))
    assert "eskin_industrial.cli.plc_cmd" in loaded
    assert not loaded & {"eskin_industrial.cli.bridge_cmd", "eskin_industrial.cli.evaluate_cmd",
                         "eskin_industrial.cli.demo_cmd", "eskin_industrial.cli.receive_cmd"}, loaded


def _leaves(cmd: click.Command) -> list[click.Command]:
    if isinstance(cmd, click.Group):
        return [leaf for sub in cmd.commands.values() for leaf in _leaves(sub)]
    return [cmd]


def test_every_command_of_the_table_loads_under_its_name_with_the_options_every_command_has():
    for name in COMMANDS:
        cmd = main.commands[name]
        assert isinstance(cmd, click.Command) and cmd.name == name
        for leaf in _leaves(cmd):
            opts = {o for p in leaf.params for o in getattr(p, "opts", [])}
            assert {"-v", "-q"} <= opts, (name, leaf.name)
            assert any(getattr(p, "envvar", None) for p in leaf.params), (name, leaf.name)
            assert leaf.epilog and "Docs: eskin-bus docs" in leaf.epilog
    assert sorted(main.commands) == sorted(COMMANDS)


def test_the_mapping_dresses_a_command_once_and_knows_names_without_loading():
    dressed: list[str] = []
    lazy = LazyCommands("eskin_industrial.cli", {"docs": ("docs_cmd", "docs")}, lambda n, c: dressed.append(n))
    assert "docs" in lazy and "nothing" not in lazy and not dressed
    assert lazy["docs"] is lazy.get("docs") and dressed == ["docs"]
    assert list(lazy) == ["docs"] and len(lazy) == 1 and dressed == ["docs"]
    with pytest.raises(KeyError):
        lazy["nothing"]
    del lazy["docs"]
    assert "docs" not in lazy and len(lazy) == 0
