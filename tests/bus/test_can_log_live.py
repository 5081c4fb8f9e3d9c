"""`candump -L can0 | eskin-bus detect -p P --can-log -`: a candump-format log read from
stdin as it comes, each update written as soon as its scan is complete, with the same
output, checks and summary as the same log read from a file."""

from __future__ import annotations

import json
import os
import select
import subprocess
import sys
import time
from pathlib import Path

import can
import numpy as np
import pytest

from eskin_industrial.bus.can.layout import CanLayout
from eskin_industrial.profile import load_profile
from tests.helpers.bridge import PAPER, hold_raw
from tests.helpers.can_frames import scans_to_messages

ESKIN = [sys.executable, "-m", "eskin_industrial"]


def candump_log(path: Path, fd: bool = False, scans: int = 300) -> Path:
    """A candump -L log written by python-can's writer (not the package's)."""
    prof = load_profile(PAPER)
    layout = CanLayout.from_profile(prof, fd=fd)
    with can.CanutilsLogWriter(path) as log:
        for m in scans_to_messages(layout, np.arange(scans) % 4096, hold_raw(prof, scans)):
            m.timestamp += 1.7e9
            m.channel = "can0"
            log.on_message_received(m)
    return path


@pytest.mark.parametrize("fd", [False, True], ids=["classic", "fd"])
def test_stdin_gives_what_the_file_gives(tmp_path: Path, fd: bool) -> None:
    log = candump_log(tmp_path / "traffic.log", fd)
    from_file = subprocess.run([*ESKIN, "detect", "-p", PAPER, "--can-log", str(log), "--json"],
                               capture_output=True, text=True, timeout=60)
    from_pipe = subprocess.run([*ESKIN, "detect", "-p", PAPER, "--can-log", "-", "--json"], input=log.read_text(),
                               capture_output=True, text=True, timeout=60)
    assert from_file.returncode == from_pipe.returncode == 0, from_pipe.stderr
    assert from_pipe.stdout == from_file.stdout and from_pipe.stdout.count("\n") == 301
    piped, filed = json.loads(from_pipe.stderr), json.loads(from_file.stderr)
    assert piped["input"] == "<stdin>" and piped["transport"] == filed["transport"]
    assert piped["transport"]["scans"] == 300 and piped["states"] == filed["states"]


def test_rows_come_while_the_log_is_still_being_written(tmp_path: Path) -> None:
    lines = candump_log(tmp_path / "traffic.log").read_text().splitlines(keepends=True)
    with subprocess.Popen([*ESKIN, "detect", "-p", PAPER, "--can-log", "-", "-q"], stdin=subprocess.PIPE,
                          stdout=subprocess.PIPE, text=True, bufsize=1) as proc:
        assert proc.stdin is not None and proc.stdout is not None
        try:
            half = len(lines) // 2
            proc.stdin.writelines(lines[:half])
            proc.stdin.flush()
            seen: list[str] = []
            deadline = time.monotonic() + 30
            while len(seen) < 50 and time.monotonic() < deadline:  # stdin still open: no EOF yet
                if select.select([proc.stdout], [], [], 0.5)[0]:
                    seen.append(proc.stdout.readline())
            assert len(seen) >= 50 and seen[0].startswith("t,r_coe"), "no row before the end of the input"
            assert proc.poll() is None
            proc.stdin.writelines(lines[half:])
            proc.stdin.close()
            rest = proc.stdout.read()
            assert proc.wait(timeout=30) == 0
            assert len(seen) + rest.count("\n") == 301
        finally:
            proc.kill()


def test_a_bad_line_another_nodes_log_and_an_empty_one_are_one_line(tmp_path: Path) -> None:
    text = candump_log(tmp_path / "traffic.log").read_text().splitlines(keepends=True)
    broken = "".join(text[:40] + ["(1700000000.5) can0 20X#GARBAGE\n"] + text[40:])
    for given, expect in ((broken, "message 41: not a valid candump -L line"),
                          ("".join(text).replace(" can0 20", " can0 30"), "no complete scan of profile paper-5x5"),
                          ("", "no complete scan")):
        res = subprocess.run([*ESKIN, "detect", "-p", PAPER, "--can-log", "-"], input=given, capture_output=True,
                             text=True, timeout=60)
        assert res.returncode == 2, res.stderr
        assert res.stderr.count("\n") == 1 and expect in res.stderr and "<stdin>" in res.stderr


def test_a_reader_that_goes_away_ends_it_quietly(tmp_path: Path) -> None:
    log = candump_log(tmp_path / "traffic.log", scans=1000)
    with open(log) as stdin:
        head = subprocess.run(f"{' '.join(ESKIN)} detect -p {PAPER} --can-log - | head -3", shell=True,
                              stdin=stdin, capture_output=True, text=True, timeout=60,
                              env={**os.environ, "PYTHONUNBUFFERED": "1"})
    assert head.stdout.count("\n") == 3 and "Traceback" not in head.stderr and "error" not in head.stderr
