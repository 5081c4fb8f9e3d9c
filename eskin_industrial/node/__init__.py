"""What crosses the output seam: a node's snapshot, the commands that come back, and
the one rule that refuses a command.

Every output (the PLC, Sparkplug, a recorder, a live view) reads the same
:class:`NodeSnapshot` in named fields and SI units; none of them decodes another's
wire format.  :class:`NodeStatus` is the state behind it (enable, slip latch, counts),
kept by the node's loop; :func:`refusal` is the rule every commanding output applies.
Pure code: no I/O, no clock.
"""

from .commands import Command, CommandName, refusal
from .snapshot import Health, NodeSnapshot
from .status import NodeStatus

__all__ = ["Command", "CommandName", "Health", "NodeSnapshot", "NodeStatus", "refusal"]
