"""The OPC UA connection protocol's first message (Part 6, 7.1), answered as the
specification says where asyncua closes the socket without a word or takes what it
should refuse: an Error message that tells the client why, then the close.

- A connection past ``max_sessions``: Error BadTooManySessions (asyncua closes it
  bare at once; the client then reports a broken connection, not the cap).
- A Hello whose ReceiveBufferSize or SendBufferSize is below 8192 bytes (the least
  a peer may offer without an ECC policy, which this server has not):
  BadTcpMessageTooLarge (this server's smallest chunk is too large for it).
- A Hello whose EndpointUrl is longer than 4096 bytes: BadTcpEndpointUrlInvalid.

The checks are bytes in, bytes out (:func:`hello_problem`, :func:`error_message`);
:class:`GuardedServer` is asyncua's server with its connections made by
:class:`_Protocol`, which applies them before asyncua sees the bytes.
"""

from __future__ import annotations

import asyncio
import socket
import struct
from collections.abc import Callable
from typing import Any

from asyncua import Server, ua
from asyncua.crypto import uacrypto
from asyncua.server.binary_server_asyncio import BinaryServer, OPCUAProtocol

#: The least buffer a peer may offer (Part 6, 7.1.2.3; 1024 only with an ECC policy).
MIN_BUFFER = 8192
#: The longest EndpointUrl (Part 6, 7.1.2.3).
MAX_URL = 4096
#: How long a refused connection is held for its Hello, that the Error answers it.
REFUSED_WAIT_S = 2.0
_HELLO_MAX = 8 + 24 + 2 * MAX_URL  #: past this the first message is asyncua's to judge

OnRefused = Callable[[str, str, str], None]  #: (counter, event, detail)


def hello_problem(body: bytes) -> tuple[int, str] | None:
    """Why a Hello's body (after its 8-byte header) is refused: (status code, reason)."""
    if len(body) < 24:
        return None  # (asyncua's to refuse as malformed)
    _version, receive, send, _size, _chunks, url_length = struct.unpack_from("<IIIIIi", body)
    if receive < MIN_BUFFER or send < MIN_BUFFER:
        return (ua.StatusCodes.BadTcpMessageTooLarge,
                f"ReceiveBufferSize {receive} or SendBufferSize {send} below {MIN_BUFFER} bytes")
    if url_length > MAX_URL:
        return ua.StatusCodes.BadTcpEndpointUrlInvalid, f"EndpointUrl of {url_length} bytes, over {MAX_URL}"
    return None


def error_message(code: int, reason: str) -> bytes:
    """An Error message (Part 6, 7.1.2.5): ERRF, its size, the code, the reason."""
    text = reason.encode()
    body = struct.pack("<Ii", code, len(text)) + text
    return b"ERRF" + struct.pack("<I", 8 + len(body)) + body


class _Protocol(OPCUAProtocol):
    """asyncua's connection, its first message checked (or refused at the cap)."""

    def __init__(self, *args: Any, on_refused: OnRefused, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.on_refused = on_refused
        self._first = b""  #: the bytes until the first message is whole
        self._checked = False
        self._held: asyncio.BaseTransport | None = None  #: a connection refused at the cap

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        if len(self.clients) >= self.iserver.max_connections:
            self._held = transport
            self.on_refused("connections_refused", "opcua_connection_refused",
                            f"{transport.get_extra_info('peername')}: at max_sessions={self.iserver.max_connections}")
            asyncio.get_running_loop().call_later(REFUSED_WAIT_S, transport.close)
            return
        super().connection_made(transport)

    def data_received(self, data: bytes) -> None:
        if self._checked:
            super().data_received(data)
            return
        self._first += data
        if len(self._first) < 8:
            return
        size = struct.unpack_from("<I", self._first, 4)[0]
        hello = self._first[:3] == b"HEL"
        if self._held is None and hello and len(self._first) < size <= _HELLO_MAX:
            return  # the rest of the Hello
        self._checked = True
        first, self._first = self._first, b""
        if self._held is not None:
            self._refuse(self._held, ua.StatusCodes.BadTooManySessions, "the server's max_sessions are in use")
            return
        problem = hello_problem(first[8:size]) if hello and size <= _HELLO_MAX else None
        if problem is not None and self.transport is not None:
            self.on_refused("hellos_refused", "opcua_hello_refused", problem[1])
            self._refuse(self.transport, *problem)
            return
        super().data_received(first)

    @staticmethod
    def _refuse(transport: Any, code: int, reason: str) -> None:
        transport.write(error_message(code, reason))
        transport.close()  # (after what is written has gone)


class _BinaryServer(BinaryServer):
    def __init__(self, *args: Any, on_refused: OnRefused, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._on_refused = on_refused

    def _make_protocol(self) -> OPCUAProtocol:
        return _Protocol(iserver=self.iserver, policies=self._policies, clients=self.clients,
                         closing_tasks=self.closing_tasks, limits=self.limits, on_refused=self._on_refused)


class GuardedServer(Server):
    """asyncua's server, its connections :class:`_Protocol`'s."""

    def __init__(self, *args: Any, on_refused: OnRefused, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._on_refused = on_refused

    async def start(self) -> None:
        """asyncua 2.1's ``Server.start``, with this module's binary server."""
        if self.iserver.certificate is not None:
            uacrypto.check_certificate(self.iserver.certificate, self._application_uri, socket.gethostname())
        await self._setup_server_nodes()
        await self.iserver.start()
        try:
            host, port = self._get_bind_socket_info()
            self.bserver = _BinaryServer(self.iserver, host, port, self.limits, on_refused=self._on_refused)
            self.bserver.set_policies(self._policies)
            await self.bserver.start()
        except Exception:
            await self.iserver.stop()
            raise
