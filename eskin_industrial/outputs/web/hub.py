"""What the node's loop leaves for the console: the newest values of each node, and a
wake-up for the server's loop.

The loop's side (:meth:`NodeFeed.publish`, :meth:`NodeFeed.update`,
:meth:`NodeFeed.frame`) is O(1) and tiny a scan: it stores a reference to the newest
snapshot, frame and update (no copy, no encoding, no lock: one reference replaced is
atomic), appends the frame to the capture ring (a bounded deque, thread-safe), and
only at a state change takes the lock for the lane and the episodes and wakes the
server (an urgent snapshot wakes it too).  Everything else is the server's, once a
display frame for every viewer together (:meth:`NodeFeed.tick`, the server's ticker):
the trend point, the scan rate, the captures frozen, the snapshot's JSON and the
frame's float32 bytes (:mod:`.wire`), each made once and shared by every message.
"""

from __future__ import annotations

import collections
import json
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ...detect.state import LABELS, GraspState
from .wire import frame_bytes

if TYPE_CHECKING:
    from ...detect.updates import Update
    from ...frames import Frame
    from ...node import Command, NodeSnapshot

#: The trends' span: a point a display frame (the newest update then), and every state change.
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

    def __post_init__(self) -> None:
        # the loop's side: references replaced, counters bumped (by that thread only)
        self.snapshot: NodeSnapshot | None = None
        self.snap_seq = 0
        self.newest_frame: Frame | None = None
        self.frame_seq = 0
        self.newest_update: Update | None = None
        self.changed_update: Update | None = None  #: the newest update that changed the state
        # the server's side: one point a display frame (and one a state change) over 30 s
        points = int(math.ceil(TREND_S / max(self.frame_interval_s, 0.005))) + LANE_MAX
        self.trend: collections.deque[tuple[int, float, float | None, float | None, float | None, float | None]] = \
            collections.deque(maxlen=points)
        self.trend_seq = 0
        self._trended: tuple[Update | None, Update | None] = (None, None)
        self.lane: collections.deque[tuple[int, float, float, str, bool]] = collections.deque(maxlen=LANE_MAX)
        self.lane_seq = 0
        self.episodes: collections.deque[Episode] = collections.deque(maxlen=EPISODES_MAX)
        self.episodes_seq = 0  #: bumped (under the lock) at an episode listed, a capture frozen or let go
        self.pending: list[Episode] = []
        window_s = self.capture_pre_s + self.capture_post_s
        # the ring holds the window and some margin (the server freezes a capture one turn late)
        self.ring: collections.deque[tuple[float, np.ndarray]] | None = (
            collections.deque(maxlen=int(math.ceil((window_s + 1.0) * self.rate_hz)) + 8) if window_s > 0 else None)
        self.commands: collections.deque[Command] = collections.deque()
        self._last_state: int | None = None
        self._episode_ids = 0
        self.scans_per_s: float | None = None
        self._rate_mark: tuple[float, int] | None = None
        self._snap_text: tuple[int, str] = (-1, "")
        self._frame_blob: tuple[int, str, bytes] = (-1, "", b"")
        self.counts = {"web_frames_dropped": 0}

    @property
    def frame_t(self) -> float | None:
        frame = self.newest_frame
        return None if frame is None else frame.t

    # -- the loop's thread -----------------------------------------------------------
    def publish(self, snapshot: NodeSnapshot) -> None:
        self.snapshot = snapshot
        self.snap_seq += 1
        if snapshot.urgent:
            self.kick()

    def update(self, u: Update) -> None:
        self.newest_update = u
        state = u.state
        if state == self._last_state:
            return
        self._last_state = state
        self.changed_update = u
        wall = time.time()
        with self.lock:
            self.lane_seq += 1
            self.lane.append((self.lane_seq, u.t, wall, LABELS[state], bool(u.valid)))
            if state in _EPISODE_STATES:
                label = LABELS[state]
                self._episode_ids += 1
                delay = self.truth.delay(u.t, label) if self.truth is not None else None
                ep = Episode(self._episode_ids, self.index, label, u.t, wall, delay)
                self.episodes.append(ep)
                self.episodes_seq += 1
                if self.ring is not None:
                    ep.waiting = True
                    self.pending.append(ep)
        self.kick()

    def frame(self, frame: Frame) -> None:
        # no copy: the calibration makes a new forces array for every scan, none is
        # changed once handed on (bridge/supervise.py)
        if self.ring is not None:
            self.ring.append((frame.t, frame.forces))
        self.newest_frame = frame
        self.frame_seq += 1

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

    def tick(self, now: float) -> None:
        """Once a display frame: the trend's point (the state change's too, when one came
        since), the scan rate, the captures whose window has passed."""
        u, changed = self.newest_update, self.changed_update
        last_u, last_changed = self._trended
        if changed is not None and changed is not last_changed and changed is not u:
            self._trend(changed)
        if u is not None and u is not last_u:
            self._trend(u)
        self._trended = (u, changed)
        snap = self.snapshot
        if snap is not None:
            mark = self._rate_mark
            if mark is None:
                self._rate_mark = (now, snap.scans)
            elif now - mark[0] >= 1.0:
                self.scans_per_s = (snap.scans - mark[1]) / (now - mark[0])
                self._rate_mark = (now, snap.scans)
        self.freeze_captures()

    def _trend(self, u: Update) -> None:
        self.trend_seq += 1
        self.trend.append((self.trend_seq, u.t, num(u.r_coe), num(u.r_dw), num(u.score_a), num(u.score_b)))

    def snapshot_text(self) -> tuple[int, str]:
        """The newest snapshot as the message's JSON (``{"i", "snap", "rate_hz"}``), made
        once for every viewer; with its seq."""
        seq = self.snap_seq
        cached = self._snap_text
        if cached[0] != seq:
            body = {"i": self.index, "snap": snapshot_json(self.snapshot), "rate_hz": num(self.scans_per_s)}
            cached = self._snap_text = (seq, json.dumps(body, allow_nan=False, separators=(",", ":")))
        return cached

    def frame_blob(self) -> tuple[int, str, bytes]:
        """The newest frame as the message's ``"frame"`` JSON and its float32 tail, made
        once for every viewer; with its seq (0: no frame yet)."""
        seq, frame = self.frame_seq, self.newest_frame
        cached = self._frame_blob
        if cached[0] != seq and frame is not None:
            forces = frame.forces
            head = json.dumps({"node": self.index, "t": num(frame.t), "n": int(forces.size)}, separators=(",", ":"))
            cached = self._frame_blob = (seq, head, frame_bytes(forces))
        return cached if frame is not None else (0, "", b"")

    def freeze_captures(self) -> bool:
        """Freeze the captures whose post-trigger window has passed; True when one did."""
        newest = self.frame_t
        with self.lock:
            if not self.pending or self.ring is None or newest is None:
                return False
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
            self.episodes_seq += 1
        return True


def snapshot_json(snap: Any) -> dict[str, Any] | None:
    if snap is None:
        return None
    d = snap._asdict()
    out: dict[str, Any] = {}
    for k, v in d.items():
        if isinstance(v, float):
            out[k] = v if math.isfinite(v) else None
        elif isinstance(v, tuple):
            out[k] = list(v)
        else:
            out[k] = v
    out["state_label"] = snap.state_label
    out["sensor_fault"] = snap.sensor_fault
    out["turn_unseen"] = snap.turn_unseen
    out["contact"] = snap.contact
    return out
