"""Peers for the Modbus tests, each started here and cleaned up: socat pty pairs,
free TCP ports, mbpoll runs; and recordings with a known slip."""

from __future__ import annotations

import contextlib
import os
import shutil
import socket
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest


def need(tool: str) -> str:
    path = shutil.which(tool)
    if path is None:
        if os.environ.get("CI") == "true":
            pytest.fail(f"{tool} is missing (scripts/debian-packages.txt lists it)")
        pytest.skip(f"{tool} not installed (Debian package {tool})")
    return path


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextlib.contextmanager
def pty_pair(tmp: Path):
    """Two linked pseudo-terminals (a null-modem cable); yields their paths."""
    socat = need("socat")
    a, b = tmp / "ttyA", tmp / "ttyB"
    proc = subprocess.Popen([socat, f"pty,raw,echo=0,link={a}", f"pty,raw,echo=0,link={b}"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 5
        while not (a.exists() and b.exists()):
            if time.monotonic() > deadline or proc.poll() is not None:
                raise RuntimeError("socat did not create the pty pair")
            time.sleep(0.01)
        yield str(a), str(b)
    finally:
        proc.terminate()
        proc.wait(timeout=5)


def mbpoll(*args: str, timeout: float = 10) -> subprocess.CompletedProcess:
    return subprocess.run([need("mbpoll"), *args], capture_output=True, text=True, timeout=timeout)


def mbpoll_values(out: str) -> dict[int, int]:
    """``[ref]: value`` lines of mbpoll's output, by 1-based reference."""
    values = {}
    for line in out.splitlines():
        line = line.strip()
        if line.startswith("[") and "]:" in line:
            ref, _, value = line[1:].partition("]:")
            values[int(ref)] = int(value.split()[0])
    return values


def footprint(n_rows: int, n_cols: int, cx: float, cy: float, force: float, width: float = 1.0) -> np.ndarray:
    r, c = np.divmod(np.arange(n_rows * n_cols), n_cols)
    shape = np.exp(-((r - cy) ** 2 + (c - cx) ** 2) / (2 * width ** 2))
    return force * shape / shape.sum()


def slip_recording(rate_hz: float = 100.0, still_s: float = 1.5, slip_s: float = 0.3, after_s: float = 1.5,
                   force: float = 6.0, seed: int = 0) -> tuple[np.ndarray, np.ndarray, float]:
    """A still grasp, then the footprint slips across the 5 x 5 grid in ``slip_s``,
    then still again.  Returns (t, forces (K, 25) N, slip onset time)."""
    rng = np.random.default_rng(seed)
    k1, k2, k3 = (int(round(x * rate_hz)) for x in (still_s, slip_s, after_s))
    # Stick-slip: the footprint slides and chatters (+-0.25 taxel at every scan).
    # A smooth slide has no wavelet detail energy; a real slip is jerky, and the
    # chatter keeps it visible however the polling aliases the node's scans.
    steps = np.linspace(0.0, 2.2, k2) + 0.25 * (-1.0) ** np.arange(k2)
    end = 1.0 + (2.2 if k2 else 0.0)
    cx = np.concatenate([np.full(k1, 1.0), 1.0 + steps, np.full(k3, end)])
    f = np.stack([footprint(5, 5, x, 2.0, force) for x in cx])
    f = np.abs(f + rng.normal(0.0, 0.01, f.shape))
    t = np.arange(len(f)) / rate_hz
    return t, f, still_s
