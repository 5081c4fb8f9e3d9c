"""CAN logs: read any format python-can reads, replay one in real time as if received
(the can-log source), and a node's scans from a whole log or a live candump stream
through the live path's assembler, with its counters and the log's checks.

Reading only: what is detected from the scans is the offline path's business
(``eskin_industrial.offline``), which hands them to the pipeline."""

from __future__ import annotations

import logging
import math
import os
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import can

from ...errors import EskinError, InputFormatError
from ...frames import RawScan
from ...preflight import check_readable
from ...profile import Profile
from ...progress import NO_PROGRESS, Progress
from ...schema import in_range
from ...seam import DEFAULT_QUEUE_FRAMES, NodeLike, OpenContext
from .layout import ID_RANGE, CanLayout, ScanAssembler, decode_messages
from .logcheck import MISMATCH_FLOOR, READ_ERRORS, check_complete, layout_mismatch
from .reader import FrameThread
from .source import CanSource

LOG = logging.getLogger(__name__)
#: A log's clock going back by more than this (or on by more than CLOCK_JUMP_ON_S) is
#: a clock that was set, not time that passed: the replay logs it once and paces on
#: from the new clock.  (Frames a few milliseconds out of order, as a multi-channel
#: log interleaves them, are no jump; a silence on the bus, however long up to
#: CLOCK_JUMP_ON_S, is replayed as one: the assembler counts counter wraps by it.)
CLOCK_JUMP_BACK_S = 0.5
CLOCK_JUMP_ON_S = 3600.0


class LogPlayer(FrameThread):
    """A CAN log replayed at its own pace into a bounded queue, as if received.

    Frames keep their relative timing; their timestamps are moved to the replay's
    clock (the assembler times scans by them).  A jump of the log's clock (back by
    more than :data:`CLOCK_JUMP_BACK_S`, on by more than :data:`CLOCK_JUMP_ON_S`) is
    logged once (``can_log_clock_jump``), counted (``log_clock_jumps``) and paced
    across from the new clock, as a live bus's frames would be; a frame whose time
    is not a number or infinite is dropped and counted (``log_bad_times``, logged at
    its first).  A log that fails to parse half-way stops the replay; the error is
    kept in ``last_error`` and counted in ``bus_errors`` (the node's source then
    reports ``failed``).
    """

    thread_name = "can-log-player"

    def __init__(self, path: str | Path, messages: Iterator[can.Message], queue_frames: int = DEFAULT_QUEUE_FRAMES,
                 speed: float = 1.0) -> None:
        super().__init__(queue_frames, log_frames=0, log_clock_jumps=0, log_bad_times=0)
        self.path = str(path)
        self._messages = messages
        self.speed = speed

    def _run(self) -> None:
        first_log: float | None = None
        first_wall = 0.0  # set with first_log
        last_log, last_due = 0.0, 0.0  # the log time and replay time of the frame before
        counters = self.counters
        try:
            for k, msg in enumerate(self._messages, 1):
                if self._stop.is_set():
                    break
                ts = msg.timestamp
                if not math.isfinite(ts):  # no time to pace by (nor to hand the assembler)
                    counters["log_bad_times"] += 1
                    if counters["log_bad_times"] == 1:
                        LOG.warning("can_log_bad_time", extra={"fields": {
                            "log": self.path, "message": k, "timestamp": str(ts), "action": "dropped"}})
                    continue
                if first_log is None:
                    first_log, first_wall = ts, time.time()
                elif not -CLOCK_JUMP_BACK_S <= ts - last_log <= CLOCK_JUMP_ON_S:
                    counters["log_clock_jumps"] += 1
                    LOG.warning("can_log_clock_jump", extra={"fields": {
                        "log": self.path, "message": k, "jump_s": round(ts - last_log, 6), "from": last_log, "to": ts}})
                    first_log, first_wall = ts, last_due  # on from the new clock, where the replay was
                due = first_wall + (ts - first_log) / self.speed
                last_log, last_due = ts, due
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
        except Exception as exc:  # noqa: BLE001 - whatever a reader raises ends the replay as a failure, never a traceback
            self.last_error = f"{self.path}: {type(exc).__name__}: {exc}"
            self.counters["bus_errors"] += 1
        finally:
            self.done = True
            self.arrived.set()


def read_can_log(path: str | Path, progress: Progress = NO_PROGRESS) -> Iterator[can.Message]:
    """Messages of a CAN log in any format python-can reads (``.log``, ``.blf``,
    ``.asc``, ``.trc``, ``.csv``, ...); a file that does not parse, or was cut short,
    is one :class:`InputFormatError` line naming the message and, where the format
    has one, the byte.  ``progress``: a stage over the file's bytes."""
    path = Path(path)
    if not path.is_file():
        raise InputFormatError(f"{path}: cannot read CAN log: no such file")
    try:
        check_complete(path)  # python-can's readers stop silently at a cut record
        reader = can.LogReader(path)
    except InputFormatError:
        raise
    except READ_ERRORS as exc:
        raise InputFormatError(f"{path}: cannot read CAN log: {_detail(exc)}") from None
    count = 0
    where = _position(reader) if progress is not NO_PROGRESS else None  # (a replay into the bridge: nobody watches)
    size = path.stat().st_size if where is not None else 0
    progress.stage(f"reading {path}", size, percent=True)
    done = 0
    with reader:
        try:
            for msg in reader:
                count += 1
                if where is not None and count % _PROGRESS_EVERY == 0:
                    at = where()
                    progress.advance(at - done)
                    done = at
                yield msg
            progress.advance(size - done)  # (read to the end; the reader has closed the file)
        except READ_ERRORS as exc:  # (the position is read while the file is still open)
            raise InputFormatError(f"{path}: message {count + 1}{_at_byte(reader)}: not a valid log entry: "
                                   f"{_detail(exc)}") from None


#: Messages between two looks at how far a log has been read.
_PROGRESS_EVERY = 4096


def _position(reader: object) -> Callable[[], int] | None:
    """How many bytes of the file a reader has read so far, if it reads a file: the
    descriptor's offset, which counts what was read from disk whatever the format,
    buffering or compression above it (asked only while the reader is still reading)."""
    try:
        fd = reader.file.fileno()  # type: ignore[attr-defined]  # (an AttributeError is the answer "no file")
        os.lseek(fd, 0, os.SEEK_CUR)
    except (AttributeError, OSError, ValueError):  # (io.UnsupportedOperation is both)
        return None
    return lambda: os.lseek(fd, 0, os.SEEK_CUR)


def _detail(exc: BaseException) -> str:
    kind = type(exc).__name__
    if kind == "error":  # zlib.error, struct.error: the module says what it is
        kind = f"{type(exc).__module__}.error"
    text = str(exc).splitlines()[0] if str(exc) else ""
    return f"{kind}: {text}" if text else kind


def _at_byte(reader: object) -> str:
    """", near byte N" for a binary log (a text reader cannot tell while it iterates)."""
    f = getattr(reader, "file", None)
    try:
        return f", near byte {f.tell()}" if f is not None and "b" in getattr(f, "mode", "") else ""
    except (OSError, ValueError):
        return ""


def log_scans(profile: Profile, path: str | Path, rate_hz: float | None = None,
              progress: Progress = NO_PROGRESS) -> tuple[list[RawScan], dict[str, int]]:
    """The node's complete scans in a CAN log, through the live path's assembler (the
    FD layout when the node's frames are FD frames), and the assembler's counters; a
    log of another layout on the node's IDs is refused in one line (never scans read
    with the wrong layout).  ``progress``: a stage over the file's bytes."""
    messages = list(read_can_log(path, progress))
    lo = profile.can.base_id
    fd = any(m.is_fd for m in messages[:10_000] if lo <= m.arbitration_id < lo + ID_RANGE)
    layout = CanLayout.from_profile(profile, fd=fd or profile.can.fd)
    scans, asm = decode_messages(layout, messages, rate_hz or profile.sensor.rate_hz)
    mismatch = layout_mismatch(asm.counters, _ids(profile))
    if mismatch is not None:
        raise InputFormatError(f"{path}: {mismatch}")
    return scans, asm.counters


#: How often a live log's layout is checked (messages): early enough to refuse a log
#: of another layout before many "scans", rarely enough to cost nothing per frame.
_CHECK_EVERY = 256


class LiveLogScans:
    """The node's scans in a candump-format log (``candump -L``: ``(time) iface
    ID#DATA``) read as it comes, each yielded as soon as it is complete: the same
    assembler and layout checks as :func:`log_scans`.  Iterate once; then
    :meth:`counters`.  What the consumer of a scan raises (a closed pipe downstream)
    passes through untouched: only the reading is the log's fault."""

    def __init__(self, profile: Profile, stream: TextIO, rate_hz: float | None = None,
                 name: str = "<stdin>") -> None:
        self.profile, self.name = profile, name
        self.rate_hz = rate_hz or profile.sensor.rate_hz
        self._stream = stream
        self._asm: ScanAssembler | None = None
        self._before = 0  # frames of other IDs before the node's first (the assembler counts the rest)

    def __iter__(self) -> Iterator[RawScan]:
        profile, name = self.profile, self.name
        lo = profile.can.base_id
        count = 0
        messages = iter(can.io.CanutilsLogReader(self._stream))
        while True:
            try:
                msg = next(messages, None)
            except READ_ERRORS as exc:
                raise InputFormatError(f"{name}: message {count + 1}: not a valid candump -L line: "
                                       f"{_detail(exc)}") from None
            if msg is None:
                break
            count += 1
            if self._asm is None:
                if not lo <= msg.arbitration_id < lo + ID_RANGE:
                    self._before += 1
                    continue
                # the node's first frame tells classic from FD, as a whole log's first frames do
                self._asm = ScanAssembler(CanLayout.from_profile(profile, fd=msg.is_fd or profile.can.fd),
                                          self.rate_hz)
            scan = self._asm.feed(msg)
            if scan is not None:
                yield scan
            if count % _CHECK_EVERY == 0:
                self._check(self._asm)
        if self._asm is not None:
            self._asm.flush()
            self._check(self._asm)

    def _check(self, asm: ScanAssembler) -> None:
        mismatch = layout_mismatch(asm.counters, _ids(self.profile))
        if mismatch is not None:
            raise InputFormatError(f"{self.name}: {mismatch}")

    def counters(self) -> dict[str, int]:
        """The assembler's counters, the frames of other IDs before the node's first
        among ``foreign_frames`` (all zero but those when the node never spoke)."""
        if self._asm is None:
            return {**ScanAssembler(CanLayout.from_profile(self.profile), self.rate_hz).counters,
                    "foreign_frames": self._before}
        counters = dict(self._asm.counters)
        counters["foreign_frames"] += self._before
        return counters


def require_scans(profile: Profile, counters: dict[str, int], name: str) -> None:
    """A log with no complete scan of the node is refused in one line (another node's
    log, a wrong base_id): never an empty output that looks like a quiet sensor."""
    if counters["scans"] == 0:
        lo = profile.can.base_id
        raise InputFormatError(
            f"{name}: no complete scan of profile {profile.name}'s node {profile.can.node_id} on IDs "
            f"{lo:#x}-{lo + ID_RANGE - 1:#x} ({counters.get('frames', 0)} frames there, "
            f"{counters.get('foreign_frames', 0)} of other IDs): another node's log, or set base_id")


def _ids(profile: Profile) -> str:
    lo = profile.can.base_id
    return f"IDs {lo:#x}-{lo + ID_RANGE - 1:#x} (profile {profile.name})"


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
    def describe(cls, node: NodeLike[Any]) -> str:
        return f"log {node.options.path}"

    @classmethod
    def check(cls, node: NodeLike[Any], base_dir: str) -> None:
        check_readable(node.options.path, "path")
        cls.check_layout(node)

    @classmethod
    def share_key(cls, node: NodeLike[Any]) -> tuple:
        return ("can-log", node.options.path)

    @classmethod
    def _reader(cls, node: NodeLike[Any], context: OpenContext) -> FrameThread:
        path = node.options.path
        return LogPlayer(path, read_can_log(path), context.queue_frames)

    def describe_where(self) -> str:
        return f"log {getattr(self.reader, 'path', '?')}"

    # -- a log is checked, not trusted: frames that do not fit the layout fail it ----
    _refused = ""

    def _poll(self, timeout_s: float | None) -> RawScan | None:
        if self._refused:
            return None
        scan = super()._poll(timeout_s)
        c = self.assembler.counters
        if c["malformed_frames"] <= MISMATCH_FLOOR:  # the usual case, decided at once
            return scan
        lay = self.assembler.layout
        mismatch = layout_mismatch(c, f"IDs {lay.base_id:#x}-{lay.base_id + ID_RANGE - 1:#x}")
        if mismatch is None:
            return scan
        self._refused = f"{getattr(self.reader, 'path', 'log')}: {mismatch}"
        self.reader.stop()  # the replay ends here: no verdict comes from it
        return None

    @property
    def done(self) -> bool:
        return bool(self._refused) or super().done

    @property
    def bus_fault(self) -> bool:
        # the player's error ends the replay: frames it queued before are still
        # decoded, and must not clear the fault as a live bus's frames would
        return bool(self._refused or self.reader.last_error) or super().bus_fault

    @property
    def last_error(self) -> str:
        return self._refused or super().last_error

    @property
    def failed(self) -> bool:
        return bool(self._refused) or super().failed
