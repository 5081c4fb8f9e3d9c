"""What the node's loop leaves for the console: the newest values of each node, kept
under a lock in bounded structures, and a wake-up for the server's loop.

The loop's side (:meth:`NodeFeed.publish`, :meth:`NodeFeed.update`,
:meth:`NodeFeed.frame`) stores and returns: a snapshot, a frame or a trend point
replaces the one before, the state lane and the episodes are bounded rings, the raw
scans a ring of the capture window.  It wakes the server's loop (thread-safely, at
most once per frame interval unless the snapshot is urgent) and never waits for it.
The server's side reads under the same lock and copies what it sends.
"""

from __future__ import annotations

import collections
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ...detect.state import LABELS, GraspState

if TYPE_CHECKING:
    from ...detect.updates import Update
    from ...frames import Frame
    from ...node import Command, NodeSnapshot

#: Trend points a second at most (the newest update of each 20 ms is kept), over 30 s.
TREND_HZ = 50.0
TREND_S = 30.0
LANE_MAX = 256  #: state changes kept for the lane
EPISODES_MAX = 64  #: episodes listed
CAPTURES_MAX = 16  #: episodes whose raw scans are kept (the oldest capture is let go)
COMMANDS_MAX = 16  #: commands queued for the loop
_EPISODE_STATES = (int(GraspState.SLIP), int(GraspState.VARIABLE_FORCE))
_TRUTH_WINDOW_S = 3.0  #: a truth onset this long before a detection is the one it detects


def num(x: float | None) -> float | None:
    """A JSON number (NaN and infinities as null)."""
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


@dataclass
class Episode:
    """One slip or varying-force episode: when it was decided, and its raw scans."""

    id: int
    node: int
    state: str
    t: float  #: sensor clock (s)
    wall_time_s: float
    delay_s: float | None  #: since the scene's own onset (None: no truth)
    rows: np.ndarray | None = None  #: (K, 1 + taxels): t, forces (N); None until the window is over
    waiting: bool = False  #: its window is not over yet (no rows, and none let go)

    def summary(self) -> dict[str, Any]:
        return {"id": self.id, "node": self.node, "state": self.state, "t": self.t, "wall": self.wall_time_s,
                "delay_s": num(self.delay_s), "capture": self.rows is not None, "waiting": self.waiting,
                "scans": 0 if self.rows is None else int(self.rows.shape[0])}


@dataclass
class Truth:
    """A scene's own onsets: (time, label) in its first lap, repeated every ``period_s``."""

    onsets: list[tuple[float, str]]
    period_s: float | None = None

    def delay(self, t: float, label: str) -> float | None:
        best: float | None = None
        for onset, what in self.onsets:
            if what != label:
                continue
            lap = math.floor((t - onset) / self.period_s) if self.period_s else 0
            start = onset + max(lap, 0) * (self.period_s or 0.0)
            if 0 <= t - start <= _TRUTH_WINDOW_S and (best is None or t - start < best):
                best = t - start
        return best


@dataclass
class NodeFeed:
    """One node's newest values, shared by its loop's thread and the server's."""

    index: int
    rate_hz: float
    capture_pre_s: float
    capture_post_s: float
    frame_interval_s: float
    kick: Callable[[], None] = lambda: None
    truth: Truth | None = None
    lock: threading.Lock = field(default_factory=threading.Lock)
    seq: int = 0  #: bumped at every change a client may not have yet

    def __post_init__(self) -> None:
        self.snapshot: NodeSnapshot | None = None
        self.snap_seq = 0
        self.frame_t: float | None = None
        self.frame_forces: np.ndarray | None = None
        self.frame_seq = 0
        points = int(TREND_HZ * TREND_S) + 16
        self.trend: collections.deque[tuple[int, float, float | None, float | None, float | None, float | None]] = \
            collections.deque(maxlen=points)
        self.trend_seq = 0
        self.lane: collections.deque[tuple[int, float, float, str, bool]] = collections.deque(maxlen=LANE_MAX)
        self.lane_seq = 0
        self.episodes: collections.deque[Episode] = collections.deque(maxlen=EPISODES_MAX)
        self.pending: list[Episode] = []
        window_s = self.capture_pre_s + self.capture_post_s
        # the ring holds the window and some margin (the server freezes a capture one turn late)
        self.ring: collections.deque[tuple[float, np.ndarray]] | None = (
            collections.deque(maxlen=int(math.ceil((window_s + 1.0) * self.rate_hz)) + 8) if window_s > 0 else None)
        self.commands: collections.deque[Command] = collections.deque()
        self._last_state: int | None = None
        self._last_trend_t = -math.inf
        self._last_kick = -math.inf
        self._episode_ids = 0
        self.scans_per_s: float | None = None
        self._rate_mark: tuple[float, int] | None = None
        self.counts = {"web_frames_dropped": 0}

    # -- the loop's thread -----------------------------------------------------------
    def publish(self, snapshot: NodeSnapshot) -> None:
        now = time.monotonic()
        with self.lock:
            self.snapshot = snapshot
            self.snap_seq += 1
            mark = self._rate_mark
            if mark is None:
                self._rate_mark = (now, snapshot.scans)
            elif now - mark[0] >= 1.0:
                self.scans_per_s = (snapshot.scans - mark[1]) / (now - mark[0])
                self._rate_mark = (now, snapshot.scans)
        self._wake(now, snapshot.urgent)

    def update(self, u: Update) -> None:
        state = u.state
        changed = state != self._last_state
        self._last_state = state
        with self.lock:
            if changed or u.t - self._last_trend_t >= 1.0 / TREND_HZ:
                self._last_trend_t = u.t
                self.trend_seq += 1
                self.trend.append((self.trend_seq, u.t, num(u.r_coe), num(u.r_dw), num(u.score_a), num(u.score_b)))
            if not changed:
                return
            wall = time.time()
            self.lane_seq += 1
            self.lane.append((self.lane_seq, u.t, wall, LABELS[state], bool(u.valid)))
            if state in _EPISODE_STATES:
                label = LABELS[state]
                self._episode_ids += 1
                delay = self.truth.delay(u.t, label) if self.truth is not None else None
                ep = Episode(self._episode_ids, self.index, label, u.t, wall, delay)
                self.episodes.append(ep)
                if self.ring is not None:
                    ep.waiting = True
                    self.pending.append(ep)
        self._wake(time.monotonic(), True)

    def frame(self, frame: Frame) -> None:
        forces = frame.forces.astype(np.float32)  # a copy: the frame's arrays are the detector's
        t = frame.t
        with self.lock:
            if self.ring is not None:
                self.ring.append((t, forces))
            self.frame_t = t
            self.frame_forces = forces
            self.frame_seq += 1
        self._wake(time.monotonic(), False)

    def _wake(self, now: float, urgent: bool) -> None:
        if urgent or now - self._last_kick >= self.frame_interval_s:
            self._last_kick = now
            self.kick()

    def take_commands(self) -> list[Command]:
        out = []
        with self.lock:
            while self.commands:
                out.append(self.commands.popleft())
        return out

    # -- the server's thread ---------------------------------------------------------
    def queue_command(self, command: Command) -> bool:
        with self.lock:
            if len(self.commands) >= COMMANDS_MAX:
                return False
            self.commands.append(command)
            return True

    def freeze_captures(self) -> bool:
        """Freeze the captures whose post-trigger window has passed; True when one did."""
        with self.lock:
            if not self.pending or self.ring is None or self.frame_t is None:
                return False
            newest = self.frame_t
            due = [ep for ep in self.pending if newest >= ep.t + self.capture_post_s]
            if not due:
                return False
            scans = list(self.ring)
        for ep in due:
            lo, hi = ep.t - self.capture_pre_s, ep.t + self.capture_post_s
            picked = [(t, f) for t, f in scans if lo <= t <= hi]
            if picked:
                rows = np.empty((len(picked), 1 + picked[0][1].size), dtype=np.float64)
                rows[:, 0] = [t for t, _ in picked]
                rows[:, 1:] = np.stack([f for _, f in picked])
            else:
                rows = np.empty((0, 1), dtype=np.float64)
            ep.rows = rows
            ep.waiting = False
        with self.lock:
            self.pending = [ep for ep in self.pending if ep not in due]
            kept = [ep for ep in self.episodes if ep.rows is not None]
            for old in kept[:-CAPTURES_MAX]:
                old.rows = None  # the oldest captures let go: memory stays bounded
        return True
