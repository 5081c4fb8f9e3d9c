"""The terminal driver of the live view: plain ANSI escape codes, no curses.

:class:`LiveScreen` switches to the alternate screen and hides the cursor, redraws
from its own thread at a capped rate (never once per scan: the data path only keeps
its newest values, and a slow terminal stalls this thread, not the detector), takes
the size from :func:`shutil.get_terminal_size` at every frame (so a resize just
works), and restores the terminal on any exit: normal end, Ctrl-C, an exception,
SIGTERM.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import threading
from collections.abc import Callable, Mapping
from types import FrameType, TracebackType
from typing import TextIO

#: alternate screen on, cursor hidden, screen cleared
ENTER = "\x1b[?1049h\x1b[?25l\x1b[2J"
#: attributes reset, cursor shown, alternate screen off (the shell's screen comes back)
LEAVE = "\x1b[0m\x1b[?25h\x1b[?1049l"
HOME = "\x1b[H"
#: terminals that know it show a frame only once it is complete (others ignore it)
_SYNC_ON, _SYNC_OFF = "\x1b[?2026h", "\x1b[?2026l"
_ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")

DEFAULT_FPS = 15.0


def visible_width(text: str) -> int:
    return len(_ANSI.sub("", text))


def frame_text(lines: list[str], width: int, height: int) -> str:
    """One redraw: home, each line cleared to its end, the rest of the screen cleared.

    A line that fills the last column leaves the cursor on that column, where an
    erase would remove the last character: it gets no erase; and no newline follows
    the last line, so a full screen never scrolls.
    """
    parts = [_SYNC_ON, HOME]
    for i, line in enumerate(lines[:height]):
        if i:
            parts.append("\r\n")
        parts.append(line)
        if visible_width(line) < width:
            parts.append("\x1b[K")
    if len(lines) < height:
        parts.append("\r\n\x1b[J" if lines else "\x1b[J")
    parts.append(_SYNC_OFF)
    return "".join(parts)


def color_wanted(env: Mapping[str, str] | None = None) -> bool:
    """Colour unless ``NO_COLOR`` is set (no-color.org) or the terminal is dumb."""
    env = os.environ if env is None else env
    return "NO_COLOR" not in env and env.get("TERM", "") not in ("", "dumb")


class RedrawError(RuntimeError):
    """Drawing failed (a bug in the view); the data path kept running."""


class LiveScreen:
    """Context manager: the alternate screen while inside, redrawn ``fps`` times a
    second from ``frame(width, height) -> lines``.

    ``frame`` runs on the redraw thread; it must only read the newest values the data
    path left (attribute reads), never wait on it.  A failure while drawing stops the
    redraws, leaves the data path alone, and is raised as :class:`RedrawError` once
    the terminal is restored.
    """

    def __init__(self, frame: Callable[[int, int], list[str]], stream: TextIO, fps: float = DEFAULT_FPS,
                 size: Callable[[], os.terminal_size] = shutil.get_terminal_size) -> None:
        self.frame = frame
        self.stream = stream
        self.interval_s = 1.0 / fps
        self.size = size
        self.frames = 0
        self.error: BaseException | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="live-view", daemon=True)
        self._old_term: Callable[[int, FrameType | None], object] | int | None = None

    def __enter__(self) -> LiveScreen:
        self._write(ENTER)
        if threading.current_thread() is threading.main_thread():
            # SIGTERM would end the process without unwinding: the shell would be left
            # on the alternate screen with no cursor.  Turn it into an orderly exit.
            self._old_term = signal.signal(signal.SIGTERM, _exit_on_term)
        self._thread.start()
        return self

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        try:
            self._write(LEAVE)
        finally:
            if self._old_term is not None:
                signal.signal(signal.SIGTERM, self._old_term)
        if self.error is not None and kind is None:
            raise RedrawError(f"live view: drawing failed: {self.error!r}") from self.error

    def draw(self) -> None:
        """One frame, now (the redraw thread calls it at the capped rate)."""
        cols, rows = self.size()
        self._write(frame_text(self.frame(cols, rows), cols, rows))
        self.frames += 1

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                self.draw()
            except Exception as exc:  # noqa: BLE001 - a drawing bug must not stop the data path
                self.error = exc
                return
            self._stop.wait(self.interval_s)

    def _write(self, text: str) -> None:
        self.stream.write(text)
        self.stream.flush()


def _exit_on_term(signum: int, frame: FrameType | None) -> None:
    raise SystemExit(128 + signum)
