"""What the OPC UA server keeps of one node: its nodes in the address space, the
values it last wrote, its alarm."""

from __future__ import annotations

import threading
from typing import Any

from ...node import NodeSnapshot
from . import model, status
from .alarm import AlarmState
from .build import NodeHandles, NodeInfo


class NodeState:
    """One node, on the server's thread (``offline_applied`` is waited on from the loops')."""

    def __init__(self, index: int, info: NodeInfo) -> None:
        self.index = index
        self.info = info
        self.handles: NodeHandles | None = None
        self.last: list[tuple[Any, int]] = [(None, -1)] * len(model.VARIABLES)  #: (value, status) written
        self.machinery: dict[str, str] = {}  #: each state machine's state written
        self.snapshot: NodeSnapshot | None = None  #: the newest applied
        self.source_end: status.SourceEnd = ""
        self.alarm = AlarmState()
        self.event: Any = None  #: the alarm's event object (asyncua), its fields the condition's state
        self.applied = 0
        self.offline_applied = threading.Event()
