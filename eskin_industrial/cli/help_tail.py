"""The end of every help page: one or two example command lines, and the command's
ESKIN_* environment variables (docs/cli.md).  The examples use built-in names and
files `eskin-bus examples copy` writes, so each runs from an install in any folder
(tests/cli/test_cli_conventions.py checks their options against the command)."""

from __future__ import annotations

import click

from .docs_cmd import DOCS_LINE

#: Example lines by command path (without "eskin-bus").
EXAMPLES: dict[str, tuple[str, ...]] = {
    "bridge": ("eskin-bus bridge -p paper-5x5 --source scene:case2 --plc serve:127.0.0.1:1502",
               "eskin-bus bridge --config bridge.toml --check   # eskin-bus examples copy bridge.toml"),
    "demo": ("eskin-bus demo", "eskin-bus demo --scene case2 --plain"),
    "detect": ("eskin-bus detect -p paper-5x5 case2.csv -o updates.csv   # eskin-bus examples copy case2.csv",
               "candump -L can0 | eskin-bus detect -p paper-5x5 --can-log - --changes"),
    "profile": ("eskin-bus profile list", "eskin-bus profile show paper-5x5"),
    "profile check": ("eskin-bus profile check cell.toml", "eskin-bus profile check --json paper-5x5 hand-4x5"),
    "profile show": ("eskin-bus profile show hand-4x5", "eskin-bus profile show --json paper-5x5"),
    "profile dbc": ("eskin-bus profile dbc hand-4x5 > hand.dbc", "eskin-bus profile dbc --config bridge.toml > plant.dbc"),
    "profile list": ("eskin-bus profile list",),
    "profile init": ("eskin-bus profile init paper-5x5 -o cell.toml",),
    "profile tune": ("eskin-bus profile tune cell.toml holds.csv --moves moves.csv --write",
                     "eskin-bus profile tune paper-5x5 holds.csv -o cell.toml   # eskin-bus simulate jittery-hold -o holds.csv"),
    "simulate": ("eskin-bus simulate --list", "eskin-bus simulate case2 -o case2.csv --labels case2-labels.csv"),
    "plot": ("eskin-bus plot -p paper-5x5 case2.csv --labels case2-labels.csv -o case2.png",),
    "evaluate": ("eskin-bus evaluate", "eskin-bus evaluate -m cof-track -s case2 --json"),
    "plc": ("eskin-bus plc map -p paper-5x5", "eskin-bus plc export -p paper-5x5 --format codesys -o plc/"),
    "plc map": ("eskin-bus plc map -p paper-5x5", "eskin-bus plc map -p paper-5x5 --json"),
    "plc export": ("eskin-bus plc export -p paper-5x5 --format plcopen -o plc/",
                   "eskin-bus plc export --config bridge.toml --format tia -o plc/"),
    "plc-sim": ("eskin-bus plc-sim -p paper-5x5 --port 1502",),
    "modbus-node": ("eskin-bus modbus-node -p paper-5x5 --port /dev/ttyUSB0 --scene case2",),
    "modbus-bridge": ("eskin-bus modbus-bridge -p paper-5x5 --rtu /dev/ttyUSB0 --serve 127.0.0.1:1502",),
    "node": ("eskin-bus node -p paper-5x5 -i socketcan -c vcan0 --scene case2",
             "eskin-bus node -p paper-5x5 --scene case2 --can-log node.asc   # no bus: a CAN log"),
    "receive": ("eskin-bus receive -p paper-5x5 -i socketcan -c vcan0 -o updates.csv --log traffic.log",
                "eskin-bus receive -p paper-5x5 --can-log node.asc -o updates.csv   # a log replayed, as if received"),
    "monitor": ("eskin-bus monitor -p hand-4x5 -i socketcan -c vcan0",),
    "examples": ("eskin-bus examples", "eskin-bus examples copy bridge.toml"),
    "examples copy": ("eskin-bus examples copy bridge.toml", "eskin-bus examples copy all cell7"),
    "plant": ("eskin-bus plant mqtt://127.0.0.1:1883", "eskin-bus plant mqtt://127.0.0.1:1883 --json --duration 10"),
    "opcua": ("eskin-bus opcua nodeset -o eskin.xml",),
    "opcua nodeset": ("eskin-bus opcua nodeset -o eskin.xml",),
    "opcua cert": ("eskin-bus opcua cert --config bridge.toml",),
    "opcua trust": ("eskin-bus opcua trust --pki-dir pki",),
    "opcua user": ("eskin-bus opcua user add users.toml scada --role reader",),
    "opcua user add": ("eskin-bus opcua user add users.toml scada --role reader",),
    "docs": ("eskin-bus docs", "eskin-bus docs plc   # docs/plc.md"),
    "completion": ("eskin-bus completion bash > ~/.local/share/bash-completion/completions/eskin-bus",),
}


def envvars(cmd: click.Command) -> list[str]:
    return [str(p.envvar) for p in cmd.params if isinstance(p, click.Option) and isinstance(p.envvar, str)]


def add_command_help_tail(cmd: click.Command, path: str) -> None:
    """The help of ``cmd`` (command path ``path``: ``bridge``, ``plc map``) and of every
    command under it ends with its examples and its variables (after
    :func:`~eskin_industrial.cli.console.add_command_envvars`, which names them)."""
    parts = []
    if path in EXAMPLES:
        # \b: click keeps the lines as they are instead of rewrapping them
        parts.append("\b\nExamples:\n" + "\n".join(f"  {line}" for line in EXAMPLES[path]))
    names = envvars(cmd)
    if names:
        parts.append("Environment: " + ", ".join(names) + " (docs/cli.md).")
    parts.append(f"\b\n{DOCS_LINE}")  # the pages the text names (docs/X.md): eskin-bus docs X
    cmd.epilog = "\n\n".join(parts)
    if isinstance(cmd, click.Group):
        for name, sub in cmd.commands.items():
            add_command_help_tail(sub, f"{path} {name}")
