"""Sparkplug device commands (DCMD) as the bridge's commands: pure, no I/O.

A host application writes a device's command metrics, declared in its DBIRTH; each
becomes the same :class:`~eskin_industrial.node.Command` a PLC's COMMAND or ENABLE
write gives, and is refused under the same rule (:func:`~eskin_industrial.node.refusal`:
no tare while something is held, or while the detector cannot say).

A host may send commands as fast as the broker goes: they are parsed where they arrive
(paho's thread) and wait for the node's loop in a :class:`Mailbox` of at most one
command of each kind, so that the loop applies a few per scan whatever the flood; and
their log lines name a few and count the rest (:func:`summary`, :func:`clip`).
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
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


#: A text a command's log line quotes (an error, a topic, the commands) is cut to this
#: many characters: a DCMD of thousands of metrics, or a metric name of 60,000
#: characters, is still one line of a readable length.
MAX_FIELD_CHARS = 200
#: The commands a line names before "... and N more".
NAMED = 4


def clip(text: str, limit: int = MAX_FIELD_CHARS) -> str:
    """``text`` cut to ``limit`` characters, saying how many were left off."""
    if len(text) <= limit:
        return text
    tail = f"... ({len(text) - limit} more characters)"
    return text[: max(limit - len(tail), 0)] + tail


def summary(names: Sequence[str], named: int = NAMED) -> str:
    """The first ``named`` names, then how many more, within :data:`MAX_FIELD_CHARS`."""
    head = ",".join(names[:named])
    rest = len(names) - named
    return clip(head if rest <= 0 else f"{head} ... and {rest} more")


def kind_of(command: Command) -> str:
    """The slot a command takes in the mailbox: enable and disable share one."""
    return "enable" if command.name in ("enable", "disable") else command.name


class Mailbox:
    """The commands of one device waiting for the node's loop: at most one of each
    kind (tare, ack, enable/disable), the newest winning and going last; what it
    replaces is counted as dropped.  Safe from any thread."""

    def __init__(self) -> None:
        self._slots: dict[str, Command] = {}
        self._lock = threading.Lock()

    def put(self, commands: Sequence[Command]) -> int:
        """Post ``commands`` in order; the number of commands dropped (replaced)."""
        dropped = 0
        with self._lock:
            slots = self._slots
            for cmd in commands:
                kind = kind_of(cmd)
                if slots.pop(kind, None) is not None:
                    dropped += 1
                slots[kind] = cmd
        return dropped

    def take(self) -> list[Command]:
        """Everything posted since the last take, in the order of the newest of each kind."""
        with self._lock:
            out = list(self._slots.values())
            self._slots.clear()
        return out

    def __len__(self) -> int:
        return len(self._slots)


#: A command message costs one token per this many bytes (one at least): decoding
#: costs by the byte (some 1.5 us each in pure Python), a DCMD of 5,000 metrics
#: (195 kB) as much as 2,400 of two.
BUDGET_BYTES = 256


class Budget:
    """A token bucket: ``rate`` tokens a second, bursts of ``rate`` (one at least):
    what the commands of one topic may cost paho's thread.  A message takes one token
    per :data:`BUDGET_BYTES`; it passes while a token is left, and a large one leaves
    the bucket in debt for as long as its cost takes to refill.  Past it a message is
    dropped before it is decoded (decoding is the cost: a flood decoded whole kept the
    loop's thread from the interpreter, and a healthy sensor read stale).  Used from
    paho's thread alone; the clock is handed in."""

    __slots__ = ("rate", "burst", "_tokens", "_at")

    def __init__(self, rate: float) -> None:
        self.rate = rate
        self.burst = max(rate, 1.0)
        self._tokens = self.burst
        self._at: float | None = None

    def take(self, now: float, size: int = 0) -> bool:
        """Whether a message of ``size`` bytes passes at ``now`` (it is charged if so)."""
        if self._at is not None:
            self._tokens = min(self.burst, self._tokens + (now - self._at) * self.rate)
        self._at = now
        if self._tokens < 1.0:
            return False
        self._tokens -= max(1.0, size / BUDGET_BYTES)
        return True


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
