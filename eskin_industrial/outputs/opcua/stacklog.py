"""What asyncua itself logs (a connection refused at the cap, a client that never
activated its session, a session timed out, a malformed message), counted and
reported as the output's events instead of free text on stderr."""

from __future__ import annotations

import logging

from .report import Report

#: asyncua's log lines that are news, by what they start with: (counter, event).
_STACK_LINES = (
    ("Refusing connection", "connections_refused", "opcua_connection_refused"),
    ("Closing idle connection", "activation_timeouts", "opcua_activation_timeout"),
    ("Session ", "sessions_timed_out", "opcua_session_timeout"),
    ("Got malformed header", "malformed", "opcua_malformed"),
    ("Exception raised while processing message", "malformed", "opcua_malformed"),  # a message that does not decode
    ("sending service fault", "service_faults", ""),
)


class StackLog(logging.Handler):
    """asyncua's warnings and errors, and its session timeouts (logged at INFO), to the
    server's counters and events instead of stderr; while attached, nothing of asyncua
    reaches the root logger (a JSON log stays JSON)."""

    _LOGGERS = {"asyncua": logging.WARNING, "asyncua.server.internal_session": logging.INFO}

    def __init__(self, report: Report) -> None:
        super().__init__(logging.INFO)
        self.report = report
        self._saved: dict[str, tuple[int, bool]] = {}

    def emit(self, record: logging.LogRecord) -> None:
        try:
            self.take(record)
        except Exception:  # noqa: BLE001 - a log line must not break the server
            pass

    def take(self, record: logging.LogRecord) -> None:
        """One of asyncua's log lines (the server's thread, or another in-process one)."""
        r = self.report
        message = record.getMessage()
        for head, counter, event in _STACK_LINES:
            if message.startswith(head):
                if head == "Session " and "idle past" not in message:
                    return
                r.counts[counter] += 1
                if event:
                    r.log_once(event, "warning", detail=message[:200])
                return
        if record.levelno >= logging.ERROR:
            r.counts["stack_errors"] += 1
            r.log_once("opcua_stack_error", "error", detail=message[:200])
        elif record.levelno >= logging.WARNING:
            r.counts["stack_warnings"] += 1
            r.log_once("opcua_stack_warning", "warning", detail=message[:200])

    def attach(self) -> None:
        for name, level in self._LOGGERS.items():
            log = logging.getLogger(name)
            self._saved[name] = (log.level, log.propagate)
            log.setLevel(level)
        root = logging.getLogger("asyncua")
        root.addHandler(self)
        root.propagate = False

    def detach(self) -> None:
        logging.getLogger("asyncua").removeHandler(self)
        for name, (level, propagate) in self._saved.items():
            log = logging.getLogger(name)
            log.setLevel(level)
            log.propagate = propagate
        self._saved.clear()
