"""Structured logs for a bridge that runs for months: one event per line, plain or JSON.

Every line is an *event* with named fields (``event=state node=left state=slip``),
so that a journal can be searched and a log shipper can parse it.  The loops that
decode and detect never write to the stream themselves: they put records on a
bounded queue that a separate thread writes out.  A stream that blocks (a full pipe,
a slow terminal) costs dropped log lines, counted in ``log_drops``, never detection.

Configured by the command, never at import time.
"""

from __future__ import annotations

import datetime as dt
import json
import logging
import logging.handlers
import math
import queue
from typing import IO, Any

LOGGER = "eskin_industrial.bridge"
#: The package's own loggers (a part with no access to the EventLog, as the Modbus
#: server's thread, logs there: the record's message is the event's name, its
#: ``fields`` extra the event's fields); an EventLog writes them out with its own.
PACKAGE_LOGGER = "eskin_industrial"
#: Records waiting for the writer thread; beyond it they are dropped and counted.
QUEUE_RECORDS = 10_000


def _utc(record: logging.LogRecord) -> str:
    t = dt.datetime.fromtimestamp(record.created, dt.UTC)
    return t.strftime("%Y-%m-%dT%H:%M:%S.") + f"{t.microsecond // 1000:03d}Z"


def _plain_value(v: Any) -> str:
    text = f"{v:.4g}" if isinstance(v, float) else str(v)
    return json.dumps(text) if (not text or any(c in text for c in " =\"")) else text


class PlainFormatter(logging.Formatter):
    """``2026-11-22T10:00:00.123Z info  state node=left state=slip``."""

    def format(self, record: logging.LogRecord) -> str:
        fields = getattr(record, "fields", {})
        body = " ".join(f"{k}={_plain_value(v)}" for k, v in fields.items())
        return f"{_utc(record)} {record.levelname.lower():7s} {record.getMessage()}" + (f" {body}" if body else "")


class JsonFormatter(logging.Formatter):
    """One JSON object per line: ``ts``, ``level``, ``event``, then the event's fields."""

    def format(self, record: logging.LogRecord) -> str:
        out: dict[str, Any] = {"ts": _utc(record), "level": record.levelname.lower(), "event": record.getMessage()}
        for k, v in getattr(record, "fields", {}).items():
            # NaN and infinity are not JSON: null, so that every line parses.
            out[k] = None if isinstance(v, float) and not math.isfinite(v) else v
        return json.dumps(out, default=str)


class _DroppingQueueHandler(logging.handlers.QueueHandler):
    """Never blocks the caller: a full queue drops the record and counts it."""

    def __init__(self, q: queue.Queue, log: EventLog) -> None:
        super().__init__(q)
        self._log = log

    def enqueue(self, record: logging.LogRecord) -> None:
        try:
            self.queue.put_nowait(record)
        except queue.Full:
            self._log.drops += 1

    def prepare(self, record: logging.LogRecord) -> logging.LogRecord:
        return record  # the fields travel as they are; the writer formats them


class _Listener(logging.handlers.QueueListener):
    # The standard listener accepts any object with get/put_nowait; EventLog always
    # hands it a queue.Queue, whose blocking put stop_within needs.  Its end marker is
    # an undeclared class attribute of the standard listener.
    queue: queue.Queue[Any]
    _sentinel: None

    def stop_within(self, timeout_s: float) -> None:
        """``stop()``, bounded: the standard one puts its end marker with
        ``put_nowait`` (``queue.Full`` when a blocked stream has let the queue fill)
        and then joins for ever; a bridge's shutdown must neither raise nor hang on
        its log.  A stream that does not move for ``timeout_s`` is given up."""
        try:
            self.queue.put(self._sentinel, timeout=timeout_s)
        except queue.Full:
            return
        if self._thread is not None:
            self._thread.join(timeout_s)
            self._thread = None


class EventLog:
    """``event(name, level, **fields)`` from any thread; :meth:`close` flushes."""

    def __init__(self, stream: IO[str], fmt: str = "plain", level: str = "info") -> None:
        self.drops = 0
        self.logger = logging.getLogger(f"{LOGGER}.{id(self)}")
        self.logger.setLevel(level.upper())
        self.logger.propagate = False
        out = logging.StreamHandler(stream)
        out.setFormatter(JsonFormatter() if fmt == "json" else PlainFormatter())
        q: queue.Queue = queue.Queue(maxsize=QUEUE_RECORDS)
        self._handler = _DroppingQueueHandler(q, self)
        self.logger.addHandler(self._handler)
        package = logging.getLogger(PACKAGE_LOGGER)
        self._package_level = package.level  # given back at close
        package.setLevel(level.upper())
        package.addHandler(self._handler)
        self._listener = _Listener(q, out)
        self._listener.start()

    def event(self, name: str, level: str = "info", **fields: Any) -> None:
        lvl = logging.getLevelName(level.upper())
        if self.logger.isEnabledFor(lvl):
            self.logger.log(lvl, name, extra={"fields": fields})

    def close(self, timeout_s: float = 5.0) -> None:
        """Write out what is queued (waiting at most ``timeout_s`` for a blocked stream)."""
        self.logger.removeHandler(self._handler)
        package = logging.getLogger(PACKAGE_LOGGER)
        package.removeHandler(self._handler)
        package.setLevel(self._package_level)
        self._listener.stop_within(timeout_s)
