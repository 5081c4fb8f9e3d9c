"""What the OPC UA server tells: its counters (the server's own, the same for every
node, and each node's) and its events, a warning at most one line a second each."""

from __future__ import annotations

import collections
import time
from collections.abc import Callable, Sequence
from typing import Any


class Report:
    """The counters and the events of one server (its thread; the loops read the counters)."""

    def __init__(self, names: Sequence[str], on_event: Callable[..., None] | None = None) -> None:
        self.names = list(names)  #: the nodes' names, by index
        self.on_event: Callable[..., None] = on_event or (lambda *args, **fields: None)
        self.counts: collections.Counter[str] = collections.Counter()
        self.node_counts: list[collections.Counter[str]] = [collections.Counter() for _ in self.names]
        self._logged: dict[str, tuple[float, int]] = {}

    def event(self, name: str, level: str, **fields: Any) -> None:
        """One event; ``node_index`` (or ``node_event``, a name) says whose node it is."""
        i = fields.pop("node_index", None)
        node = fields.pop("node_event", None)
        if i is not None:
            node = self.names[i]
        self.on_event(name, level, node, **fields)

    def log_once(self, event: str, level: str, **fields: Any) -> None:
        """At most one line a second per event; the next says how many were not logged."""
        now = time.monotonic()
        last, quiet = self._logged.get(event, (float("-inf"), 0))
        if now - last < 1.0:
            self._logged[event] = (last, quiet + 1)
            return
        self._logged[event] = (now, 0)
        self.event(event, level, not_logged=quiet, **fields)
