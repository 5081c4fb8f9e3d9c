"""The live view on a running chain: what the data path leaves, and the snapshots
the redraw thread builds from it.

The data path does nothing for the view but what it already does (the pipeline keeps
its newest frame and update; the loop its newest snapshot; the bridge its counters)
plus one ``deque.append`` per state change.  :meth:`Watch.snapshot` runs on the redraw thread and only reads:
attribute reads and list copies, atomic under the interpreter lock.
"""

from __future__ import annotations

import collections
import time
from collections.abc import Callable, Mapping, Sequence
from typing import TextIO

import numpy as np

from ..detect.state import GraspState
from ..detect.updates import Update
from ..node import NodeSnapshot
from ..pipeline import Pipeline
from ..profile import Profile
from .screen import render
from .snapshot import RegisterTable, Snapshot, indicator_scale
from .terminal import DEFAULT_FPS, LiveScreen

#: Counters the view shows, in this order, under these names.
COUNTER_LABELS: tuple[tuple[str, str], ...] = (
    ("scans", "scans"), ("lost_scans", "lost"), ("torn_scans", "torn"), ("malformed_frames", "malformed"),
    ("late_frames", "late"), ("duplicate_frames", "dup"), ("rx_queue_drops", "drops"),
    ("bus_errors", "bus errors"), ("heartbeats", "heartbeats"), ("state_changes", "changes"),
    ("publications", "publications"), ("plc_writes", "PLC writes"), ("plc_write_failures", "PLC failures"),
)


def short_counters(counters: Mapping[str, int]) -> dict[str, int]:
    return {label: int(counters[key]) for key, label in COUNTER_LABELS if key in counters}


def change_line(u: Update) -> str:
    """One state change, as ``monitor --plain`` prints it."""
    return (f"{u.t:8.2f} s  {GraspState(u.state).label:15s} valid={int(u.valid)}  "
            f"F={u.f_sum:6.2f} N  scores {u.score_a:6.2f} {u.score_b:6.2f}  R_coe {u.r_coe:6.2f} R_dw {u.r_dw:6.2f}")


class Watch:
    """Newest values of one chain -> :class:`Snapshot` (on the redraw thread)."""

    #: Scan rate measured over at least this long.
    RATE_WINDOW_S = 1.0

    def __init__(self, profile: Profile, pipeline: Pipeline, *, method: str,
                 snapshot: Callable[[], NodeSnapshot | None], counters: Callable[[], Mapping[str, int]],
                 source: str, title: str, started: float, log_lines: int = 100,
                 registers: Callable[[], RegisterTable | None] | None = None, registers_from: str = "",
                 extra: Callable[[], Sequence[str]] | None = None) -> None:
        """``snapshot``: the node's newest published snapshot; ``registers``, when
        given: a register table to show beside it (the PLC's, decoded by the caller);
        ``extra``: lines shown under the state (read on the redraw thread)."""
        self.profile = profile
        self.pipeline = pipeline
        self.scale = indicator_scale(method, profile.detector, pipeline.detector)
        self.newest = snapshot
        self.registers = registers
        self.registers_from = registers_from
        self.extra = extra
        self.counters = counters
        self.source = source
        self.title = title
        self.started = started
        self.log: collections.deque[str] = collections.deque(maxlen=log_lines)
        self._rate_mark: tuple[float, int] | None = None
        self._rate: float | None = None

    def note(self, line: str) -> None:
        """A state-change line for the log area (data path: one append)."""
        self.log.append(line)

    def snapshot(self, now: float) -> Snapshot:
        lay = self.profile.layout
        frame = self.pipeline.last_frame
        u = self.pipeline.last_update
        forces = None if frame is None else np.array(frame.forces, dtype=np.float64).reshape(lay.rows, lay.cols)
        published = self.newest()
        table = self.registers() if self.registers is not None else None
        counters = dict(self.counters())
        scans = int(counters.get("scans", 0))
        if self._rate_mark is None:
            self._rate_mark = (now, scans)
        elif now - self._rate_mark[0] >= self.RATE_WINDOW_S:
            self._rate = (scans - self._rate_mark[1]) / (now - self._rate_mark[0])
            self._rate_mark = (now, scans)
        return Snapshot(
            forces=forces,
            row_names=lay.row_names,
            # the gauges show the deciding method's scores against its thresholds
            r_coe=None if u is None else u.score_a,
            r_dw=None if u is None else u.score_b,
            scale=self.scale,
            state=None if u is None else GraspState(u.state).label,
            valid=False if u is None else bool(u.valid),
            stale=frame is None or (published is not None and published.stale),
            f_sum=None if u is None else u.f_sum,
            cof=None if u is None else (u.xc, u.yc),
            registers=None if table is None else table.values,
            status_bits=() if table is None else table.bits,
            registers_from=self.registers_from,
            counters=short_counters(counters),
            elapsed_s=now - self.started,
            scan_rate_hz=self._rate,
            source=self.source,
            title=self.title,
            log=tuple(self.log),
            extra=tuple(self.extra()) if self.extra is not None else (),
        )

    def frame(self, now: float, width: int, height: int, color: bool) -> list[str]:
        return render(self.snapshot(now), width, height, color)


def live_screen(watch: Watch, stream: TextIO, color: bool, fps: float = DEFAULT_FPS) -> LiveScreen:
    """The terminal driver drawing ``watch`` (the clock is read here, on the redraw
    thread, never in the renderer)."""
    return LiveScreen(lambda width, height: watch.frame(time.monotonic(), width, height, color), stream, fps)
