"""CAN logs: read any format python-can reads, replay one in real time as if received,
and decode a node's scans from one through the live path's assembler and pipeline."""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import can

from ...detect.updates import Update, UpdateTable
from ...errors import EskinError, InputFormatError
from ...frames import RawScan
from ...pipeline import Pipeline
from ...preflight import check_readable
from ...schema import in_range
from ..source import DEFAULT_QUEUE_FRAMES, NodeLike, OpenContext
from .layout import ID_RANGE, CanLayout, ScanAssembler, decode_messages
from .reader import FrameThread
from .source import CanSource


class LogPlayer(FrameThread):
    """A CAN log replayed at its own pace into a bounded queue, as if received.

    Frames keep their relative timing; their timestamps are moved to the replay's
    clock (the assembler times scans by them).  A log that fails to parse half-way
    stops the replay; the error is kept in ``last_error``.
    """

    thread_name = "can-log-player"

    def __init__(self, path: str | Path, messages: Iterator[can.Message], queue_frames: int = DEFAULT_QUEUE_FRAMES,
                 speed: float = 1.0) -> None:
        super().__init__(queue_frames, log_frames=0)
        self.path = str(path)
        self._messages = messages
        self.speed = speed

    def _run(self) -> None:
        first_log: float | None = None
        first_wall = 0.0  # set with first_log
        try:
            for msg in self._messages:
                if self._stop.is_set():
                    break
                if first_log is None:
                    first_log, first_wall = msg.timestamp, time.time()
                due = first_wall + (msg.timestamp - first_log) / self.speed
                delay = due - time.time()
                if delay > 0 and self._stop.wait(delay):
                    break
                msg.timestamp = max(due, time.time() - 1.0)
                if len(self.queue) >= self.max_frames:
                    self.counters["rx_queue_drops"] += 1
                    continue
                self.queue.append(msg)
                self.counters["log_frames"] += 1
                self.arrived.set()
        except EskinError as exc:
            self.last_error = str(exc)
            self.counters["bus_errors"] += 1
        finally:
            self.done = True
            self.arrived.set()


def read_can_log(path: str | Path) -> Iterator[can.Message]:
    """Messages of a CAN log in any format python-can reads (``.log``, ``.blf``,
    ``.asc``, ``.trc``, ``.csv``, ...); a file that does not parse is one line."""
    path = Path(path)
    if not path.is_file():
        raise InputFormatError(f"{path}: cannot read CAN log: no such file")
    try:
        reader = can.LogReader(path)
    except (ValueError, OSError) as exc:
        raise InputFormatError(f"{path}: cannot read CAN log: {exc}") from None
    count = 0
    try:
        with reader:
            for msg in reader:
                count += 1
                yield msg
    except (ValueError, IndexError, OSError, can.CanError) as exc:
        raise InputFormatError(f"{path}: message {count + 1}: not a valid log entry: {exc}") from None


def replay(scans: list[RawScan], pipeline: Pipeline) -> list[Update]:
    updates: list[Update] = []
    for scan in scans:
        updates += pipeline.push(scan)
    return updates


def log_scans(profile, path: str | Path, rate_hz: float | None = None) -> tuple[list[RawScan], ScanAssembler]:
    """The node's scans in a CAN log, through the live path's assembler (the FD layout
    when the node's frames are FD frames)."""
    messages = list(read_can_log(path))
    lo = profile.can.base_id
    fd = any(m.is_fd for m in messages[:10_000] if lo <= m.arbitration_id < lo + ID_RANGE)
    layout = CanLayout.from_profile(profile, fd=fd or profile.can.fd)
    return decode_messages(layout, messages, rate_hz or profile.sensor.rate_hz)


def detect_log(profile, path: str | Path, rate_hz: float | None = None, method: str | None = None,
               quiet: bool = True):
    """A CAN log through the live path's assembler and pipeline: the updates as a
    table, and (unless ``quiet``) the counters on stderr."""
    rate = rate_hz or profile.sensor.rate_hz
    scans, asm = log_scans(profile, path, rate)
    pipeline = Pipeline(profile, rate_hz=rate, method=method)
    table = UpdateTable.from_updates(replay(scans, pipeline))
    if not quiet:
        c = pipeline.counters
        summary = {k: v for k, v in vars(c).items() if k != "extra"} | asm.counters
        print(f"{path}: " + json.dumps(summary), file=sys.stderr)
    return table


@dataclass(frozen=True)
class CanLogOptions:
    """``[[node]]`` keys of ``source = "can-log"``: a candump/asc/blf/... log replayed
    at its own pace, once."""

    path: str
    fd: bool | None = None
    base_id: int | None = field(default=None, metadata=in_range(0, 0x1FFFFFFF))
    node_id: int | None = field(default=None, metadata=in_range(0, 255))


class CanLogSource(CanSource):
    """A node's scans from a CAN log replayed in real time (several nodes of one log
    share its player)."""

    kind = "can-log"
    spec = "log:FILE"
    Options = CanLogOptions
    profile_keys = {"fd": "can.fd", "base_id": "can.base_id", "node_id": "can.node_id"}

    @classmethod
    def options_from_spec(cls, where: str, bus: dict[str, Any]) -> dict[str, Any]:
        if not where:
            raise ValueError("expected log:FILE")
        return {"path": where, **({"fd": bus["fd"]} if bus.get("fd") is not None else {})}

    @classmethod
    def describe(cls, node: NodeLike) -> str:
        return f"log {node.options.path}"

    @classmethod
    def check(cls, node: NodeLike, base_dir: str) -> None:
        check_readable(node.options.path, "path")
        cls.check_layout(node)

    @classmethod
    def share_key(cls, node: NodeLike) -> tuple:
        return ("can-log", node.options.path)

    @classmethod
    def _reader(cls, node: NodeLike, context: OpenContext) -> FrameThread:
        path = node.options.path
        return LogPlayer(path, read_can_log(path), context.queue_frames)

    def describe_where(self) -> str:
        return f"log {getattr(self.reader, 'path', '?')}"
