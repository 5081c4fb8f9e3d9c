"""The live view's terminal driver: alternate screen, capped redraws, and the terminal
restored however the run ends."""
from __future__ import annotations

import io
import os
import signal
import threading
import time

import pytest

from eskin_industrial.view.terminal import (
    ENTER,
    HOME,
    LEAVE,
    LiveScreen,
    RedrawError,
    color_wanted,
    frame_text,
    visible_width,
)


def size(cols: int = 80, rows: int = 24):
    return lambda: os.terminal_size((cols, rows))


class Recorder(io.StringIO):
    """A terminal stand-in that counts redraws and can be slow to take them."""

    def __init__(self, slow_s: float = 0.0) -> None:
        super().__init__()
        self.slow_s = slow_s
        self.frames = 0

    def write(self, text: str) -> int:
        if HOME in text:
            self.frames += 1
            time.sleep(self.slow_s)
        return super().write(text)


def screen(stream, frame=lambda w, h: [f"{w}x{h}", "second line"], fps: float = 20.0) -> LiveScreen:
    return LiveScreen(frame, stream, fps=fps, size=size())


def test_enters_and_restores_the_terminal():
    out = Recorder()
    with screen(out):
        time.sleep(0.15)
    text = out.getvalue()
    assert text.startswith(ENTER) and text.endswith(LEAVE)
    assert "\x1b[?1049h" in ENTER and "\x1b[?25l" in ENTER  # alternate screen, cursor hidden
    assert "\x1b[?25h" in LEAVE and "\x1b[?1049l" in LEAVE  # cursor back, shell screen back
    assert "80x24" in text  # the size came from the size function, at every frame
    assert out.frames >= 2


@pytest.mark.parametrize("error", [KeyboardInterrupt, ValueError])
def test_restores_the_terminal_on_ctrl_c_and_errors(error):
    out = Recorder()
    with pytest.raises(error):
        with screen(out):
            time.sleep(0.05)
            raise error()
    assert out.getvalue().endswith(LEAVE)


def test_sigterm_ends_the_view_in_order():
    out = Recorder()
    before = signal.getsignal(signal.SIGTERM)
    with pytest.raises(SystemExit) as exit_info:
        with screen(out):
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(1.0)  # the handler raises here
    assert exit_info.value.code == 128 + signal.SIGTERM
    assert out.getvalue().endswith(LEAVE)
    assert signal.getsignal(signal.SIGTERM) is before


def test_redraws_are_capped_whatever_the_update_rate():
    out = Recorder()
    newest = {"n": 0}
    with screen(out, frame=lambda w, h: [f"update {newest['n']}"], fps=20.0):
        start = time.monotonic()
        while time.monotonic() - start < 0.5:  # the data path: as many updates as it can
            newest["n"] += 1
    assert newest["n"] > 10_000
    assert 3 <= out.frames <= 0.5 * 20 + 3


def test_a_slow_terminal_never_holds_up_the_data_path():
    out = Recorder(slow_s=0.3)  # every redraw takes 0.3 s to be written
    with screen(out):
        time.sleep(0.05)  # a redraw is under way
        start = time.monotonic()
        for _ in range(100_000):
            pass
        spent = time.monotonic() - start
    assert spent < 0.2


def test_a_drawing_failure_is_raised_once_the_terminal_is_restored():
    out = Recorder()
    done = threading.Event()

    def broken(w: int, h: int) -> list[str]:
        raise ZeroDivisionError("bug")

    with pytest.raises(RedrawError, match="bug"):
        with screen(out, frame=broken):
            time.sleep(0.1)
            done.set()  # the body ran to its end: the failure did not stop it
    assert done.is_set() and out.getvalue().endswith(LEAVE)


def test_frame_text_never_scrolls_or_wraps():
    full = frame_text(["a" * 10, "b" * 4, "c" * 10], 10, 3)
    assert full.count("\r\n") == 2 and not full.removesuffix("\x1b[?2026l").endswith("\n")
    # a line that fills the width is not erased after (that would remove its last character)
    assert "a" * 10 + "\r\n" in full and "b" * 4 + "\x1b[K" in full
    assert "\x1b[J" not in full
    short = frame_text(["x"], 10, 3)
    assert short.endswith("\x1b[J\x1b[?2026l")  # the rest of the screen is cleared
    assert visible_width("\x1b[1;31mab\x1b[0m") == 2


def test_colour_only_for_a_terminal_that_has_it():
    assert color_wanted({"TERM": "xterm-256color"})
    assert not color_wanted({"TERM": "xterm-256color", "NO_COLOR": "1"})
    assert not color_wanted({"TERM": "dumb"}) and not color_wanted({})
