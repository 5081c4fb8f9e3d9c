"""The methods of a node's object (Tare, AcknowledgeSlip, Enable), on the server's
thread: each judged under :func:`~eskin_industrial.node.refusal` on the newest
snapshot its loop published, then queued for the loop, which takes it at its next
turn."""

from __future__ import annotations

import collections
from collections.abc import Callable
from typing import Any

from asyncua import ua

from ...node import Command, NodeSnapshot, refusal
from . import status
from .options import OpcuaOptions
from .report import Report
from .uaconv import status_code

#: Commands held for a node's loop at most; past it a call is answered BadTooManyOperations.
COMMANDS_MAX = 64
_METHOD_COMMAND = {"Tare": "tare", "AcknowledgeSlip": "ack"}


class Calls:
    """Every node's method calls on one server, and the commands waiting for each loop."""

    def __init__(self, options: OpcuaOptions, nodes: int, report: Report) -> None:
        self.options = options
        self.report = report
        #: The newest snapshot each node's loop published (a command is judged on it).
        self.published: list[NodeSnapshot | None] = [None] * nodes
        self.commands: list[collections.deque[Command]] = [collections.deque() for _ in range(nodes)]
        self.by_object: dict[ua.NodeId, int] = {}  #: a node's index by its object

    def take(self, index: int) -> list[Command]:
        """The node's waiting commands (its loop's thread)."""
        q = self.commands[index]
        out = []
        while q:
            out.append(q.popleft())
        return out

    def method(self, name: str) -> Callable[..., Any]:
        """The callback of the method ``name`` (for every node's object)."""
        async def call(parent: ua.NodeId, *args: Any) -> Any:
            return self.call(name, parent, args)

        return call

    def call(self, name: str, parent: ua.NodeId, args: tuple[Any, ...]) -> Any:
        """A method of a node (the server's thread): judged under the one refusal rule
        on the newest snapshot its loop published, then queued for the loop."""
        i = self.by_object.get(parent)
        if i is None:  # called on the type, or on another object
            return status_code(ua.StatusCodes.BadMethodInvalid)
        counts = self.report.node_counts[i]
        counts["method_calls"] += 1
        if name == "Enable":
            if not args:
                return status_code(ua.StatusCodes.BadArgumentsMissing)
            value = args[0].Value
            if not isinstance(value, bool):
                return status_code(ua.StatusCodes.BadTypeMismatch)
            command = Command("enable" if value else "disable")
        else:
            command = Command(_METHOD_COMMAND[name])  # type: ignore[arg-type]
        why = refusal(command, self.published[i], read_only=self.options.read_only)
        if why is not None:
            counts["commands_refused"] += 1
            self.report.event("opcua_command_refused", "warning", node_index=i, command=command.name, reason=why)
            return status_code(status.BAD_USER_ACCESS_DENIED if why == "read_only" else status.BAD_INVALID_STATE)
        queue = self.commands[i]
        if len(queue) >= COMMANDS_MAX:
            counts["commands_busy"] += 1
            self.report.log_once("opcua_commands_busy", "warning", command=command.name)
            return status_code(status.BAD_TOO_MANY_OPERATIONS)
        queue.append(command)
        counts["commands"] += 1
        self.report.event("opcua_command", "info", node_index=i, command=command.name)
        return []
