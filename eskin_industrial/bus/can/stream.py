"""Is this frame stream one node's?  The judgement behind FLAGS ``STREAM``.

Pure code, no I/O: :class:`~.layout.ScanAssembler` reports what it sees in the
node's frames and asks, at each scan it delivers, whether the stream is one
sensor's.  On one CAN bus a node's frames arrive in the order it sent them; what
breaks that order is a second sender on the node's IDs (a twin node, a replaced
one left powered, a replay), and its frames are well formed: each alone passes.
Only the stream shows it:

- two counter sequences at once: a frame of an older scan whose counter the
  stream never started (a counter the jump before it skipped), or a counter that
  runs ahead of the receipt clock (a jump of many scans in a fraction of their
  time): the fault is raised at once;
- a heartbeat naming another node number: at once, and until one names ours;
- a sustained rate of frames out of order (late), of repeated segments or scans,
  and of torn scans: :data:`SUSTAINED_EVENTS` of them within the frames of
  :data:`SUSTAINED_SCANS` scans (a lost frame now and then tears one scan and is
  no fault).

The fault holds until the stream has been clean (no event of any kind) for
:data:`CLEAN_S` seconds of the node's scans: a twin that keeps sending keeps it.
"""

from __future__ import annotations

import collections
import math

from ...frames import FrameFlag

_STREAM = int(FrameFlag.STREAM)
#: Events (late, repeated, torn) within the frames of SUSTAINED_SCANS scans that make a fault.
SUSTAINED_EVENTS = 8
SUSTAINED_SCANS = 32
#: Seconds of the node's scans with no event before the fault clears.
CLEAN_S = 2.0
#: A counter this far ahead of the receipt clock (at least two scan periods) is a
#: second sequence, not a loss: after a loss the clock has run as long as the counter.
AHEAD_S = 0.02


class StreamWatch:
    """The ``STREAM`` bit of one node's frames, fed by its assembler."""

    def __init__(self, rate_hz: float, segments: int, counters: dict[str, int]) -> None:
        self.rate_hz = rate_hz
        self._counters = counters  # the assembler's: ``stream_faults`` counts the entries
        self._window = SUSTAINED_SCANS * (segments + 1)  # in the node's frames (a heartbeat now and then)
        self._events: collections.deque[int] = collections.deque(maxlen=SUSTAINED_EVENTS)
        self._clean_scans = max(1, math.ceil(CLEAN_S * rate_hz))
        self._ahead_s = max(AHEAD_S, 2.0 / rate_hz)
        self._clean = 0  # scans delivered since the last event
        self._wrong_node = False
        self.fault = 0  #: FrameFlag.STREAM while the fault holds, else 0
        self.reason = ""  #: what raised the fault last (for the log)

    def event(self, frame: int, what: str) -> None:
        """A late, repeated or torn frame of the node (``frame``: the node's frame count)."""
        self._clean = 0
        ev = self._events
        ev.append(frame)
        if len(ev) == SUSTAINED_EVENTS and frame - ev[0] <= self._window:
            self.trip(f"{SUSTAINED_EVENTS} frames out of order, repeated or torn within {frame - ev[0] + 1} "
                      f"frames (the last: {what})")

    def trip(self, why: str) -> None:
        """A second sequence or another node: the fault, at once."""
        self._clean = 0
        if not self.fault:
            self._counters["stream_faults"] += 1
            self.fault = _STREAM
            self.reason = why

    def counter_ahead(self, d: int, elapsed_s: float) -> None:
        """A scan whose counter moved ``d`` on from the last one, ``elapsed_s`` later."""
        if d > 1 and math.isfinite(elapsed_s) and (d - 1) / self.rate_hz - elapsed_s > self._ahead_s:
            self.trip(f"the scan counter ran {d} scans on in {1000 * max(elapsed_s, 0.0):.1f} ms")

    def heartbeat(self, node_id: int, expected: int) -> None:
        self._wrong_node = node_id != expected
        if self._wrong_node:
            self.trip(f"a heartbeat names node {node_id}, the profile node {expected}")

    def scan(self) -> int:
        """A scan delivered: its ``STREAM`` bit."""
        if self.fault:
            self._clean += 1
            if self._clean >= self._clean_scans and not self._wrong_node:
                self.fault = 0
        return self.fault
