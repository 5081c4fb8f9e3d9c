"""A sensor node on a CAN bus, simulated: raw scans out as frames, paced or in a burst,
with a heartbeat and injected faults.

Pacing uses absolute deadlines (``start + k / rate``), so the sending rate does not
drift however long it runs; ``burst`` sends as fast as the bus takes frames (a full
transmit queue is waited out, never a lost frame).  Faults act on the frames on the
wire, the way a faulty node or harness would: drop, duplicate, hold back
(reorder), corrupt (a frame one byte short) and fall silent for a while.
"""

from __future__ import annotations

import errno
import random
import time
from dataclasses import dataclass

import can
import numpy as np

from ..bus.can.layout import CanLayout, NodeState, NodeStatus


@dataclass(frozen=True)
class Faults:
    drop: float = 0.0  #: probability that a frame is not sent
    duplicate: float = 0.0  #: probability that a frame is sent twice
    reorder: float = 0.0  #: probability that a frame is held back behind the next one
    corrupt: float = 0.0  #: probability that a frame is sent one byte short
    silent_at_s: float | None = None  #: node time at which it falls silent
    silent_for_s: float = 0.0  #: for how long (scans keep counting, nothing is sent)
    seed: int = 0


@dataclass
class NodeStats:
    scans: int = 0
    frames_sent: int = 0
    heartbeats: int = 0
    dropped: int = 0
    duplicated: int = 0
    reordered: int = 0
    corrupted: int = 0
    silent_scans: int = 0
    tx_retries: int = 0
    late_s: float = 0.0  #: worst lateness of a scan behind its deadline (paced mode)
    elapsed_s: float = 0.0


class CanNode:
    """Send raw scans ``(K, taxels)`` as the node would; ``run`` returns the stats."""

    def __init__(self, layout: CanLayout, bus: can.BusABC, raw: np.ndarray, rate_hz: float,
                 heartbeat_s: float = 0.1, faults: Faults = Faults(), burst: bool = False,
                 repeat: int = 1, duration_s: float | None = None, first_seq: int = 0,
                 t0: float | None = None) -> None:
        self.layout = layout
        self.bus = bus
        self.rate_hz = float(rate_hz)
        self.heartbeat_every = max(1, int(round(heartbeat_s * rate_hz)))
        self.faults = faults
        self.burst = burst
        self.repeat = repeat
        self.duration_s = duration_s
        self.first_seq = first_seq
        self.t0 = t0  #: the node clock's start (None: the wall clock's at ``run``)
        self._stamp = 0.0  # the timestamp of the scan being sent: t0 + k / rate
        self.stats = NodeStats()
        self._frames = layout.encode(np.arange(len(raw)), raw)  # packed once; counter patched per scan
        self._rng = random.Random(faults.seed)
        self._held: can.Message | None = None

    def _message(self, can_id: int, data: bytes) -> can.Message:
        lay = self.layout
        # a bus stamps what it sends itself; a log (bus/can/logbus.py) keeps the node's clock
        return can.Message(timestamp=self._stamp, arbitration_id=can_id, data=data, is_extended_id=lay.extended_id,
                           is_fd=lay.fd, bitrate_switch=lay.fd)

    def _send(self, msg: can.Message) -> None:
        """Send, waiting out a full transmit queue (for at most 5 s)."""
        give_up = None
        while True:
            try:
                self.bus.send(msg, timeout=1.0)
                self.stats.frames_sent += 1
                return
            except can.CanOperationError as exc:
                if exc.error_code not in (errno.ENOBUFS, errno.EAGAIN, None):
                    raise
                now = time.monotonic()
                give_up = give_up or now + 5.0
                if now > give_up:
                    raise
                self.stats.tx_retries += 1
                time.sleep(0.0002)

    def _emit(self, msg: can.Message) -> None:
        """One frame through the fault injector."""
        f, rng, st = self.faults, self._rng, self.stats
        if f.drop and rng.random() < f.drop:
            st.dropped += 1
            return
        if f.corrupt and rng.random() < f.corrupt:
            st.corrupted += 1
            msg = self._message(msg.arbitration_id, bytes(msg.data[:-1]))
        if f.reorder and self._held is None and rng.random() < f.reorder:
            st.reordered += 1
            self._held = msg
            return
        self._send(msg)
        if f.duplicate and rng.random() < f.duplicate:
            st.duplicated += 1
            self._send(msg)
        if self._held is not None:
            held, self._held = self._held, None
            self._send(held)

    def _heartbeat(self, seq: int) -> None:
        status = NodeStatus(self.layout.node_id, NodeState.RUNNING, 0, 0, int(round(self.rate_hz)), seq)
        self._send(self._message(self.layout.status_id, self.layout.encode_status(status)))
        self.stats.heartbeats += 1

    def run(self) -> NodeStats:
        lay, st, f = self.layout, self.stats, self.faults
        period = 1.0 / self.rate_hz
        k_total = len(self._frames)
        total = k_total * self.repeat
        if self.duration_s is not None:
            total = int(round(self.duration_s * self.rate_hz))
        silent_lo = silent_hi = -1
        if f.silent_at_s is not None:
            silent_lo = int(round(f.silent_at_s * self.rate_hz))
            silent_hi = silent_lo + int(round(f.silent_for_s * self.rate_hz))
        start = time.monotonic()
        t0 = time.time() if self.t0 is None else self.t0
        for i in range(total):
            seq = self.first_seq + i
            self._stamp = t0 + i * period
            if not self.burst:
                deadline = start + i * period
                delay = deadline - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
                else:
                    st.late_s = max(st.late_s, -delay)
            st.scans += 1
            if silent_lo <= i < silent_hi:
                st.silent_scans += 1
                continue
            for can_id, data in self._frames[i % k_total]:
                data = lay.header(seq, can_id - lay.base_id) + data[2:]
                self._emit(self._message(can_id, data))
            if i % self.heartbeat_every == self.heartbeat_every - 1:
                self._heartbeat(seq)
        if self._held is not None:
            held, self._held = self._held, None
            self._send(held)
        st.elapsed_s = time.monotonic() - start
        return st
