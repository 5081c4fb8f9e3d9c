"""A Modbus TCP server of our own, on a background thread: the PDUs are answered by
:mod:`.pdu` (pure), the frames split and built by :mod:`.mbap` (pure); this module
moves the bytes and applies the :class:`Policy`.

- Every complete request in the receive buffer is answered, in order: requests sent
  back to back in one TCP segment each get their response.
- At most ``max_connections`` at once.  A connection beyond the cap replaces, first,
  the oldest connection that has sent no whole request yet (a socket that holds a
  slot and says nothing: connections opened and replaced faster than any quiet time
  must not keep a reconnecting PLC out); else the one idle the longest, if that one
  has been quiet for :data:`EVICT_IDLE_S` or more (an idle socket left behind, never
  a PLC that polls); otherwise it is closed at once.  The PLC's slot is kept: a
  client on ``allow_write`` (the PLC, when the list names it) always gets in, and
  replaces the quietest connection that is not on ``allow_write``; with no
  ``allow_write``, the longest-established connection that has sent requests is the
  PLC's, and never replaced.
- A connection quiet for ``idle_timeout_s`` is closed.  Only whole requests are
  activity: bytes of a frame never completed are not, and a frame still incomplete
  after ``frame_timeout_s`` closes its connection (one byte a second keeps no socket).
- Fair service: at most ``max_batch`` requests of one connection are answered in a
  turn of the server's loop, the rest after every other connection has had its turn
  (its reading paused meanwhile, so TCP holds the client back); at most
  ``max_unread_bytes`` of answers a client has not read are buffered (the kernel's
  send buffer set to as much), beyond it the client is not read either, and a
  client that leaves its answers unread for ``unread_timeout_s`` is closed.
- ``allow_read`` / ``allow_write``: the client addresses (or networks) that may
  connect and read, and that may write; empty: any.  A client in neither list is
  closed at once; a write from a client that may not write, or any write in
  ``read_only`` mode, is answered with exception 01 (ILLEGAL FUNCTION).
- ``unit_ids``: the unit ids served; a request to another is answered with exception
  0x0B (gateway target device failed to respond).
- A frame header no Modbus TCP client sends closes its connection.

Every refusal is counted (:attr:`TcpServer.counters`) and logged; the log lines (and
whatever asyncio reports) go to the standard logger :data:`LOG` as structured events,
at most one line per event name per :data:`.serving.LOG_EVERY_S`, the next line saying
how many were held back.
"""

from __future__ import annotations

import asyncio
import contextvars
import ipaddress
import logging
import socket
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from ..errors import DecodeError, EskinError, ListenError
from ..netaddr import listen_error
from . import mbap, pdu
from .exception_codes import GATEWAY_TARGET_FAILED, ILLEGAL_FUNCTION
from .serving import RateLimitedLog, answer

Network = ipaddress.IPv4Network | ipaddress.IPv6Network
Address = ipaddress.IPv4Address | ipaddress.IPv6Address

LOG = logging.getLogger(__name__)
#: At the connection cap, a connection quiet this long may be replaced by a new one.
EVICT_IDLE_S = 1.0
#: The client whose request is being answered (for a handler's log line).
PEER: contextvars.ContextVar[str] = contextvars.ContextVar("modbus_peer", default="-")


def networks(entries: Sequence[str], key: str = "allow") -> tuple[Network, ...]:
    """Addresses or networks (``10.0.0.5``, ``10.0.0.0/24``, ``::1``); ValueError
    ``key: ...`` naming the first entry that is neither."""
    out = []
    for entry in entries:
        try:
            out.append(ipaddress.ip_network(entry, strict=False))
        except ValueError:
            raise ValueError(f"{key}: {entry!r} is not an IP address or network") from None
    return tuple(out)


@dataclass(frozen=True)
class Policy:
    """Who may do what; see the module's docstring."""

    max_connections: int = 8
    idle_timeout_s: float = 60.0
    allow_read: tuple[Network, ...] = ()
    allow_write: tuple[Network, ...] = ()
    read_only: bool = False
    unit_ids: frozenset[int] | None = None  #: None: every unit id
    #: Requests of one connection answered in one turn; the rest wait for the next.
    max_batch: int = 8
    #: Answers a client has not read, buffered at most (bytes; the kernel's send
    #: buffer is set to as much, which the kernel doubles for its own bookkeeping).
    max_unread_bytes: int = 8192
    #: A client that leaves its answers unread this long is closed.
    unread_timeout_s: float = 5.0
    #: A frame still incomplete this long after its first byte closes its connection.
    frame_timeout_s: float = 2.0

    def may_connect(self, ip: Address) -> bool:
        if not self.allow_read:
            return True
        return _within(ip, self.allow_read) or (bool(self.allow_write) and _within(ip, self.allow_write))

    def kept_slot(self, ip: Address) -> bool:
        """A client named by ``allow_write`` (the PLC): it gets in at the cap."""
        return bool(self.allow_write) and _within(ip, self.allow_write)

    def may_write(self, ip: Address) -> bool:
        if self.read_only:
            return False
        return not self.allow_write or _within(ip, self.allow_write)


def _within(ip: Address, nets: tuple[Network, ...]) -> bool:
    return any(ip in n for n in nets)


def _peer_ip(peer: Any) -> Address | None:
    try:
        ip = ipaddress.ip_address(peer[0])
    except (TypeError, ValueError, IndexError):
        return None
    mapped = getattr(ip, "ipv4_mapped", None)  # a dual-stack socket's IPv4 client
    return mapped if mapped is not None else ip


@dataclass
class Counters:
    connections: int = 0  #: accepted
    refused_connections: int = 0  #: not in the allow-lists
    over_cap: int = 0  #: closed at once: the cap was reached and nobody idle to replace
    evicted: int = 0  #: replaced by a new connection at the cap
    idle_closed: int = 0
    partial_closed: int = 0  #: closed for a frame left incomplete past ``frame_timeout_s``
    unread_closed: int = 0  #: closed for answers left unread past ``unread_timeout_s``
    deferred: int = 0  #: turns in which a connection had more than ``max_batch`` requests
    malformed: int = 0  #: connections closed for a frame header no client sends
    requests: int = 0
    denied_writes: int = 0  #: read-only mode, or a client not allowed to write
    wrong_unit: int = 0
    handler_errors: int = 0
    asyncio_errors: int = 0

    def as_dict(self) -> dict[str, int]:
        return {f"modbus_{k}": v for k, v in vars(self).items()}


class _Connection(asyncio.Protocol):
    def __init__(self, server: TcpServer) -> None:
        self.server = server
        self.transport: asyncio.Transport | None = None
        self.buf = bytearray()
        self.since = self.last = time.monotonic()  #: the last whole request (or the connection's start)
        self.served = 0  #: whole requests answered
        self.partial_since: float | None = None  #: the first byte of a frame not yet complete
        self.unread_since: float | None = None  #: answers left unread past the limit, since
        self.backlog = False  #: requests left for the next turn
        self.peer = "-"
        self.may_write = False
        self.kept = False  #: on allow_write: never replaced to let another in
        self.ip: Address | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport
        peer = transport.get_extra_info("peername")
        self.peer = f"{peer[0]}:{peer[1]}" if isinstance(peer, tuple) else str(peer)
        limit = self.server.policy.max_unread_bytes
        transport.set_write_buffer_limits(high=limit)
        sock = transport.get_extra_info("socket")
        if sock is not None:  # else the kernel grows it to megabytes of unread answers
            try:
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, limit)
            except OSError:
                pass
        self.server.admit(self, _peer_ip(peer))

    def data_received(self, data: bytes) -> None:
        self.buf += data
        if not self.backlog:
            self._serve()

    def _serve(self) -> None:
        """Answer up to ``max_batch`` whole requests, in order, in one send."""
        self.backlog = False
        transport = self.transport
        if transport is None or transport.is_closing():
            return
        buf = self.buf
        out: list[bytes] = []
        bad = ""
        limit = self.server.policy.max_batch
        while len(buf) >= mbap.HEADER_BYTES:
            try:
                need = mbap.frame_length(bytes(buf[:mbap.HEADER_BYTES]))
            except DecodeError as exc:
                bad = str(exc)
                break
            if len(buf) < need:
                break
            if len(out) == limit:  # more than a turn's share: the rest after the others
                self.backlog = True
                break
            request = bytes(buf[:need])
            del buf[:need]
            out.append(self.server.answer(request, self))
        now = time.monotonic()
        if out:
            self.last = now
            self.served += len(out)
            transport.write(b"".join(out))  # the answers, in order, in one send
        if bad:  # the requests before it are answered; the stream cannot be resynchronised
            self.server.malformed(self, bad)
            return
        if self.backlog:
            self.server.counters.deferred += 1
            self.partial_since = None
            asyncio.get_running_loop().call_soon(self._next_turn)
        elif buf:
            if self.partial_since is None or out:
                self.partial_since = now
        else:
            self.partial_since = None
        self._reading()

    def _next_turn(self) -> None:
        if self.unread_since is None:  # else resume_writing serves the rest
            self._serve()

    def _reading(self) -> None:
        """Read the client only while it has no backlog and reads its answers."""
        transport = self.transport
        if transport is None or transport.is_closing():
            return
        if self.backlog or self.unread_since is not None:
            transport.pause_reading()
        else:
            transport.resume_reading()

    def pause_writing(self) -> None:  # the client does not read its answers: stop reading it
        self.unread_since = time.monotonic()
        self._reading()

    def resume_writing(self) -> None:
        self.unread_since = None
        if self.backlog:
            self._serve()
        else:
            self._reading()

    def connection_lost(self, exc: Exception | None) -> None:
        self.server.conns.discard(self)

    def close(self, flush: bool = False) -> None:
        """Abort (an idle or refused peer gets no goodbye), or with ``flush`` close
        once the answers already written have gone out."""
        if self.transport is not None:
            if flush:
                self.transport.close()
            else:
                self.transport.abort()
        self.server.conns.discard(self)


class TcpServer:
    """Serves ``handler`` over Modbus TCP on ``host:port`` from its own thread;
    ``start()`` returns once it listens."""

    def __init__(self, handler: pdu.RegisterHandler, host: str, port: int, identity: pdu.Identity,
                 policy: Policy | None = None, server_id: int = 1) -> None:
        self.handler = handler
        self.host, self.port = host, port
        self.identity = identity
        self.policy = policy or Policy()
        self.server_id = server_id
        self.counters = Counters()
        self.log = RateLimitedLog(LOG)
        self.conns: set[_Connection] = set()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stopping: asyncio.Event | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None

    @property
    def tcp(self) -> tuple[str, int]:
        return self.host, self.port

    @property
    def where(self) -> str:
        return f"tcp {self.host}:{self.port}"

    # -- the policy, on the server's thread ------------------------------------------
    def admit(self, conn: _Connection, ip: Address | None) -> None:
        p, c = self.policy, self.counters
        if ip is None or not p.may_connect(ip):
            c.refused_connections += 1
            self.log.event("modbus_client_refused", peer=conn.peer, reason="not in allow_read")
            conn.close()
            return
        conn.kept, conn.ip = p.kept_slot(ip), ip
        if len(self.conns) >= p.max_connections:
            now = time.monotonic()
            victim, why = self._room_for(conn, now)
            if victim is None:
                c.over_cap += 1
                self.log.event("modbus_client_refused", peer=conn.peer, reason="connection cap",
                               max_connections=p.max_connections)
                conn.close()
                return
            c.evicted += 1
            self.log.event("modbus_client_evicted", level=logging.INFO, peer=victim.peer, reason=why,
                           idle_s=round(now - victim.last, 1), by=conn.peer)
            victim.close()
        conn.may_write = p.may_write(ip)
        self.conns.add(conn)
        c.connections += 1

    def _room_for(self, conn: _Connection, now: float) -> tuple[_Connection | None, str]:
        """The connection a newcomer at the cap replaces, and why; None: none may go."""
        others = [k for k in self.conns if not k.kept]
        silent = [k for k in others if not k.served]
        if silent:  # holds a slot and has asked nothing: the oldest such goes first
            return min(silent, key=lambda k: k.since), "silent"
        if conn.kept and others:  # the PLC's slot: the quietest of the others makes room
            return min(others, key=lambda k: k.last), "plc_slot"
        if not self.policy.allow_write and others:
            # no PLC named: the longest-established connection that asks is the PLC's,
            # replaced only by its own address (the PLC back after a cable fault, its
            # old connection dead and quiet)
            plc = min(others, key=lambda k: k.since)
            if plc.ip != conn.ip:
                others.remove(plc)
        if others:
            quietest = min(others, key=lambda k: k.last)
            if now - quietest.last >= EVICT_IDLE_S:
                return quietest, "idle"
        return None, ""

    def answer(self, request: bytes, conn: _Connection) -> bytes:
        tid, unit, req = mbap.split_request(request)
        fc = req[0] if req else 0
        c = self.counters
        c.requests += 1
        units = self.policy.unit_ids
        if units is not None and unit not in units:
            c.wrong_unit += 1
            self.log.event("modbus_unit_refused", peer=conn.peer, unit=unit, served=",".join(map(str, sorted(units))))
            return mbap.frame(tid, unit, pdu.exception(fc, GATEWAY_TARGET_FAILED))
        if fc in pdu.WRITES and not conn.may_write:
            c.denied_writes += 1
            self.log.event("modbus_write_denied", peer=conn.peer, function=fc,
                           reason="read_only" if self.policy.read_only else "not in allow_write")
            return mbap.frame(tid, unit, pdu.exception(fc, ILLEGAL_FUNCTION))
        token = PEER.set(conn.peer)
        try:
            resp = answer(req, self.handler, self.identity, self.server_id, self.log, c)
        finally:
            PEER.reset(token)
        return mbap.frame(tid, unit, resp)

    def malformed(self, conn: _Connection, why: str) -> None:
        self.counters.malformed += 1
        self.log.event("modbus_client_malformed", peer=conn.peer, error=why)
        conn.buf.clear()
        conn.close(flush=True)

    def _sweep(self) -> None:
        p, c = self.policy, self.counters
        now = time.monotonic()
        for conn in list(self.conns):
            if conn.partial_since is not None and now - conn.partial_since >= p.frame_timeout_s:
                c.partial_closed += 1
                self.log.event("modbus_client_partial_frame", peer=conn.peer, pending_bytes=len(conn.buf),
                               frame_timeout_s=p.frame_timeout_s)
            elif conn.unread_since is not None and now - conn.unread_since >= p.unread_timeout_s:
                c.unread_closed += 1
                self.log.event("modbus_client_not_reading", peer=conn.peer, unread_timeout_s=p.unread_timeout_s,
                               max_unread_bytes=p.max_unread_bytes)
            elif now - conn.last >= p.idle_timeout_s:
                c.idle_closed += 1
                self.log.event("modbus_client_idle", level=logging.INFO, peer=conn.peer,
                               idle_timeout_s=p.idle_timeout_s)
            else:
                continue
            conn.close()

    def _asyncio_error(self, loop: asyncio.AbstractEventLoop, context: dict[str, Any]) -> None:
        """asyncio's reports (an accept that fails for lack of descriptors, ...) as
        structured events, rate-limited, never a traceback on stderr."""
        self.counters.asyncio_errors += 1
        exc = context.get("exception")
        self.log.event("modbus_server_error", level=logging.ERROR, message=context.get("message", "-"),
                       error=f"{type(exc).__name__}: {exc}" if exc is not None else "-")

    # -- the thread ---------------------------------------------------------------------
    def start(self, timeout_s: float = 5.0) -> TcpServer:
        self._thread = threading.Thread(target=self._run, name="modbus-server", daemon=True)
        self._thread.start()
        if not self._ready.wait(timeout_s):
            raise EskinError(f"modbus server ({self.where}): did not start within {timeout_s:g} s")
        if isinstance(self._error, OSError):  # in use, not this machine's address, ...: say which
            raise ListenError(listen_error(self.host, self.port, self._error))
        if self._error is not None:
            raise EskinError(f"modbus server ({self.where}): cannot listen: {self._error}")
        return self

    def _run(self) -> None:
        try:
            asyncio.run(self._main())
        except BaseException as exc:  # noqa: BLE001 - reported to start()
            self._error = exc
            self._ready.set()

    async def _main(self) -> None:
        loop = self._loop = asyncio.get_running_loop()
        loop.set_exception_handler(self._asyncio_error)
        self._stopping = asyncio.Event()
        server = await loop.create_server(lambda: _Connection(self), self.host, self.port)
        self._ready.set()
        p = self.policy
        tick = min(1.0, p.idle_timeout_s / 4, p.frame_timeout_s / 4, p.unread_timeout_s / 4)
        try:
            while not self._stopping.is_set():
                try:
                    await asyncio.wait_for(self._stopping.wait(), tick)
                except TimeoutError:
                    self._sweep()
        finally:
            server.close()
            for conn in list(self.conns):
                conn.close()
            await server.wait_closed()

    def stop(self) -> None:
        """Stop serving and close every connection; safe to call twice."""
        loop, stopping = self._loop, self._stopping
        if loop is not None and stopping is not None and not loop.is_closed():
            try:
                loop.call_soon_threadsafe(stopping.set)
            except RuntimeError:  # the loop has just closed
                pass
        if self._thread is not None:
            self._thread.join(timeout=5)
        self._loop = None

    def __enter__(self) -> TcpServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
