"""Snapshots from the node loops' threads to the server's event loop: bounded, newest
wins, and the loop never waits.

The loop's side (:meth:`Handover.put`) appends to a bounded deque or replaces a
slot.  Urgent snapshots (a state, validity, latch or health change) wake the server
at once, at most once until it has looked (:class:`Waker`: one
``call_soon_threadsafe`` per batch, a byte on asyncio's self pipe), and are kept in
order, up to :data:`URGENT_MAX` per node, so that a slip that starts and ends
between two of the server's turns is still seen (its data changes, its alarm); past
that bound the oldest go (counted).  A periodic refresh, and a taxel frame, only
replace the previous one (the newest wins) and wake nobody: the server takes them
at its next turn, at least every ``refresh_s`` (one wake for every node's refresh,
not one a node).
"""

from __future__ import annotations

import collections
import itertools
from collections.abc import Callable
from typing import Any

from ...node import NodeSnapshot

URGENT_MAX = 32


class Waker:
    """Wakes the server once per batch from any thread; :meth:`arm` is the server
    saying it has looked (before it takes what is pending)."""

    def __init__(self) -> None:
        self._call: Callable[[], None] | None = None
        self._armed = False
        self.failed = 0  #: wakes that found the server's loop closed

    def attach(self, call: Callable[[], None]) -> None:
        """``call``: thread-safe, wakes the server (its loop's ``call_soon_threadsafe``)."""
        self._call = call

    def wake(self) -> None:
        if self._armed:
            return  # already woken, not looked at yet: what was just put is taken too
        self._armed = True
        call = self._call
        if call is None:
            return
        try:
            call()
        except RuntimeError:  # the loop has closed (the server stopped)
            self.failed += 1

    def arm(self) -> None:
        self._armed = False


class Handover:
    """One node's snapshots and frames, from its loop to the server."""

    def __init__(self, waker: Waker) -> None:
        self.waker = waker
        self._seq = itertools.count()
        self._urgent: collections.deque[tuple[int, NodeSnapshot]] = collections.deque(maxlen=URGENT_MAX)
        self._latest: tuple[int, NodeSnapshot] | None = None
        self._frame: tuple[Any, float] | None = None
        self.dropped = 0  #: urgent snapshots lost to the bound
        self.frames_replaced = 0  #: frames replaced before the server took them

    # -- the loop's thread --------------------------------------------------------
    def put(self, snapshot: NodeSnapshot) -> None:
        item = (next(self._seq), snapshot)
        if snapshot.urgent:
            urgent = self._urgent
            if len(urgent) == URGENT_MAX:
                self.dropped += 1
            urgent.append(item)
            self.waker.wake()
        else:
            self._latest = item

    def put_frame(self, forces: Any, wall_time_s: float) -> None:
        if self._frame is not None:
            self.frames_replaced += 1
        self._frame = (forces, wall_time_s)

    # -- the server's thread ------------------------------------------------------
    def take(self) -> list[NodeSnapshot]:
        """What came since the last call, in order: every urgent snapshot, then the
        newest refresh when it came after them."""
        urgent = self._urgent
        out: list[tuple[int, NodeSnapshot]] = []
        while urgent:
            out.append(urgent.popleft())
        latest, self._latest = self._latest, None
        if latest is not None and (not out or latest[0] > out[-1][0]):
            out.append(latest)
        return [s for _, s in out]

    def take_frame(self) -> tuple[Any, float] | None:
        frame, self._frame = self._frame, None
        return frame
