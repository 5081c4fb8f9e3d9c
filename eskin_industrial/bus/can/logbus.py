"""A CAN "bus" that is a log file: what is sent is written with python-can's writer
for the file's suffix (``.asc``, ``.blf``, ``.csv``, ``.log`` candump, ``.trc``), or
as candump ``-L`` lines to stdout for ``-``.

This is how the node simulator runs without hardware and without vcan: its frames go
to a file that ``detect --can-log``, the ``can-log`` source, python-can and can-utils
read.  The frames keep the timestamps the sender gave them (the node's clock), made
non-decreasing as on a wire: a frame held back behind the next one goes out after it.
"""

from __future__ import annotations

import io
import sys
from pathlib import PurePath
from typing import TYPE_CHECKING

import can

if TYPE_CHECKING:
    from can.io.generic import MessageWriter

#: What ``--can-log`` writes, by suffix (python-can's writers that its readers, and so
#: ``detect --can-log``, read back; ``.gz`` after a text suffix compresses it).
LOG_SUFFIXES = (".asc", ".blf", ".csv", ".log", ".trc")


def check_log_path(path: str) -> None:
    """ValueError naming the suffixes unless ``path`` is ``-`` or has one of them."""
    if path == "-":
        return
    parts = [s.lower() for s in PurePath(path).suffixes]
    if parts and parts[-1] == ".gz" and len(parts) >= 2 and parts[-2] in LOG_SUFFIXES and parts[-2] != ".blf":
        return
    if parts and parts[-1] in LOG_SUFFIXES:
        return
    raise ValueError(f"{path}: expected a CAN log ending in {', '.join(LOG_SUFFIXES)} (or - for candump -L "
                     "on stdout)")


def open_log_writer(path: str) -> MessageWriter:
    """python-can's writer for ``path`` (``-``: candump ``-L`` lines on stdout, one
    line as soon as it is written, so that a reader downstream gets them live)."""
    check_log_path(path)
    if path == "-":
        # stdout's descriptor, not sys.stdout: the writer closes its file when it stops
        out = io.TextIOWrapper(open(sys.stdout.fileno(), "wb", closefd=False), encoding="ascii", line_buffering=True)
        return can.io.CanutilsLogWriter(out)
    return can.Logger(path)


class LogBus(can.BusABC):
    """Frames sent are written to a CAN log; nothing is ever received.  ``shutdown``
    closes the log (twice is safe)."""

    def __init__(self, path: str, channel: str = "can0") -> None:
        self.path = path
        self.writer = open_log_writer(path)
        self._last = float("-inf")
        self._closed = False
        super().__init__(channel=channel)
        self.channel_info = f"CAN log {path}"

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        stamped = can.Message(timestamp=max(msg.timestamp, self._last), arbitration_id=msg.arbitration_id,
                              is_extended_id=msg.is_extended_id, is_remote_frame=msg.is_remote_frame,
                              is_error_frame=msg.is_error_frame, dlc=msg.dlc, data=msg.data, is_fd=msg.is_fd,
                              bitrate_switch=msg.bitrate_switch, error_state_indicator=msg.error_state_indicator)
        self._last = stamped.timestamp
        self.writer.on_message_received(stamped)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        return None, False

    def shutdown(self) -> None:
        if not self._closed:
            self._closed = True
            self.writer.stop()
        super().shutdown()
