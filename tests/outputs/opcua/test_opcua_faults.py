"""The OPC UA server under the faults the other outputs are tested with: a client that
vanishes mid-subscription, a hundred connections opened and abandoned, a flood of
method calls, malformed messages on the port.  The server stays up (a client reads
afterwards), the node's loop never waits for it (every scan taken, no publication
held up), connections are capped and timed out, and the counters and the log say
what happened."""

from __future__ import annotations

import asyncio
import os
import random
import signal
import socket
import struct
import subprocess
import sys
import textwrap
import time
from pathlib import Path
from typing import Any

import pytest

from eskin_industrial.bridge.config import NodeConfig
from tests.helpers.bridge import PAPER, running_bridge, wait_for
from tests.helpers.opcua import NAMESPACE_URI, opcua_config

pytestmark = pytest.mark.slow


def _timed_publish(run: Any) -> list[float]:
    """Every publish of the node's OPC UA sink, timed (the loop's side of the handover)."""
    sink = next(s for s in run.bridge.runs[0].sinks if s.kind == "opcua")
    took: list[float] = []
    publish = sink.publish

    def timed(snapshot: Any) -> None:
        t0 = time.perf_counter()
        publish(snapshot)
        took.append(time.perf_counter() - t0)

    sink.publish = timed
    return took


async def _read_method(url: str) -> str:
    from asyncua import Client

    async with Client(url, timeout=10) as client:
        ns = await client.get_namespace_index(NAMESPACE_URI)
        return str(await client.get_node(f"ns={ns};s=grip.Method").read_value())


def _hello(url: str, **sizes: int) -> bytes:
    """An OPC UA TCP Hello (Part 6, 7.1.2.3), its fields overridable to lie."""
    fields = {"version": 0, "receive": 65535, "send": 65535, "message": 0, "chunks": 0, **sizes}
    body = struct.pack("<IIIII", fields["version"], fields["receive"], fields["send"], fields["message"],
                       fields["chunks"])
    body += struct.pack("<i", sizes.get("url_length", len(url))) + url.encode()
    return b"HELF" + struct.pack("<I", 8 + len(body)) + body


def test_abandoned_connections_are_capped_and_timed_out_and_a_vanished_client_is_dropped(tmp_path: Path) -> None:
    config = opcua_config(NodeConfig.of("grip", PAPER, "scene", scene="case2"), max_sessions=8,
                          activation_timeout_s=1.0, session_timeout_s=2.0)
    url = config.outputs["opcua"].endpoint
    port = int(url.rsplit(":", 1)[1])
    with running_bridge(config) as run:
        took = _timed_publish(run)
        scans0 = run.counters("grip")["scans"]
        # 100 connections that never open a session: of the 50 that send a Hello, 8
        # held and the rest refused; the 50 silent ones told BadTimeout after 2 s
        socks = []
        try:
            for i in range(100):
                s = socket.create_connection(("127.0.0.1", port), timeout=5)
                if i % 2:
                    s.sendall(_hello(url))
                socks.append(s)
            wait_for(lambda: run.counters("grip")["opcua_connections_refused"] >= 42, 10, "42 connections refused")
            wait_for(lambda: run.counters("grip")["opcua_hello_timeouts"] >= 50, 10, "50 silent ones timed out")
            wait_for(lambda: run.counters("grip")["opcua_activation_timeouts"] >= 8, 10,
                     "the 8 held ones closed for not activating a session")
        finally:
            for s in socks:
                s.close()
        assert asyncio.run(asyncio.wait_for(_read_method(url), 30)) == "cof-track"  # room again

        # a client with a subscription that vanishes (SIGKILL): its session outlives the
        # connection (OPC UA lets a client take it back) until the session timeout
        script = textwrap.dedent(f"""
            import asyncio, os, signal
            from asyncua import Client
            async def main():
                clients = []
                for _ in range(3):
                    c = Client("{url}", timeout=10)
                    c.session_timeout = 2000
                    await c.connect()
                    sub = await c.create_subscription(50, None)
                    ns = await c.get_namespace_index("{NAMESPACE_URI}")
                    await sub.subscribe_data_change(c.get_node(f"ns={{ns}};s=grip.Counters.Scans"))
                    clients.append(c)
                print("subscribed", flush=True)
                await asyncio.sleep(0.5)
                os.kill(os.getpid(), signal.SIGKILL)
            asyncio.run(main())
        """)
        proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
        assert proc.returncode == -signal.SIGKILL and "subscribed" in proc.stdout, proc.stderr
        wait_for(lambda: run.counters("grip")["opcua_sessions_timed_out"] >= 3, 15, "the vanished sessions dropped")
        wait_for(lambda: run.counters("grip")["opcua_connections"] == 0, 5, "no connection left")
        counters = run.counters("grip")
        elapsed_scans = counters["scans"] - scans0
    assert counters["lost_scans"] == 0 and elapsed_scans > 0
    assert took and max(took) < 0.1, max(took)  # the loop handed snapshots over, never waited
    events = {e["event"] for e in run.log.events()}
    assert {"opcua_connection_refused", "opcua_hello_timeout", "opcua_activation_timeout",
            "opcua_session_timeout"} <= events
    _one_line_a_second(run.log.events())  # 42 refusals: a line a second, the others counted in the next
    assert sum(e["not_logged"] + 1 for e in run.log.events("opcua_connection_refused")) <= 42
    assert "loop_failed" not in events


def test_a_flood_of_method_calls_is_answered_and_the_loop_goes_on(tmp_path: Path) -> None:
    from asyncua import Client, ua

    config = opcua_config(NodeConfig.of("grip", PAPER, "scene", scene="case2"))
    url = config.outputs["opcua"].endpoint

    async def flood(n: int) -> dict[str, int]:
        counts: dict[str, int] = {}
        async with Client(url, timeout=30) as client:
            ns = await client.get_namespace_index(NAMESPACE_URI)
            grip = client.get_node(f"ns={ns};s=grip")
            enable = client.get_node(f"ns={ns};s=grip.Enable")

            async def one(i: int) -> None:
                try:
                    await grip.call_method(enable, ua.Variant(i % 7 != 0, ua.VariantType.Boolean))
                    name = "Good"
                except ua.UaStatusCodeError as exc:
                    name = type(exc).__name__
                counts[name] = counts.get(name, 0) + 1

            for start in range(0, n, 100):  # 100 calls in flight at a time
                await asyncio.gather(*(one(i) for i in range(start, min(n, start + 100))))
            # The last batch can leave the loop's queue full until its next scan takes it:
            # busy is the answer then, and a client calls again, as this one does.
            for _ in range(250):
                try:
                    await grip.call_method(enable, ua.Variant(True, ua.VariantType.Boolean))
                    break
                except ua.uaerrors.BadTooManyOperations:
                    await asyncio.sleep(0.02)
            else:
                raise AssertionError("the last Enable was busy for 5 s")
        return counts

    with running_bridge(config) as run:
        took = _timed_publish(run)
        t0, scans0 = time.monotonic(), run.counters("grip")["scans"]
        counts = asyncio.run(asyncio.wait_for(flood(2000), 300))
        elapsed, scans = time.monotonic() - t0, run.counters("grip")["scans"] - scans0
        wait_for(lambda: run.bridge.runs[0].loop.status.enabled, 5, "enabled at the end")
        c = run.counters("grip")
    assert sum(counts.values()) == 2000 and set(counts) <= {"Good", "BadTooManyOperations"}, counts
    assert c["opcua_method_calls"] >= 2000 and c["opcua_commands"] + c["opcua_commands_busy"] >= 2000
    assert c["lost_scans"] == 0
    assert scans >= 0.5 * 100 * elapsed, (scans, elapsed)  # the scene plays at 100 Hz all along
    assert took and max(took) < 0.1, max(took)


def test_malformed_messages_leave_the_server_up_and_counted(tmp_path: Path) -> None:
    config = opcua_config(NodeConfig.of("grip", PAPER, "scene", scene="case2"), activation_timeout_s=1.0)
    url = config.outputs["opcua"].endpoint
    port = int(url.rsplit(":", 1)[1])
    rng = random.Random(27)
    garbage = [
        b"GET / HTTP/1.1\r\nHost: x\r\n\r\n",
        b"HELF" + struct.pack("<I", 8),  # a header and no body
        b"HELF" + struct.pack("<I", 4),  # a size smaller than the header
        b"MSGF" + struct.pack("<I", 0xFFFFFFF0) + b"\x00" * 64,  # a message of 4 GB announced
        _hello(url, url_length=-5),
        _hello(url, url_length=1 << 30),
        _hello(url, receive=1, send=1),
        _hello(url) + b"OPNF" + struct.pack("<I", 40) + os.urandom(32),
        _hello(url) + b"MSGF" + struct.pack("<I", 64) + os.urandom(56),
        b"\x00" * 4096,
        *(bytes(rng.getrandbits(8) for _ in range(rng.randint(1, 300))) for _ in range(40)),
    ]
    with running_bridge(config) as run:
        took = _timed_publish(run)
        for data in garbage:
            with socket.create_connection(("127.0.0.1", port), timeout=5) as s:
                s.settimeout(0.3)
                try:
                    s.sendall(data)
                    s.recv(4096)  # an error message, a close, or nothing until the timeout
                except (TimeoutError, ConnectionError, OSError):
                    pass
        assert asyncio.run(asyncio.wait_for(_read_method(url), 30)) == "cof-track"  # still serving
        wait_for(lambda: run.counters("grip")["opcua_connections"] <= 1, 10, "the garbage connections closed")
        c = run.counters("grip")
    assert c["lost_scans"] == 0 and took and max(took) < 0.1
    assert c["opcua_malformed"] + c["opcua_stack_warnings"] + c["opcua_stack_errors"] + \
        c["opcua_activation_timeouts"] >= 1
    _one_line_a_second(run.log.events())


def _one_line_a_second(events: list[dict[str, Any]]) -> None:
    """Each kind of the output's warnings is logged once a second at most."""
    from datetime import datetime

    last: dict[str, datetime] = {}
    for e in events:
        if not e["event"].startswith("opcua_") or e["level"] == "info":
            continue
        ts = datetime.fromisoformat(e["ts"].replace("Z", "+00:00"))
        before = last.get(e["event"])
        assert before is None or (ts - before).total_seconds() >= 0.99, (e, before)
        last[e["event"]] = ts
