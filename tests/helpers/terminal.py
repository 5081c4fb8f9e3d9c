"""``eskin-bus`` with its stderr on a pseudo-terminal, as a user at a terminal runs it,
its stdout into a file or a pipe as a script takes it."""

from __future__ import annotations

import os
import pty
import select
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

ESKIN = [sys.executable, "-m", "eskin_industrial"]


@dataclass
class Run:
    code: int
    #: What the terminal showed (stderr), CR and escape sequences as they came.
    shown: str
    #: stdout, as bytes.
    stdout: bytes


def on_a_terminal(args: list[str], stdout: Path | None, timeout_s: float = 60.0,
                  stdin: list[bytes] | None = None, pause_s: float = 0.0) -> Run:
    """Run ``eskin-bus ARGS``, stderr on a pseudo-terminal, stdout into the file
    ``stdout`` (None: the same terminal).  ``stdin``: pieces written to its stdin, a
    pipe, ``pause_s`` apart, as a live log comes."""
    leader, follower = pty.openpty()
    with open(stdout if stdout is not None else os.devnull, "wb") as out:
        proc = subprocess.Popen([*ESKIN, *args], stdout=out if stdout is not None else follower, stderr=follower,
                                stdin=subprocess.DEVNULL if stdin is None else subprocess.PIPE,
                                env={**os.environ, "COLUMNS": "120"})
    os.close(follower)
    if stdin is not None:
        assert proc.stdin is not None
        for i, piece in enumerate(stdin):
            if i:
                time.sleep(pause_s)
            proc.stdin.write(piece)
            proc.stdin.flush()
        proc.stdin.close()
    shown = b""
    deadline = time.monotonic() + timeout_s
    try:
        while time.monotonic() < deadline:
            ready, _, _ = select.select([leader], [], [], 0.2)
            if ready:
                try:
                    chunk = os.read(leader, 65536)
                except OSError:  # the other side closed
                    break
                if not chunk:
                    break
                shown += chunk
            elif proc.poll() is not None:
                break
    finally:
        os.close(leader)
        if proc.poll() is None:
            proc.kill()
    return Run(proc.wait(timeout=10), shown.decode(errors="replace"), stdout.read_bytes() if stdout else b"")


def piped(args: list[str], timeout_s: float = 60.0) -> subprocess.CompletedProcess[bytes]:
    """Run ``eskin-bus ARGS`` with stdout and stderr into pipes."""
    return subprocess.run([*ESKIN, *args], capture_output=True, timeout=timeout_s, stdin=subprocess.DEVNULL)
