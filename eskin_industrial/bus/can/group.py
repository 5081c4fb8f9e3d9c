"""Frames of one CAN bus (or one replayed log) for the nodes on it.

The bus is read by one thread into one bounded queue
(:class:`~eskin_industrial.bus.can.reader.BusReader`, or
:class:`~eskin_industrial.bus.can.log.LogPlayer` for a log).  :meth:`CanGroup.route`
waits for frames and moves each into the queue of the node that owns its ID (16 IDs
from the node's ``base_id``); error frames go to every node, since a bus error
concerns them all; frames of no node are counted.  With ``all_frames`` (a receiver
watching one node), the lone node also gets every other frame, which its assembler
counts as foreign.  A recording of the
traffic (``receive --log``) gets every frame read, before any routing.
"""

from __future__ import annotations

import collections
import struct
import threading
from collections.abc import Callable, Sequence

import can

from .layout import ID_RANGE, CanLayout
from .reader import FrameThread


class CanGroup:
    """The feeder of the nodes on one bus: ``route`` once a round, then each node's
    source assembles its own frames."""

    def __init__(self, reader: FrameThread, layouts: Sequence[CanLayout],
                 log: can.Listener | None = None, all_frames: bool = False) -> None:
        self.reader = reader
        self.log = log
        self.queues: list[collections.deque[can.Message]] = [collections.deque() for _ in layouts]
        self._route: dict[tuple[bool, int], collections.deque[can.Message]] = {}
        self._single = self.queues[0] if len(layouts) == 1 and all_frames else None
        for layout, q in zip(layouts, self.queues):
            for can_id in range(layout.base_id, layout.base_id + ID_RANGE):
                self._route[(layout.extended_id, can_id)] = q
        self.unrouted_frames = 0
        self.log_write_errors = 0
        self._started = False
        #: Held by whoever steps the nodes of this bus: the loop thread, or the reader
        #: thread serving an arrival while the loop thread waits.
        self.lock = threading.Lock()
        self._serve: Callable[[], None] | None = None
        self.serve_error: BaseException | None = None

    def serve_arrivals(self, serve: Callable[[], None]) -> None:
        """Let the reader thread run ``serve`` (route, then step every node) itself when
        frames arrive while the nodes' loop thread is idle: the scan is decided and
        published with no thread hand-off.  Under load (frames already queued, or the
        loop thread busy) the reader only queues them, as before, and keeps reading."""
        self._serve = serve
        self.reader.on_queued = self._on_queued  # a log player replays at its pace: it never calls it

    def _on_queued(self) -> bool:
        serve = self._serve
        if serve is None or not self.lock.acquire(blocking=False):
            return False
        try:
            serve()
        except BaseException as exc:  # noqa: BLE001 - handed to the loop thread, which fails the bridge
            self.serve_error, self._serve = exc, None
            return False
        finally:
            self.lock.release()
        return True

    def start(self) -> CanGroup:
        """Start the reader (once: several sources share it)."""
        if not self._started:
            self._started = True
            self.reader.start()
        return self

    def wait(self, timeout_s: float) -> None:
        """Wait up to ``timeout_s`` for frames to be queued."""
        q, arrived = self.reader.queue, self.reader.arrived
        if not q:
            # Cleared before the second look, so a frame queued in between is seen.
            arrived.clear()
            if not q:
                arrived.wait(timeout_s)

    def route(self, timeout_s: float) -> int:
        """Wait up to ``timeout_s`` for frames, then hand every queued frame to its
        node; returns how many."""
        if timeout_s > 0.0:
            self.wait(timeout_s)
        q = self.reader.queue
        n = 0
        log, single, route = self.log, self._single, self._route
        while q:
            msg = q.popleft()
            n += 1
            if log is not None:
                self._record(log, msg)
            if single is not None:
                # a receiver watching one node: it sees every frame
                if not msg.is_error_frame and (msg.is_extended_id, msg.arbitration_id) not in route:
                    self.unrouted_frames += 1
                single.append(msg)
            elif msg.is_error_frame:
                for nq in self.queues:
                    nq.append(msg)
            else:
                dest = route.get((msg.is_extended_id, msg.arbitration_id))
                if dest is None:
                    self.unrouted_frames += 1
                else:
                    dest.append(msg)
        return n

    def _record(self, log: can.Listener, msg: can.Message) -> None:
        try:
            log.on_message_received(msg)
        except (OSError, ValueError, TypeError, struct.error):
            # a full disk or a frame the format cannot hold: the recording has a gap
            # (counted), the reception goes on
            self.log_write_errors += 1

    def counters(self) -> dict[str, int]:
        out = dict(self.reader.counters)
        out["unrouted_frames"] = self.unrouted_frames
        if self.log is not None:
            out["log_write_errors"] = self.log_write_errors
        return out

    @property
    def done(self) -> bool:
        """A replayed log has ended and every frame was handed on."""
        return self.reader.done and not self.reader.queue

    def stop(self) -> None:
        """Stop the reader (the recording is its opener's to close); safe to call twice."""
        self.reader.stop()
