"""Commands an output hands back to the node (acknowledge, tare, enable, disable), and
the one rule that refuses one.

A PLC's COMMAND or ENABLE write, a coil, a Sparkplug DCMD and any later output's
method call all become a :class:`Command`, and every one of them is refused under
:func:`refusal`, in this one place: an output that refuses by another rule would
let a host tare what the PLC may not.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Literal, NamedTuple

from ..detect.state import GraspState

if TYPE_CHECKING:
    from .snapshot import NodeSnapshot

CommandName = Literal["ack", "tare", "enable", "disable"]
_NO_CONTACT = int(GraspState.NO_CONTACT)

#: Why a command was refused: the reasons :func:`refusal` gives, for docs and logs.
REASONS: dict[str, str] = {
    "read_only": "the output takes no commands (read-only)",
    "contact_unknown": "tare: the detector has no valid verdict yet that the gripper is open",
    "in_contact": "tare: something is held (the held force would become the new zero)",
}


class Command(NamedTuple):
    name: CommandName


def refusal(command: Command, snapshot: NodeSnapshot | None, *, read_only: bool = False) -> str | None:
    """Why ``command`` must not be applied now (None: it may be), from the newest
    snapshot the output was handed (None: none yet).

    - A read-only output takes no command at all.
    - A tare while something is held would take the held force for the new zero, and
      every output would then read ``no_contact`` with valid data until the next
      tare; so a tare needs a fresh, valid ``no_contact`` (the detector's own verdict:
      a node whose detection is disabled still runs its detector, and may be tared).
    """
    if read_only:
        return "read_only"
    if command.name != "tare":
        return None
    if snapshot is None or snapshot.detected_state is None or not snapshot.detected_valid:
        return "contact_unknown"
    if snapshot.detected_state != _NO_CONTACT:
        return "in_contact"
    return None
