"""What ``bridge --check`` can find on this machine before the run: a file to read is
there and readable, a folder to write into is there and writable, a serial device is
there.  Each is one ValueError ``KEY: PATH: what is wrong``, the message the run would
otherwise fail with later (or, for a replayed log, after its start line)."""

from __future__ import annotations

import os
from pathlib import Path


def check_readable(path: str, key: str) -> None:
    """``path`` is a file this process can open for reading."""
    p = Path(path)
    if not p.exists():
        raise ValueError(f"{key}: {path}: no such file")
    if not p.is_file():
        raise ValueError(f"{key}: {path}: not a file")
    try:
        with open(p, "rb"):
            pass
    except OSError as exc:
        raise ValueError(f"{key}: {path}: cannot read: {exc.strerror or exc}") from None


def check_writable_dir(path: str, key: str) -> None:
    """The folder ``path`` goes into exists and this process may create files in it."""
    folder = Path(path).parent
    if not folder.is_dir():
        raise ValueError(f"{key}: {path}: no such folder {str(folder)!r}")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise ValueError(f"{key}: {path}: folder {str(folder)!r} is not writable")


def check_serial(port: str, key: str) -> None:
    """A serial device path exists and may be opened for reading and writing
    (pyserial's URLs, ``socket://``, ``rfc2217://``, ``loop://``, are left to the run)."""
    if "://" in port:
        return
    if not os.path.exists(port):
        raise ValueError(f"{key}: {port}: no such device")
    if not os.access(port, os.R_OK | os.W_OK):
        raise ValueError(f"{key}: {port}: no permission to read and write it (the user's groups: dialout?)")
