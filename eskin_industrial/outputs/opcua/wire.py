"""The OPC UA connection protocol (Part 6, 7.1), answered as the specification says
where asyncua closes the socket without a word, takes what it should refuse, or waits:
an Error message that tells the client why, at once, then the close.

A new socket is held here until its Hello is whole, and is not asyncua's yet: it
counts against no limit, so idle sockets cannot keep a client out.  Then:

- No complete Hello within ``hello_timeout_s``: BadTimeout.
- A first message that is no Hello (garbage, HTTP): BadTcpMessageTypeInvalid, as soon
  as its first bytes say so; a Hello announcing more than a Hello can hold:
  BadTcpMessageTooLarge; one too short for its fields, or whose EndpointUrl does not
  fit in it: BadDecodingError.
- A Hello whose ReceiveBufferSize or SendBufferSize is below 8192 bytes (the least
  a peer may offer without an ECC policy, which this server has not):
  BadTcpMessageTooLarge (this server's smallest chunk is too large for it).
- A Hello whose EndpointUrl is longer than 4096 bytes: BadTcpEndpointUrlInvalid.
- A connection past ``max_sessions``: BadTooManySessions; past ``max_pending``
  connections that have not activated a session yet: BadTcpServerTooBusy (asyncua
  closes such a connection bare at once; the client then reports a broken
  connection, not the cap).

After the Hello, asyncua's: each chunk's header is still checked as it arrives (a
type other than OPN, MSG or CLO: BadTcpMessageTypeInvalid; a size shorter than a
chunk's header or over the receive buffer the Acknowledge agreed:
BadDecodingError, BadTcpMessageTooLarge), where asyncua would wait for the bytes a
lying size announces.

The checks are bytes in, bytes out (:func:`hello_problem`, :func:`first_problem`,
:class:`Chunks`, :func:`error_message`); :class:`GuardedServer` is asyncua's server
with its connections made by :class:`_Protocol`, which applies them before asyncua
sees the bytes.
"""

from __future__ import annotations

import asyncio
import socket
import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from asyncua import Server, ua
from asyncua.crypto import uacrypto
from asyncua.server.binary_server_asyncio import BinaryServer, OPCUAProtocol

#: The least buffer a peer may offer (Part 6, 7.1.2.3; 1024 only with an ECC policy).
MIN_BUFFER = 8192
#: The longest EndpointUrl (Part 6, 7.1.2.3).
MAX_URL = 4096
_HEADER = 8  #: a message's type (3 bytes), chunk type (1) and size (UInt32)
_HELLO_MIN = _HEADER + 24  #: five UInt32 and the EndpointUrl's length
_HELLO_MAX = _HELLO_MIN + 2 * MAX_URL  #: past this no Hello: BadTcpMessageTooLarge
_CHUNK_MIN = _HEADER + 4  #: a chunk after the Hello carries at least its SecureChannelId
_CHUNK_TYPES = (b"OPN", b"MSG", b"CLO")

OnRefused = Callable[[str, str, str], None]  #: (counter, event, detail)
Problem = tuple[int, str]  #: (status code, reason)


@dataclass(frozen=True)
class WireLimits:
    """What a connection may hold before its session is activated."""

    #: Connections at once that have sent their Hello but not activated a session.
    max_pending: int = 8
    #: How long a new socket may take to send a complete Hello.
    hello_timeout_s: float = 2.0


def hello_problem(body: bytes) -> Problem | None:
    """Why a Hello's body (after its 8-byte header) is refused: (status code, reason)."""
    if len(body) < _HELLO_MIN - _HEADER:
        return ua.StatusCodes.BadDecodingError, f"a Hello of {len(body) + _HEADER} bytes, under {_HELLO_MIN}"
    _version, receive, send, _size, _chunks, url_length = struct.unpack_from("<IIIIIi", body)
    if receive < MIN_BUFFER or send < MIN_BUFFER:
        return (ua.StatusCodes.BadTcpMessageTooLarge,
                f"ReceiveBufferSize {receive} or SendBufferSize {send} below {MIN_BUFFER} bytes")
    if url_length > MAX_URL:
        return ua.StatusCodes.BadTcpEndpointUrlInvalid, f"EndpointUrl of {url_length} bytes, over {MAX_URL}"
    if url_length < -1 or url_length > len(body) - 24:
        return (ua.StatusCodes.BadDecodingError,
                f"an EndpointUrl of {url_length} bytes in a Hello with {len(body) - 24} for it")
    return None


def first_problem(head: bytes) -> Problem | None:
    """Why a connection's first bytes are no Hello, as soon as they say so."""
    if not b"HELF".startswith(head[:4]):
        return ua.StatusCodes.BadTcpMessageTypeInvalid, f"a first message of type {head[:4]!r}, not HELF"
    if len(head) < _HEADER:
        return None
    size = struct.unpack_from("<I", head, 4)[0]
    if size > _HELLO_MAX:
        return ua.StatusCodes.BadTcpMessageTooLarge, f"a Hello of {size} bytes announced, over {_HELLO_MAX}"
    if size < _HELLO_MIN:
        return ua.StatusCodes.BadDecodingError, f"a Hello of {size} bytes announced, under {_HELLO_MIN}"
    return None


def chunk_limit(hello_body: bytes, limits: Any) -> int:
    """The largest chunk the client may send after this Hello: the receive buffer the
    Acknowledge agrees (asyncua's ``TransportLimits``, either way it reads them)."""
    _version, receive, send = struct.unpack_from("<III", hello_body)
    return max(min(receive, limits.max_send_buffer), min(send, limits.max_recv_buffer))


class Chunks:
    """The chunk headers of a connection after its Hello, checked as the bytes come."""

    def __init__(self, limit: int) -> None:
        self.limit = limit
        self._left = 0  #: bytes of the current chunk still to come
        self._head = b""  #: a header not yet whole

    def feed(self, data: bytes) -> Problem | None:
        """The problem of the first bad header in ``data``, if any."""
        i, n = 0, len(data)
        while i < n:
            if self._left:
                step = min(self._left, n - i)
                self._left -= step
                i += step
                continue
            take = min(_HEADER - len(self._head), n - i)
            self._head += data[i:i + take]
            i += take
            if len(self._head) < _HEADER:
                return None
            head, self._head = self._head, b""
            if head[:3] not in _CHUNK_TYPES or head[3:4] not in (b"F", b"C", b"A"):
                return ua.StatusCodes.BadTcpMessageTypeInvalid, f"a chunk of type {head[:4]!r}"
            size = struct.unpack_from("<I", head, 4)[0]
            if size > self.limit:
                return ua.StatusCodes.BadTcpMessageTooLarge, f"a chunk of {size} bytes announced, over {self.limit}"
            if size < _CHUNK_MIN:
                return ua.StatusCodes.BadDecodingError, f"a chunk of {size} bytes announced, under {_CHUNK_MIN}"
            self._left = size - _HEADER
        return None


def error_message(code: int, reason: str) -> bytes:
    """An Error message (Part 6, 7.1.2.5): ERRF, its size, the code, the reason."""
    text = reason.encode()
    body = struct.pack("<Ii", code, len(text)) + text
    return b"ERRF" + struct.pack("<I", 8 + len(body)) + body


def _activated(c: OPCUAProtocol) -> bool:
    return c.processor is not None and c.processor.session is not None and c.processor.session.is_activated()


def _kept(task: asyncio.Task[Any]) -> bool:
    """A done closing task is kept for asyncua's cleanup only when it failed (which logs it)."""
    return not task.cancelled() and task.exception() is not None


class _Protocol(OPCUAProtocol):
    """asyncua's connection once its Hello is whole and admitted; until then held here."""

    def __init__(self, *args: Any, on_refused: OnRefused, wire: WireLimits, held: set[_Protocol],
                 **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.on_refused = on_refused
        self.wire = wire
        self.held = held  #: the server's connections still before their Hello (closed at its stop)
        self._socket: asyncio.Transport | None = None  #: until asyncua has it (then ``transport``)
        self._first = b""  #: the bytes until the Hello is whole
        self._chunks: Chunks | None = None  #: once admitted
        self._timer: asyncio.TimerHandle | None = None
        self._done = False  #: refused: nothing more is read

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.peer_name = transport.get_extra_info("peername")
        self._socket = transport  # type: ignore[assignment]
        self.held.add(self)
        self._timer = asyncio.get_running_loop().call_later(self.wire.hello_timeout_s, self._hello_late)

    def connection_lost(self, ex: BaseException | None) -> None:
        self._stop_timer()
        self.held.discard(self)
        self._socket = None
        if self._chunks is not None:
            super().connection_lost(ex)
            # asyncua keeps every closing task until its cleanup, every 10 s, then awaits
            # them all in one go: after a connect/close storm, tens of thousands at once,
            # a stall of the server's loop; the ones done are let go here
            self.closing_tasks[:] = [t for t in self.closing_tasks if not t.done() or _kept(t)]

    def data_received(self, data: bytes) -> None:
        if self._done:
            return
        if self._chunks is not None:
            problem = self._chunks.feed(data)
            if problem is not None:
                self._refuse("malformed", "opcua_malformed", *problem)
                return
            super().data_received(data)
            return
        self._first += data
        problem = first_problem(self._first)
        if problem is not None:
            self._refuse("hellos_refused", "opcua_hello_refused", *problem)
            return
        if len(self._first) < _HEADER or len(self._first) < struct.unpack_from("<I", self._first, 4)[0]:
            return  # the rest of the Hello
        self._stop_timer()
        size = struct.unpack_from("<I", self._first, 4)[0]
        hello, rest = self._first[:size], self._first[size:]
        self._first = b""
        problem = hello_problem(hello[_HEADER:])
        if problem is not None:
            self._refuse("hellos_refused", "opcua_hello_refused", *problem)
            return
        problem = self._full()
        if problem is not None:
            self._refuse("connections_refused", "opcua_connection_refused", *problem)
            return
        self._admit(hello, rest)

    def _full(self) -> Problem | None:
        """Why the server takes no more connections now, if so."""
        if len(self.clients) >= self.iserver.max_connections:
            return (ua.StatusCodes.BadTooManySessions,
                    f"the server's max_sessions={self.iserver.max_connections} are in use")
        pending = sum(1 for c in self.clients if not _activated(c))
        if pending >= self.wire.max_pending:
            return (ua.StatusCodes.BadTcpServerTooBusy,
                    f"max_pending={self.wire.max_pending} connections are activating their sessions")
        return None

    def _admit(self, hello: bytes, rest: bytes) -> None:
        """asyncua's from here: its connection made and the Hello handed over."""
        transport = self._socket
        assert transport is not None
        self.held.discard(self)
        self._chunks = Chunks(chunk_limit(hello[_HEADER:], self.limits))
        super().connection_made(transport)
        super().data_received(hello)
        if rest:
            self.data_received(rest)

    def _hello_late(self) -> None:
        self._timer = None
        if self._chunks is None and not self._done:
            self._refuse("hello_timeouts", "opcua_hello_timeout", ua.StatusCodes.BadTimeout,
                         f"no complete Hello within hello_timeout_s={self.wire.hello_timeout_s:g}")

    def close(self) -> None:
        """Closed before its Hello (the server stops)."""
        self._done = True
        self._stop_timer()
        if self._socket is not None:
            self._socket.close()

    def _stop_timer(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

    def _refuse(self, counter: str, event: str, code: int, reason: str) -> None:
        """The Error message, then the close (after what is written has gone)."""
        self._done = True
        self._stop_timer()
        self.on_refused(counter, event, f"{self.peer_name}: {reason}")
        transport = self._socket
        if transport is not None and not transport.is_closing():
            transport.write(error_message(code, reason))
            transport.close()


class _BinaryServer(BinaryServer):
    def __init__(self, *args: Any, on_refused: OnRefused, wire: WireLimits, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._on_refused = on_refused
        self._wire = wire
        self._held: set[_Protocol] = set()

    def _make_protocol(self) -> OPCUAProtocol:
        return _Protocol(iserver=self.iserver, policies=self._policies, clients=self.clients,
                         closing_tasks=self.closing_tasks, limits=self.limits, on_refused=self._on_refused,
                         wire=self._wire, held=self._held)

    async def stop(self) -> None:
        for p in list(self._held):
            p.close()
        await super().stop()


class GuardedServer(Server):
    """asyncua's server, its connections :class:`_Protocol`'s."""

    def __init__(self, *args: Any, on_refused: OnRefused, wire: WireLimits | None = None, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._on_refused = on_refused
        self._wire = wire or WireLimits()

    async def start(self) -> None:
        """asyncua 2.1's ``Server.start``, with this module's binary server."""
        if self.iserver.certificate is not None:
            uacrypto.check_certificate(self.iserver.certificate, self._application_uri, socket.gethostname())
        await self._setup_server_nodes()
        await self.iserver.start()
        try:
            host, port = self._get_bind_socket_info()
            self.bserver = _BinaryServer(self.iserver, host, port, self.limits, on_refused=self._on_refused,
                                         wire=self._wire)
            self.bserver.set_policies(self._policies)
            await self.bserver.start()
        except Exception:
            await self.iserver.stop()
            raise
