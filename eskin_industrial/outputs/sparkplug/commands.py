"""Sparkplug device commands (DCMD) as the bridge's commands: pure, no I/O.

A host application writes a device's command metrics, declared in its DBIRTH; each
becomes the same :class:`~eskin_industrial.node.Command` a PLC's COMMAND or ENABLE
write gives, and is refused under the same rule (:func:`~eskin_industrial.node.refusal`:
no tare while something is held, or while the detector cannot say).
"""

from __future__ import annotations

from typing import NamedTuple

from ...node import Command, CommandName
from . import payload as pb


class CommandDef(NamedTuple):
    name: str
    on_true: CommandName
    on_false: CommandName | None  #: None: a write of false is not a command
    doc: str


#: The device's command metrics (Boolean), aliases ``device base + COMMAND_ALIAS + index``.
COMMANDS: tuple[CommandDef, ...] = (
    CommandDef("Device Control/Tare", "tare", None,
               "write true: tare (refused while something is held or the state is unknown)"),
    CommandDef("Device Control/Acknowledge Slip", "ack", None, "write true: acknowledge the slip latch"),
    CommandDef("Device Control/Enable", "enable", "disable", "write true to enable detection, false to disable"),
)
COMMAND_ALIAS = 100
_BY_NAME = {c.name: i for i, c in enumerate(COMMANDS)}


class BadCommand(ValueError):
    """A DCMD that is not one of this device's commands (one line: what is wrong)."""


def parse_device_command(payload: pb.Payload, base: int) -> list[Command]:
    """The commands of one DCMD, in order; :class:`BadCommand` if any metric is not a
    command of this device (by name, or by alias from ``base``) or not a Boolean."""
    if not payload.metrics:
        raise BadCommand("no metrics")
    out: list[Command] = []
    for m in payload.metrics:
        index = _BY_NAME.get(m.name) if m.name is not None else None
        if index is None and m.name is None and m.alias is not None:
            offset = m.alias - base - COMMAND_ALIAS
            index = offset if 0 <= offset < len(COMMANDS) else None
        if index is None:
            raise BadCommand(f"metric {m.name if m.name is not None else f'alias {m.alias}'!r} is not a command")
        c = COMMANDS[index]
        if not isinstance(m.value, bool):
            raise BadCommand(f"{c.name}: expected a Boolean value, got {m.value!r}")
        name = c.on_true if m.value else c.on_false
        if name is None:
            raise BadCommand(f"{c.name}: only true is a command")
        out.append(Command(name))
    return out


def birth_metrics(base: int, now: int, enabled: bool | None) -> list[pb.Metric]:
    """The command metrics of a DBIRTH: Tare and Acknowledge Slip false (nothing
    asked), Enable the detection's current state (null before the first snapshot),
    as a birth gives every metric its current value
    (tck-id-operational-behavior-data-publish-dbirth-values)."""
    out = []
    for i, c in enumerate(COMMANDS):
        value = enabled if c.on_false is not None else False
        out.append(pb.Metric(c.name, base + COMMAND_ALIAS + i, now, pb.BOOLEAN, value,
                             is_null=True if value is None else None))
    return out
