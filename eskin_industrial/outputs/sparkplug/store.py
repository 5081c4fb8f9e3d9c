"""Store-and-forward for the Sparkplug edge node: the data messages of an outage,
held in a bounded queue on disk and sent again, as historical metrics, once the
broker is back and the births have gone out.

The queue is one SQLite table (``held``: serial, device, alias base, timestamp,
payload) in ``<store_dir>/<group_id>-<edge_node_id>.sqlite3``: one file, written in
transactions, readable after a crash, and left behind by a bridge that stops while
the broker is away, so the next start sends what it holds.  With no ``store_dir`` the
same table lives in memory (an outage is covered, a restart is not).

Threads: the loop's thread only appends to a deque (:meth:`Forwarder.hold`, no I/O);
the forwarder's own thread writes the deque to the table, and while the edge node is
connected reads the table in order and hands each row to the node
(``send(device, base, body) -> bool``), then deletes what went out.  The bound counts
rows: a message that finds the table full is counted (``overflow``) and dropped (the
newest goes: the births after the outage carry the newest values, so the history
kept is the outage's start without a hole).

A file that cannot be opened or written (a full disk, a read-only or failing file
system, a folder that cannot be made) never stops the node: the store goes on in
memory with the same bound (:meth:`Forwarder._to_memory`), said in one line
(``sparkplug_store_in_memory``: the file, the OS error, the rows left in it) and
counted (``sparkplug_store_in_memory`` 1).  The rows already in the file stay there,
untouched: the next start that opens the file sends them (a chunk sent in the moment
the file failed, its rows not yet deleted, is sent again then: historical, with the
times it was made).  A message the failing write carried goes to memory instead; past
the bound it is counted as ``sparkplug_store_overflow``, as ever; what memory holds
when the bridge stops is lost, as without ``store_dir``.
"""

from __future__ import annotations

import collections
import contextlib
import os
import sqlite3
import threading
import urllib.parse
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import NamedTuple

from . import payload as pb


class Held(NamedTuple):
    """One data message held for later: its metrics as they were sent (by alias), or
    already encoded as historical (``body``, read back from the table)."""

    serial: int  #: production order across the edge node (the replay order)
    device: str
    base: int  #: the device's alias base when it was produced
    ts: int  #: ms since the epoch, when it was produced
    metrics: tuple[pb.Metric, ...] = ()
    body: bytes | None = None


def historical(held: Held) -> bytes:
    """The metrics of a held message's DDATA, without the payload's timestamp and
    ``seq`` (appended when it is sent, the time of sending and the next number:
    protobuf fields may come in any order): every metric ``is_historical`` with the
    time it was produced, by alias, without its datatype (as any data message).

    A row written by an earlier version carries a payload timestamp of its own (the
    production time): the one appended at sending comes later, and protobuf's last
    value of a field wins."""
    if held.body is not None:
        return held.body
    ts = held.ts
    return pb.encode(pb.Payload(None, tuple(pb.Metric(None, m.alias, ts, m.datatype, m.value, is_historical=True)
                                            for m in held.metrics)), datatypes=False)


_SCHEMA = ("CREATE TABLE IF NOT EXISTS held (serial INTEGER PRIMARY KEY, device TEXT NOT NULL, "
           "base INTEGER NOT NULL, ts INTEGER NOT NULL, body BLOB NOT NULL)")


def store_path(store_dir: str | None, group_id: str, edge_node_id: str) -> str:
    return ":memory:" if store_dir is None else str(Path(store_dir) / f"{group_id}-{edge_node_id}.sqlite3")


#: Bytes a probe writes to learn the file system's own answer (SQLite names no errno).
PROBE_BYTES = 1 << 20


def os_error(path: str, exc: BaseException) -> str:
    """The OS error behind a store that failed, one line: an ``OSError``'s own, else
    (SQLite says only ``disk I/O error``) what the file system answers to a write of
    our own beside the file: ``File too large``, ``No space left on device``, ..."""
    if isinstance(exc, OSError):
        return exc.strerror or str(exc)
    probe = Path(path).with_name(Path(path).name + ".probe")
    try:
        fd = os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        try:
            block, done = b"\0" * 65536, 0
            while done < PROBE_BYTES:
                done += os.write(fd, block)
            os.fsync(fd)
        finally:
            os.close(fd)
            with contextlib.suppress(OSError):
                os.unlink(probe)
    except OSError as probe_exc:
        return f"{probe_exc.strerror or probe_exc} (sqlite: {exc})"
    return f"sqlite: {exc}"


def _rows_in(path: str) -> int:
    """Rows a file holds, read only (0 when it cannot be read: none that we know of)."""
    try:
        uri = f"file:{urllib.parse.quote(path)}?mode=ro"
        with contextlib.closing(sqlite3.connect(uri, uri=True)) as db:
            return int(db.execute("SELECT COUNT(*) FROM held").fetchone()[0])
    except sqlite3.Error:
        return 0


def _connect(path: str) -> sqlite3.Connection:
    if path != ":memory:":
        Path(path).parent.mkdir(parents=True, exist_ok=True)
    db = sqlite3.connect(path, check_same_thread=False, isolation_level=None)
    try:
        db.execute("PRAGMA journal_mode=WAL" if path != ":memory:" else "PRAGMA journal_mode=MEMORY")
        db.execute("PRAGMA synchronous=NORMAL")
        if path == ":memory:":
            db.execute("PRAGMA temp_store=MEMORY")  # no file at all, not even a temporary one
        db.execute(_SCHEMA)
    except BaseException:
        db.close()
        raise
    return db


class Forwarder:
    """The bounded queue and the thread that fills it and drains it."""

    CHUNK = 200  #: rows read and sent per round (the node's lock is taken per message)

    def __init__(self, path: str, bound: int, send: Callable[[int, str, int, bytes], bool | None],
                 connected: Callable[[], bool], event: Callable[..., None] | None = None,
                 drained: Callable[[], None] | None = None) -> None:
        self.path = path
        self.bound = bound
        self._send = send
        self._connected = connected
        self._log = event or (lambda *a, **k: None)
        self._drained = drained
        self.incoming: collections.deque[Held] = collections.deque()
        self.held = self.overflow = self.forwarded = self.discarded = self.failures = 0
        self.on_disk = path != ":memory:"  #: the table is the file (False: in memory, by choice or fallback)
        #: Why the file was given up for memory ("" while it was not): the OS error, one line.
        self.fallback = ""
        self.left_on_disk = 0  #: rows the file held when it was given up (the next start sends them)
        self._fallback_logged = False
        # Opened here, used by the forwarder's thread only after start (never at once).
        try:
            self.db = _connect(path)
            self.rows = int(self.db.execute("SELECT COUNT(*) FROM held").fetchone()[0])
            #: The next serial: after anything a previous run left behind.
            self.next_serial = int(self.db.execute("SELECT COALESCE(MAX(serial), -1) FROM held").fetchone()[0]) + 1
        except (sqlite3.Error, OSError) as exc:  # a full disk at start: the node runs, the store in memory
            self.rows = self.next_serial = 0
            self._to_memory(exc, None, _rows_in(path))
        self._outage_overflow = self._outage_held = self._outage_sent = 0
        self._wake = threading.Event()
        self._stop = False
        self._thread = threading.Thread(target=self._run, name="sparkplug-store", daemon=True)
        self._lock = threading.Lock()  #: the table, between the thread and close

    # -- any thread ---------------------------------------------------------------------
    def hold(self, item: Held) -> None:
        """Queue a message for the table (the loop's thread: an append, no I/O)."""
        self.incoming.append(item)
        self._wake.set()

    def wake(self) -> None:
        self._wake.set()

    @property
    def where(self) -> str:
        """Where the table is, for the log: the file, or ``:memory:`` once it was given up."""
        return self.path if self.on_disk else ":memory:"

    @property
    def pending(self) -> int:
        return self.rows + len(self.incoming)

    def start(self) -> Forwarder:
        self._log_fallback()  # a file given up at start: said once the node's log is there
        self._thread.start()
        return self

    # -- the file given up ----------------------------------------------------------------
    def _to_memory(self, exc: BaseException, old: sqlite3.Connection | None, left: int) -> None:
        """Go on in memory, with the same bound, after the file failed (``old``: its
        connection, closed; ``left``: the rows it holds, left there)."""
        self.fallback = os_error(self.path, exc)
        self.left_on_disk = left
        self.on_disk = False
        if old is not None:
            with contextlib.suppress(sqlite3.Error):
                if old.in_transaction:
                    old.execute("ROLLBACK")
            with contextlib.suppress(sqlite3.Error):
                old.close()
        self.db = _connect(":memory:")
        self.rows = 0

    def _log_fallback(self) -> None:
        if self.fallback and not self._fallback_logged:
            self._fallback_logged = True
            self._log("sparkplug_store_in_memory", "error", store=self.path, error=self.fallback,
                      left_on_disk=self.left_on_disk, bound=self.bound)

    def stop(self, timeout_s: float = 2.0) -> None:
        """Stop the thread (what it holds stays held)."""
        self._stop = True
        self._wake.set()
        if self._thread.is_alive():
            self._thread.join(timeout_s)

    def close(self) -> None:
        """Stop, write what is still queued to the table, close the file."""
        self.stop()
        with self._lock:
            self._persist()
            self.db.close()

    # -- the forwarder's thread -----------------------------------------------------------
    def _run(self) -> None:
        while not self._stop:
            self._wake.wait(0.5)
            self._wake.clear()
            with self._lock:
                if self._stop:
                    return
                try:
                    self._persist()
                    while self.rows and self._connected() and not self._stop:
                        if not self._drain_chunk():
                            break
                except sqlite3.Error as exc:  # a full disk, a broken file: logged, the thread goes on
                    self.failures += 1
                    if self.on_disk:  # the file: given up for memory, what it holds left in it
                        self._to_memory(exc, self.db, self.rows)
                        self._log_fallback()
                        self._wake.set()
                        continue
                    if self.failures == 1 or self.failures % 1000 == 0:
                        self._log("sparkplug_store_failed", "error", store=self.where, error=str(exc),
                                  failures=self.failures)
                    self._wake.wait(1.0)

    def _persist(self) -> None:
        if not self.incoming:
            return
        rows: list[tuple[int, str, int, int, bytes]] = []
        # (a batch a failed write loses is counted as overflow: taken off the deque first)
        while self.incoming:
            item = self.incoming.popleft()
            if self.rows + len(rows) >= self.bound:
                self.overflow += 1
                self._outage_overflow += 1
                if self._outage_overflow == 1:
                    self._log("sparkplug_store_full", "warning", bound=self.bound, store=self.where)
                continue
            rows.append((item.serial, item.device, item.base, item.ts, historical(item)))
        if rows:
            if self._outage_held == 0:
                self._log("sparkplug_store_holding", "warning", store=self.where, bound=self.bound)
            self._outage_held += len(rows)
            try:
                self._insert(rows)
            except sqlite3.Error as exc:
                if not self.on_disk:
                    self.overflow += len(rows)
                    with contextlib.suppress(sqlite3.Error):  # (beyond use: the next write says so again)
                        if self.db.in_transaction:
                            self.db.execute("ROLLBACK")
                    raise
                # The file failed: the same rows in memory (within the bound: fewer than before)
                self.failures += 1
                self._to_memory(exc, self.db, self.rows)
                self._log_fallback()
                self._insert(rows)
            self.rows = int(self.db.execute("SELECT COUNT(*) FROM held").fetchone()[0])
            self.held += len(rows)

    def _insert(self, rows: list[tuple[int, str, int, int, bytes]]) -> None:
        self.db.execute("BEGIN")
        # OR REPLACE: a message sent but never acknowledged comes back with its serial
        self.db.executemany("INSERT OR REPLACE INTO held VALUES (?, ?, ?, ?, ?)", rows)
        self.db.execute("COMMIT")

    def _drain_chunk(self) -> bool:
        """Send the oldest rows; False when the connection went (the rest stay)."""
        chunk: Sequence[tuple[int, str, int, bytes]] = self.db.execute(
            "SELECT serial, device, base, body FROM held ORDER BY serial LIMIT ?", (self.CHUNK,)).fetchall()
        done: list[tuple[int]] = []
        ok = True
        for serial, device, base, body in chunk:
            sent = self._send(serial, device, base, bytes(body))
            if sent is False:  # not connected: stop here, in order
                ok = False
                break
            if sent is None:  # no such device (now): counted, dropped
                self.discarded += 1
            else:
                self.forwarded += 1
                self._outage_sent += 1
            done.append((serial,))
        if done:
            self.db.execute("BEGIN")
            self.db.executemany("DELETE FROM held WHERE serial = ?", done)
            self.db.execute("COMMIT")
            self.rows -= len(done)
        if ok and not self.rows and not self.incoming:
            self._log("sparkplug_store_forwarded", "info", forwarded=self._outage_sent,
                      overflow=self._outage_overflow, discarded=self.discarded)
            self._outage_held = self._outage_overflow = self._outage_sent = 0
            if self._drained is not None:
                self._drained()
        return ok
