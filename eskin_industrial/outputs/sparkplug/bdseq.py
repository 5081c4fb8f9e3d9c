"""The edge node's ``bdSeq`` across restarts of the process.

Sparkplug 3.0 numbers the MQTT sessions of an edge node: the will of each CONNECT
carries a ``bdSeq`` one above the previous CONNECT's, 255 wrapping to 0, and the
NBIRTH repeats it (tck-id-message-flow-edge-node-birth-publish-will-message-payload-bdSeq,
tck-id-topics-nbirth-bdseq-increment).  A host tells a late will of the last run from
the death of the current one by it.  A process that starts again must therefore go on
from the value of its previous run: the value of each CONNECT is written to
``<folder>/<group_id>-<edge_node_id>.bdseq`` (one line, a decimal number) just before
each connection attempt that may send it, to a temporary file renamed over the old
one, so that a crash leaves the old value or the new one, never half of one.  Written
before, not after: a run that never reaches its broker may leave one number unused (a
host matches a death to its birth by equality: a gap is harmless), and no two sessions
ever carry the same number (a late will would then end the wrong one).

The folder is the store's (``store_dir``) when it is set, else the process's state
folder: ``$STATE_DIRECTORY`` (systemd's ``StateDirectory=``), ``$XDG_STATE_HOME/eskin-bus``,
or ``~/.local/state/eskin-bus``.
"""

from __future__ import annotations

import os
from pathlib import Path


def state_folder(store_dir: str | None) -> Path:
    """Where the ``bdSeq`` file lives: the store's folder, else the process's state folder."""
    if store_dir is not None:
        return Path(store_dir)
    systemd = os.environ.get("STATE_DIRECTORY")
    if systemd:
        return Path(systemd.split(":")[0])
    xdg = os.environ.get("XDG_STATE_HOME")
    base = Path(xdg) if xdg else Path.home() / ".local" / "state"
    return base / "eskin-bus"


def bdseq_path(store_dir: str | None, group_id: str, edge_node_id: str) -> Path:
    return state_folder(store_dir) / f"{group_id}-{edge_node_id}.bdseq"


def writable(path: Path) -> str | None:
    """None when the ``bdSeq`` file can be kept at ``path``; else why not (one line)."""
    d = path.parent
    while not d.exists() and d != d.parent:  # created on the first write: its first existing parent
        d = d.parent
    if not d.is_dir() or not os.access(d, os.W_OK | os.X_OK):
        return f"{str(d)!r} is not a writable folder"
    if path.exists() and not os.access(path, os.R_OK | os.W_OK):
        return f"{str(path)!r} is not readable and writable"
    return None


class BdSeqFile:
    """The ``bdSeq`` of the newest CONNECT, on disk; in memory only when the file
    cannot be kept (:attr:`error` says why)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.error = writable(path)

    def previous(self) -> int | None:
        """The value the previous run's newest CONNECT carried; None when there is none
        (or the file is unreadable: a first start)."""
        try:
            text = self.path.read_text(encoding="ascii").strip()
        except (OSError, UnicodeDecodeError):
            return None
        return int(text) if text.isdigit() and int(text) <= 255 else None

    def first(self) -> int:
        """This run's first ``bdSeq``: one above the previous run's newest, else 0."""
        prev = self.previous()
        return 0 if prev is None else (prev + 1) & 0xFF

    def write(self, value: int) -> str | None:
        """Keep ``value`` (before the CONNECT that carries it); the error, if any."""
        if self.error is not None:
            return self.error
        tmp = self.path.with_name(self.path.name + ".tmp")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            with open(tmp, "w", encoding="ascii") as f:
                f.write(f"{value}\n")
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, self.path)
        except OSError as exc:
            return f"{str(self.path)!r}: {exc.strerror or exc}"
        return None
