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
"""

from __future__ import annotations

import collections
import sqlite3
import threading
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
        if path != ":memory:":
            Path(path).parent.mkdir(parents=True, exist_ok=True)
        # Opened here, used by the forwarder's thread only after start (never at once).
        self.db = sqlite3.connect(path, check_same_thread=False, isolation_level=None)
        self.db.execute("PRAGMA journal_mode=WAL" if path != ":memory:" else "PRAGMA journal_mode=MEMORY")
        self.db.execute("PRAGMA synchronous=NORMAL")
        self.db.execute(_SCHEMA)
        self.rows = int(self.db.execute("SELECT COUNT(*) FROM held").fetchone()[0])
        #: The next serial: after anything a previous run left behind.
        self.next_serial = int(self.db.execute("SELECT COALESCE(MAX(serial), -1) FROM held").fetchone()[0]) + 1
        self.incoming: collections.deque[Held] = collections.deque()
        self.held = self.overflow = self.forwarded = self.discarded = self.failures = 0
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
    def pending(self) -> int:
        return self.rows + len(self.incoming)

    def start(self) -> Forwarder:
        self._thread.start()
        return self

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
                    if self.failures == 1 or self.failures % 1000 == 0:
                        self._log("sparkplug_store_failed", "error", store=self.path, error=str(exc),
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
                    self._log("sparkplug_store_full", "warning", bound=self.bound, store=self.path)
                continue
            rows.append((item.serial, item.device, item.base, item.ts, historical(item)))
        if rows:
            if self._outage_held == 0:
                self._log("sparkplug_store_holding", "warning", store=self.path, bound=self.bound)
            self._outage_held += len(rows)
            try:
                self.db.execute("BEGIN")
                # OR REPLACE: a message sent but never acknowledged comes back with its serial
                self.db.executemany("INSERT OR REPLACE INTO held VALUES (?, ?, ?, ?, ?)", rows)
                self.db.execute("COMMIT")
            except sqlite3.Error:
                self.overflow += len(rows)
                try:
                    if self.db.in_transaction:
                        self.db.execute("ROLLBACK")
                except sqlite3.Error:
                    pass  # (the file is beyond use: the next write says so again)
                raise
            self.rows = int(self.db.execute("SELECT COUNT(*) FROM held").fetchone()[0])
            self.held += len(rows)

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
