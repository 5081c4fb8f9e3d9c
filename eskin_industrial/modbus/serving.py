"""What our two servers share (:mod:`.tcp_server`, :mod:`.rtu_server`): the answer to
one request, which a handler's bug never turns into the end of the server, and their
log lines, structured and rate-limited."""

from __future__ import annotations

import logging
from typing import Any, Protocol

from ..ratelimit import LOG_EVERY_S, Throttle
from . import pdu
from .exception_codes import DEVICE_FAILURE

__all__ = ["LOG_EVERY_S", "HandlerErrors", "RateLimitedLog", "answer"]


class HandlerErrors(Protocol):
    """A server's counters, of which :func:`answer` counts one."""

    handler_errors: int


class RateLimitedLog:
    """Structured events on ``logger`` (the record's message is the event's name, its
    ``fields`` extra the event's fields), at most one per name per ``every_s``; the
    next line of a name says how many were held back."""

    def __init__(self, logger: logging.Logger, every_s: float = LOG_EVERY_S) -> None:
        self.logger = logger
        self.every_s = every_s
        self._throttle = Throttle(every_s)

    def event(self, name: str, level: int = logging.WARNING, **fields: Any) -> None:
        held = self._throttle.passes(name)
        if held is None:
            return
        if held:
            fields["held_back"] = held
        self.logger.log(level, name, extra={"fields": fields})


def answer(req: bytes, handler: pdu.RegisterHandler, identity: pdu.Identity, server_id: int, log: RateLimitedLog,
           counters: HandlerErrors) -> bytes:
    """The response PDU to a request (TCP and RTU alike): a handler that raises is a
    bug, answered SERVER DEVICE FAILURE, counted and logged, never the end of the server."""
    try:
        return pdu.handle(req, handler, identity, server_id)
    except Exception as exc:  # noqa: BLE001 - a handler's bug must not end the server
        counters.handler_errors += 1
        log.event("modbus_handler_error", level=logging.ERROR, function=req[0], error=f"{type(exc).__name__}: {exc}")
        return pdu.exception(req[0], DEVICE_FAILURE)
