"""The recorder: every detector update of a node, as CSV (the columns of ``eskin-bus
detect``'s output) or JSON lines, to a file or standard output.

Configured as ``[recorder]`` in the bridge configuration or ``--record PATH`` on the
command line.  With several nodes, ``{node}`` in the path names each node's file.  The
file is written every ``flush_every_s`` so that a reader following it sees recent
updates, and it only ever ends on a whole row: a write that fails (a full disk, a
file-size limit) is cut back to the last whole row, its rows are lost and counted
(``record_lost_rows``), the failure is logged once (``record_write_failed``, an
error) and the bridge goes on, trying again at the next write; ``record_write_ok``
says when the file is written again.  (The recorder's degraded mode: detection and
the other outputs never wait for a disk.)
"""

from __future__ import annotations

import json
import math
import os
import time
from typing import IO

from ...detect.state import LABELS
from ...detect.updates import COLUMNS, Update
from ...recording import update_row
from ..base import Sink, SinkHealth


class Recorder(Sink):
    """One node's updates, written to a stream (opened by :class:`.kind.RecorderKind`)."""

    def __init__(self, stream: IO[str], fmt: str, node: str, *, where: str, owned: bool,
                 flush_every_s: float = 1.0, header: bool = True) -> None:
        super().__init__()
        self.where = where
        self._out = stream
        self._owned = owned
        self._node = node
        self._jsonl = fmt == "jsonl"
        self._flush_every_s = flush_every_s
        self._next_flush = time.monotonic() + flush_every_s
        self.records = 0
        self.write_errors = 0
        self.last_error = ""
        self._failing = False  #: since a write failed, until one succeeds
        if not self._jsonl and header:
            self._write(",".join(COLUMNS) + "\n")

    def on_update(self, update: Update) -> None:
        if self._jsonl:
            u = update
            line = json.dumps({"node": self._node, "t": _num(u.t), "r_coe": _num(u.r_coe), "r_dw": _num(u.r_dw),
                               "state": LABELS[u.state], "valid": int(u.valid), "f_sum": _num(u.f_sum),
                               "xc": _num(u.xc), "yc": _num(u.yc), "flags": int(u.flags),
                               "score_a": _num(u.score_a), "score_b": _num(u.score_b)}) + "\n"
        else:
            line = update_row(update, LABELS[update.state])
        if self._write(line):
            self.records += 1
        now = time.monotonic()
        if now >= self._next_flush:
            self._next_flush = now + self._flush_every_s
            self._flush_stream()

    def _write(self, text: str) -> bool:
        try:
            self._out.write(text)
            return True
        except (OSError, ValueError) as exc:  # a full disk, a closed pipe: counted, never fatal
            self._failed(exc)
            return False

    def _flush_stream(self) -> None:
        before = self._out.written if isinstance(self._out, RowFile) else None
        try:
            self._out.flush()
        except (OSError, ValueError) as exc:
            self._failed(exc)
        else:
            # ok again only once rows reached the file (a flush with nothing to write,
            # the one at the end, says nothing of the disk)
            if self._failing and (before is None or self._out.written > before):  # type: ignore[attr-defined]
                self._failing = False
                self._event("record_write_ok", path=self.where, lost_rows=self.lost_rows,
                            write_errors=self.write_errors)

    def _failed(self, exc: Exception) -> None:
        self.write_errors += 1
        self.last_error = str(exc.strerror if isinstance(exc, OSError) and exc.strerror else exc)
        if not self._failing:
            self._failing = True
            self._event("record_write_failed", "error", path=self.where, error=self.last_error,
                        lost_rows=self.lost_rows)

    @property
    def lost_rows(self) -> int:
        return self._out.lost_rows if isinstance(self._out, RowFile) else 0

    def health(self) -> SinkHealth:
        return SinkHealth(None, self.write_errors, self.last_error)

    def counters(self) -> dict[str, int]:
        return {"recorded_updates": self.records, "record_write_errors": self.write_errors,
                "record_lost_rows": self.lost_rows}

    def flush(self, timeout_s: float = 1.0) -> bool:
        self._flush_stream()
        return True

    def _close(self) -> None:
        self._flush_stream()
        if self._owned:
            try:
                self._out.close()
            except OSError as exc:
                self.write_errors += 1
                self.last_error = str(exc)


class RowFile:
    """A file written in whole rows: ``write`` buffers, ``flush`` writes; a write the
    disk refuses (full, a file-size limit) is cut back to the end of the last whole
    row written, and the rows it held are lost (``lost_rows``); OSError as from a file."""

    #: Written out when the buffer holds this much, flushed or not.
    BUFFER_BYTES = 65536

    def __init__(self, path: str, append: bool = False) -> None:
        self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | (0 if append else os.O_TRUNC), 0o666)
        #: the file's length when opened (appended to: after the rows already there)
        self.size = os.lseek(self._fd, 0, os.SEEK_END)
        self._buf = bytearray()
        self._end = self.size  #: the end of the last whole row on disk
        self.lost_rows = 0
        self.written = 0  #: bytes this process wrote to the file (a flush that wrote nothing proves nothing)

    def write(self, text: str) -> int:
        self._buf += text.encode("utf-8")
        if len(self._buf) >= self.BUFFER_BYTES:
            self.flush()
        return len(text)

    def flush(self) -> None:
        if not self._buf or self._fd < 0:
            return
        data = bytes(self._buf)
        self._buf.clear()  # written or lost: never written twice
        view = memoryview(data)
        try:
            while view:
                view = view[os.write(self._fd, view):]
        except OSError:
            self.lost_rows += data.count(b"\n")
            try:  # no half row left behind
                os.ftruncate(self._fd, self._end)
                os.lseek(self._fd, self._end, os.SEEK_SET)
            except OSError:
                pass
            raise
        self._end += len(data)
        self.written += len(data)

    def close(self) -> None:
        if self._fd < 0:
            return
        try:
            self.flush()
        finally:
            os.close(self._fd)
            self._fd = -1


def _num(x: float) -> float | None:
    """A JSON number; NaN and infinities (no JSON for them) as null."""
    x = float(x)
    return x if math.isfinite(x) else None
