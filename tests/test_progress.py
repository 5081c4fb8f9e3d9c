"""Progress of long work: a bar on stderr when it is a terminal, nothing when piped or
with -q, and the work's output the same, byte for byte, whoever watches.

The work reports through ``eskin_industrial.progress`` (stages and steps); the
command line's ``Ticker`` draws it.  Here: what each kind of work reports, that
reading and writing in pieces (so that there is something to report) gives what the
whole did, the ticker's rules on a pseudo-terminal, and the commands on one."""

from __future__ import annotations

import contextlib
import io
import json
import os
import pty
import re
import select
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from unittest import mock

import can
import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from eskin_industrial import offline, recording
from eskin_industrial.bus.can import log as can_log
from eskin_industrial.bus.can.layout import CanLayout
from eskin_industrial.calibration import full_scale
from eskin_industrial.cli import main
from eskin_industrial.cli.console import Ticker
from eskin_industrial.detect.methods import get_method
from eskin_industrial.errors import InputFormatError
from eskin_industrial.evaluation.families import FAMILIES
from eskin_industrial.evaluation.holdout import CANDIDATES, hold_out
from eskin_industrial.evaluation.metrics import SceneScore
from eskin_industrial.evaluation.suite import by_name, evaluate
from eskin_industrial.profile import load_profile
from eskin_industrial.recording import read_recording, write_recording, write_updates
from eskin_industrial.scenes import render
from tests.helpers.bridge import PAPER, hold_raw
from tests.helpers.can_frames import scans_to_messages
from tests.helpers.terminal import on_a_terminal, piped


class Recorded:
    """A Progress that keeps what it is told."""

    def __init__(self) -> None:
        self.stages: list[tuple[str, int, bool]] = []
        self.steps: list[list[tuple[int, str | None]]] = [[]]

    def stage(self, label: str, total: int, percent: bool = False) -> None:
        self.stages.append((label, total, percent))
        self.steps.append([])

    def advance(self, n: int = 1, label: str | None = None) -> None:
        self.steps[-1].append((n, label))

    def done(self, i: int) -> int:
        """Steps advanced in stage ``i``."""
        return sum(n for n, _ in self.steps[i + 1])


# -- what the work reports ---------------------------------------------------------------


def test_evaluate_advances_once_per_method_scene_and_seed() -> None:
    seen = Recorded()
    evaluate(by_name("paper", "cof-track"), scenes=("case2", "case4"), seeds=(1000, 1001), progress=seen)
    labels = [label for _n, label in seen.steps[0]]
    assert labels == ["paper, case2", "cof-track, case2"] * 2 + ["paper, case4", "cof-track, case4"] * 2


def test_a_held_out_family_is_a_stage_of_its_own() -> None:
    tuning = {fam: {c.label: SceneScore() for c in CANDIDATES["cof-track"]} for fam in FAMILIES}
    seen = Recorded()
    hold_out("cof-track", "varying-force", tuning, seeds=(1000,), progress=seen)
    (label, total, _), = seen.stages
    # nothing to choose on: the default is chosen, one run of the family's one scene
    assert label == "varying-force" and total == seen.done(0) == 1


def _csv(rows: list[str]) -> str:
    return "t,f0,f1\n" + "".join(rows)


def _parse(text: str, piece: int) -> np.ndarray | str:
    """read_recording of ``text`` cut into pieces of ``piece`` characters: the values, or the error."""
    with mock.patch.object(recording, "_PIECE_CHARS", piece), mock.patch.object(recording, "_read_text",
                                                                                 return_value=(text, "r.csv")):
        try:
            rec = read_recording("r.csv", 2)
        except InputFormatError as exc:
            return str(exc)
    return np.column_stack([rec.t, rec.values])


_NUMBER = st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=32).map(repr),
                    st.integers(-10**6, 10**6).map(str))
_ROW = st.one_of(st.lists(_NUMBER, min_size=3, max_size=3).map(lambda c: ",".join(c) + "\n"),
                 st.just("\n"), st.just("\r\n"),  # blank lines: skipped, in the whole as in a piece
                 st.sampled_from(["  \n", "1,2\n", "1,2,x\n", "1,2,3,4\n", "1,,3\n"]))  # and the faults


@settings(max_examples=150, deadline=None)
@given(rows=st.lists(_ROW, min_size=1, max_size=40), piece=st.integers(1, 60), last_newline=st.booleans())
def test_a_recording_read_in_pieces_is_the_recording_read_whole(rows: list[str], piece: int,
                                                                  last_newline: bool) -> None:
    text = _csv(rows)
    if not last_newline:
        text = text.rstrip("\n")
    whole = _parse(text, 1 << 40)
    cut = _parse(text, piece)
    if isinstance(whole, str):
        assert cut == whole  # the same line and column named
    else:
        assert isinstance(cut, np.ndarray) and np.array_equal(cut, whole, equal_nan=True)


def test_reading_reports_every_character_once() -> None:
    text = _csv([f"{i / 100},{i},{-i}\n" for i in range(500)])
    seen = Recorded()
    with mock.patch.object(recording, "_PIECE_CHARS", 300), \
            mock.patch.object(recording, "_read_text", return_value=(text, "r.csv")):
        read_recording("r.csv", 2, progress=seen)
    (label, total, percent), = seen.stages
    body = text.partition("\n")[2]
    assert label == "reading r.csv" and percent and total == seen.done(0) == len(body)
    assert len(seen.steps[1]) > 10  # in pieces, so that there is progress to show


def test_a_recording_written_in_pieces_is_the_recording_written_whole() -> None:
    rec = render("case2", 100.0, 1000)
    whole = io.StringIO()
    np.savetxt(whole, np.column_stack([rec.t, rec.forces]), delimiter=",", comments="",
               header="t," + ",".join(f"f{i}" for i in range(25)), fmt=["%.6f"] + ["%.9g"] * 25)
    cut = io.StringIO()
    seen = Recorded()
    with mock.patch.object(recording, "_PIECE_ROWS", 7):
        write_recording(cut, rec.t, rec.forces, progress=seen)
    assert cut.getvalue() == whole.getvalue()
    assert seen.stages[0][1] == seen.done(0) == len(rec.t) and len(seen.steps[1]) == -(-len(rec.t) // 7)


def _candump(path: Path, scans: int) -> Path:
    """A candump -L log of the paper-5x5 node, written by python-can's writer."""
    prof = load_profile(PAPER)
    layout = CanLayout.from_profile(prof)
    writer = can.CanutilsLogWriter(path) if path.suffix == ".log" else can.BLFWriter(path)
    with writer:
        for m in scans_to_messages(layout, np.arange(scans) % 4096, hold_raw(prof, scans)):
            m.timestamp += 1.7e9
            m.channel = "can0"
            writer.on_message_received(m)
    return path


@pytest.mark.parametrize("suffix", [".log", ".blf"])
def test_a_can_log_reports_its_bytes_then_its_scans(tmp_path: Path, suffix: str) -> None:
    log = _candump(tmp_path / f"traffic{suffix}", 600)
    seen = Recorded()
    with mock.patch.object(can_log, "_PROGRESS_EVERY", 200), mock.patch.object(offline, "_PROGRESS_EVERY", 200):
        found = offline.detect_can_log(load_profile(PAPER), log, progress=seen)
    table, counters = found.table, found.transport
    assert counters is not None
    (reading, size, percent), (detecting, scans, _) = seen.stages
    assert reading == f"reading {log}" and percent and size == seen.done(0) == log.stat().st_size
    assert len(seen.steps[1]) > 2  # read as it goes, not only at the end
    assert detecting == "detecting" and scans == seen.done(1) == counters["scans"] == 600 == len(table)


def test_detect_in_pieces_gives_the_methods_batch(tmp_path: Path) -> None:
    rec = render("case2", 100.0, 1000)
    path = tmp_path / "case2.csv"
    write_recording(path, rec.t, rec.forces)
    prof = load_profile(PAPER)
    x, y = prof.coordinates_mm
    back = read_recording(path, 25)  # (as the file holds it: 9 digits)
    values, flags = full_scale(back.values, prof.calibration.full_scale_n)
    want = io.StringIO()
    write_updates(want, get_method("cof-track").batch(prof.detector, x, y, 100.0, back.t, values, flags))
    with mock.patch.object(offline, "_PIECE_FRAMES", 7):
        got = CliRunner().invoke(main, ["detect", "-p", PAPER, "--method", "cof-track", "--rate", "100", str(path),
                                        "-q"])
    assert got.exit_code == 0, got.output
    assert got.stdout == want.getvalue()


# -- the ticker on a pseudo-terminal -----------------------------------------------------


@contextlib.contextmanager
def stderr_on_a_terminal() -> Iterator[Callable[[], str]]:
    """sys.stderr on a pseudo-terminal (in the test itself: pytest sets its own between
    a fixture and the test) and sys.stdout into a buffer, as a file or a pipe takes
    it; yields what the terminal showed since last asked."""
    leader, follower = pty.openpty()
    err = os.fdopen(follower, "w", buffering=1)

    def shown() -> str:
        err.flush()
        out = b""
        while select.select([leader], [], [], 0.05)[0]:
            out += os.read(leader, 65536)
        return out.decode(errors="replace")

    try:
        with mock.patch.object(sys, "stderr", err), mock.patch.object(sys, "stdout", io.StringIO()):
            yield shown
    finally:
        err.close()
        os.close(leader)


def test_the_bar_waits_for_work_that_takes_long() -> None:
    with stderr_on_a_terminal() as terminal, Ticker(10, "work", delay_s=0.3) as ticker:
        ticker.advance()
        assert terminal() == ""
        time.sleep(0.35)
        ticker.advance()
        assert "2/10" in terminal()  # where the work is, not where the bar began


def test_a_line_goes_above_the_bar() -> None:
    with stderr_on_a_terminal() as terminal:
        ticker = Ticker(5, "work")
        ticker.advance()
        ticker.write("figure 3")
        ticker.advance()
        ticker.close()
        before, _, after = terminal().partition("figure 3")
    assert "1/5" in before and "\x1b[K" in before[-8:]  # the bar's line cleared for it
    assert after.startswith("\r\n") and "2/5" in after


def test_a_long_label_is_cut_so_that_the_line_never_wraps(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("COLUMNS", "70")  # (a line that wraps cannot be drawn over with a CR)
    with stderr_on_a_terminal() as terminal, Ticker(5, "scoring") as ticker:
        ticker.advance(1, "tuning point-contact: no stick-slip evidence (ripple_s 0), sphere, seed 1000")
        ticker.advance(1, "short")
        lines = re.split(r"[\r\n]+", re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", terminal()))
    assert "2/5" in lines[-1] and "tuning point-contact" in lines[-2]
    assert max(len(line) for line in lines) <= 70


def test_no_bar_among_rows_on_the_same_terminal() -> None:
    leader, follower = pty.openpty()
    with stderr_on_a_terminal() as terminal, os.fdopen(follower, "w") as out, mock.patch.object(sys, "stdout", out):
        with Ticker(5, "writing", stdout_data=True) as ticker:
            ticker.advance()
        assert terminal() == ""
        with Ticker(5, "writing") as ticker:  # a command whose data goes elsewhere
            ticker.advance()
        assert "1/5" in terminal()
    os.close(leader)


def test_quiet_or_no_terminal_no_bar() -> None:
    with stderr_on_a_terminal() as terminal:
        with Ticker(5, "work", own_quiet=True) as ticker:
            ticker.advance()
            ticker.write("a line")
        assert terminal() == ""
    log = io.StringIO()
    with mock.patch.object(sys, "stderr", log), Ticker(5, "work") as ticker:
        ticker.advance()
        ticker.write("a line")
    assert log.getvalue() == "a line\n"  # a log's line, never a bar's


# -- the commands on a terminal, piped and with -q ---------------------------------------


def _no_bar(stderr: str) -> None:
    assert "[#" not in stderr and "[-" not in stderr and "\r" not in stderr


@pytest.mark.slow
def test_evaluate_long_holds(tmp_path: Path) -> None:
    args = ["evaluate", "--long-holds", "--seeds", "2000..2001", "-m", "cof-track", "--format", "json"]
    tty = on_a_terminal(args, tmp_path / "out")
    assert tty.code == 0 and "4/4" in tty.shown and "cof-track, hand-hold" in tty.shown
    quiet = on_a_terminal([*args, "-q"], tmp_path / "out")
    assert quiet.code == 0 and quiet.shown == ""
    pipe = piped(args)
    assert pipe.returncode == 0 and pipe.stderr == b""

    def figures(out: bytes) -> dict:  # all but the times, which differ from run to run
        doc = json.loads(out)
        del doc["seconds"]
        for m in doc["methods"]:
            del m["us_per_frame"], m["cost_vs_paper"]
        return doc

    assert figures(tty.stdout) == figures(quiet.stdout) == figures(pipe.stdout)


@pytest.mark.slow
def test_evaluate_charts(tmp_path: Path) -> None:
    args = ["evaluate", "--charts", str(tmp_path / "charts"), "--only", "figure3"]
    tty = on_a_terminal(args, tmp_path / "out")
    assert tty.code == 0 and "7/7" in tty.shown and "figure 3: hand" in tty.shown
    assert tty.shown.startswith("figure 3\r\n")  # the log's line, then the bar
    assert (tmp_path / "charts" / "figure3-indicators.png").stat().st_size > 10_000
    pipe = piped(args)
    assert pipe.returncode == 0 and pipe.stderr == b"figure 3\n" and pipe.stdout == b""
    quiet = on_a_terminal([*args, "-q"], tmp_path / "out")
    assert quiet.code == 0 and quiet.shown == ""


@pytest.mark.slow
def test_detect_a_large_csv(tmp_path: Path) -> None:
    rec = render("hold", 2000.0, 5)  # a still hold at 2 kHz: 44 MB, a few seconds of detect
    path = tmp_path / "hold.csv"
    write_recording(path, rec.t, rec.forces)
    frames = len(rec.t)
    args = ["detect", "-p", PAPER, str(path), "--rate", "2000"]
    tty = on_a_terminal(args, tmp_path / "out")
    assert tty.code == 0 and re.search(rf"detecting +\[#+\] +{frames}/{frames}", tty.shown), tty.shown[-500:]
    assert tty.shown.index(f"{frames} frames at 2000.0 Hz") > tty.shown.rindex(f"{frames}/{frames}")  # then the summary
    quiet = on_a_terminal([*args, "-q"], tmp_path / "out")  # (piped: the CAN log's test)
    assert quiet.code == 0 and quiet.shown == ""
    assert tty.stdout == quiet.stdout and tty.stdout.count(b"\n") > 1000


@pytest.mark.slow
def test_detect_a_large_can_log(tmp_path: Path) -> None:
    log = _candump(tmp_path / "traffic.log", 40_000)
    args = ["detect", "-p", PAPER, "--can-log", str(log), "--method", "cof-track"]
    tty = on_a_terminal(args, tmp_path / "out")
    assert tty.code == 0 and "40000/40000" in tty.shown, tty.shown[-500:]
    pipe = piped(args)  # (-q: the CSV's test)
    assert pipe.returncode == 0
    _no_bar(pipe.stderr.decode())
    assert pipe.stderr.decode().count("\n") == 1  # the summary alone
    assert tty.stdout == pipe.stdout and tty.stdout.count(b"\n") == 40_001


@pytest.mark.slow
def test_simulate_a_long_scene_to_stdout(tmp_path: Path) -> None:
    args = ["simulate", "hold", "--rate", "5000", "--seed", "2"]
    rows = len(render("hold", 5000.0, 2).t)
    tty = on_a_terminal(args, tmp_path / "out")  # stdout into a file, stderr the terminal
    assert tty.code == 0 and "writing <stdout>" in tty.shown and f"{rows}/{rows}" in tty.shown, tty.shown[-300:]
    pipe = piped(args)  # (-q: the other commands' tests)
    assert pipe.returncode == 0 and pipe.stderr == b""
    assert tty.stdout == pipe.stdout and tty.stdout.count(b"\n") == rows + 1


@pytest.mark.slow
def test_a_live_log_on_stdin_counts_its_updates(tmp_path: Path) -> None:
    """No length to show a share of: a count, once it has run a second; none with -q,
    none with the rows on the same terminal."""
    lines = _candump(tmp_path / "traffic.log", 300).read_bytes().splitlines(keepends=True)
    live = [b"".join(lines[:1500]), b"".join(lines[1500:])]  # then a pause longer than the delay
    args = ["detect", "-p", PAPER, "--can-log", "-"]
    tty = on_a_terminal(args, tmp_path / "out", stdin=live, pause_s=1.3)
    assert tty.code == 0 and "\r\x1b[Kupdates  300\r\n" in tty.shown, tty.shown[-300:]
    assert tty.stdout.count(b"\n") == 301
    quiet = on_a_terminal([*args, "-q"], tmp_path / "out", stdin=live, pause_s=1.3)
    assert quiet.code == 0 and quiet.shown == "" and quiet.stdout == tty.stdout
    rows_here = on_a_terminal(args, None, stdin=live, pause_s=1.3)
    assert rows_here.code == 0 and "updates  " not in rows_here.shown and rows_here.shown.count("\n") == 302
