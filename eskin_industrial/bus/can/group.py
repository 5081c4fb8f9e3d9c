"""Several sensor nodes on one CAN bus: one reader, frames routed by arbitration ID.

The bus (or a replayed log) is read by one thread into one bounded queue
(:class:`~eskin_industrial.bus.can_source.BusReader`, or :class:`LogPlayer` for a
log).  :class:`CanGroup` moves each frame into the queue of the node that owns its
ID (16 IDs from the node's ``base_id``), where that node's
:class:`~eskin_industrial.bus.can_poll.CanScanPoller` assembles it; error frames go
to every node, since a bus error concerns them all; frames of no node are counted.
"""

from __future__ import annotations

import collections

import can

from ...bridge.config import ResolvedNode
from .layout import ID_RANGE, CanLayout, ScanAssembler
from .source import CanScanPoller


class _NoWait:
    """A node's queue is filled by the group loop itself: nothing to wait for."""

    def clear(self) -> None:
        pass

    def wait(self, timeout: float | None = None) -> bool:
        return False


class _NodeQueue:
    """What a node's poller reads: its own frames, the bus's counters."""

    def __init__(self, reader) -> None:
        self.queue: collections.deque[can.Message] = collections.deque()
        self.counters = reader.counters
        self.arrived = _NoWait()
        self._reader = reader

    @property
    def last_error(self) -> str:
        """The shared bus's last error: the bridge's ``bus_fault`` log line reads it
        from the node's reader, which would otherwise always say ``-``."""
        return getattr(self._reader, "last_error", "")


class CanGroup:
    def __init__(self, reader, nodes: list[ResolvedNode]) -> None:
        self.reader = reader
        self.names = [n.name for n in nodes]
        self.pollers: list[CanScanPoller] = []
        self._route: dict[tuple[bool, int], collections.deque] = {}
        self._queues: list[collections.deque] = []
        self.unrouted_frames = 0
        for n in nodes:
            layout = CanLayout.from_profile(n.profile, fd=n.fd)
            nq = _NodeQueue(reader)
            self.pollers.append(CanScanPoller(nq, ScanAssembler(layout, n.rate_hz)))  # type: ignore[arg-type]
            self._queues.append(nq.queue)
            for can_id in range(layout.base_id, layout.base_id + ID_RANGE):
                self._route[(layout.extended_id, can_id)] = nq.queue

    def route(self, timeout_s: float) -> int:
        """Wait up to ``timeout_s`` for frames, then hand every queued frame to its
        node; returns how many."""
        q, arrived = self.reader.queue, self.reader.arrived
        if not q:
            arrived.clear()
            if not q:
                arrived.wait(timeout_s)
        n = 0
        route = self._route
        while q:
            msg = q.popleft()
            n += 1
            if msg.is_error_frame:
                for nq in self._queues:
                    nq.append(msg)
                continue
            dest = route.get((msg.is_extended_id, msg.arbitration_id))
            if dest is None:
                self.unrouted_frames += 1
            else:
                dest.append(msg)
        return n

    @property
    def done(self) -> bool:
        """A replayed log has ended and every frame was handed on."""
        return self.reader.done and not self.reader.queue

    def stop(self) -> None:
        self.reader.stop()


