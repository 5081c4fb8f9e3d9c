"""The connection protocol's first message over a raw socket on loopback (Part 6,
7.1): a refused Hello, and a connection past ``max_sessions``, are answered with an
Error message that says why (its status code) before the server closes the socket,
where asyncua closed it without a word or took the Hello.  A good Hello is answered
with an Acknowledge, and the server serves on."""

from __future__ import annotations

import asyncio
import socket
import struct

import pytest

from eskin_industrial.bridge.config import NodeConfig
from eskin_industrial.outputs.opcua import wire
from tests.helpers.bridge import PAPER, running_bridge, wait_for
from tests.helpers.opcua import NAMESPACE_URI, opcua_config

pytestmark = pytest.mark.slow


def _hello(url: str, receive: int = 65535, send: int = 65535, url_bytes: bytes | None = None) -> bytes:
    raw = url.encode() if url_bytes is None else url_bytes
    body = struct.pack("<IIIIIi", 0, receive, send, 0, 0, len(raw)) + raw
    return b"HELF" + struct.pack("<I", 8 + len(body)) + body


def _answer(sock: socket.socket) -> tuple[bytes, int | None, bool]:
    """The first message's type and (for an Error) its code, and whether the server
    then closed the connection."""
    data = b""
    while len(data) < 8 or len(data) < struct.unpack_from("<I", data, 4)[0]:
        chunk = sock.recv(65536)
        if not chunk:
            break
        data += chunk
    assert len(data) >= 8, f"no answer, only {data!r}"
    kind = data[:3]
    code = struct.unpack_from("<I", data, 8)[0] if kind == b"ERR" else None
    try:
        closed = sock.recv(1) == b""
    except TimeoutError:
        closed = False
    return kind, code, closed


def test_hellos_and_connections_refused_are_told_why() -> None:
    from asyncua import Client, ua

    config = opcua_config(NodeConfig.of("grip", PAPER, "scene", scene="idle"), max_sessions=2)
    url = config.outputs["opcua"].endpoint
    port = int(url.rsplit(":", 1)[1])

    def ask(message: bytes) -> tuple[bytes, int | None, bool]:
        with socket.create_connection(("127.0.0.1", port), timeout=5) as s:
            s.sendall(message)
            return _answer(s)

    with running_bridge(config) as run:
        small = ask(_hello(url, receive=4096))
        small_send = ask(_hello(url, send=8191))
        long_url = ask(_hello(url, url_bytes=b"opc.tcp://127.0.0.1/" + b"x" * 4100))
        good = socket.create_connection(("127.0.0.1", port), timeout=1)
        held = socket.create_connection(("127.0.0.1", port), timeout=1)
        try:
            good.sendall(_hello(url))
            acknowledged = _answer(good)
            held.sendall(_hello(url))
            _answer(held)
            over = ask(_hello(url))
        finally:
            good.close()
            held.close()
        wait_for(lambda: run.bridge.counters()["grip"]["opcua_connections"] == 0, 5, "the two closed")

        async def read() -> object:
            async with Client(url, timeout=10) as client:
                ns = await client.get_namespace_index(NAMESPACE_URI)
                return await client.get_node(f"ns={ns};s=grip.Method").read_value()

        method = asyncio.run(asyncio.wait_for(read(), 30))
        counters = run.counters("grip")
    assert small == (b"ERR", ua.StatusCodes.BadTcpMessageTooLarge, True)
    assert small_send == (b"ERR", ua.StatusCodes.BadTcpMessageTooLarge, True)
    assert long_url == (b"ERR", ua.StatusCodes.BadTcpEndpointUrlInvalid, True)
    assert acknowledged[0] == b"ACK" and not acknowledged[2]
    assert over == (b"ERR", ua.StatusCodes.BadTooManySessions, True)
    assert method == "cof-track"
    assert counters["opcua_hellos_refused"] == 3 and counters["opcua_connections_refused"] == 1


def test_the_error_message_is_part_6s() -> None:
    """ERRF, the message size, the code, the reason as a String."""
    from asyncua import ua
    from asyncua.ua.ua_binary import struct_from_binary

    message = wire.error_message(ua.StatusCodes.BadTooManySessions, "full")
    assert message[:4] == b"ERRF" and struct.unpack_from("<I", message, 4)[0] == len(message)
    decoded = struct_from_binary(ua.ErrorMessage, ua.utils.Buffer(message[8:]))
    assert decoded.Error.value == ua.StatusCodes.BadTooManySessions and decoded.Reason == "full"
    assert wire.hello_problem(_hello("opc.tcp://h:1")[8:]) is None
