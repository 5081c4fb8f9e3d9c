"""What the web console is handed beside its options: the register block (served by
the PLC output in server mode; in client mode the image the writer last wrote, and
whether the PLC acknowledged it), kept with the login sessions across a supervised
restart of the web output.  A bridge playing a still grasp in this process, a pymodbus
server on loopback as the PLC, aiohttp's client as the browser."""

from __future__ import annotations

import asyncio
import json
import time
from typing import Any

import aiohttp
import pytest

from eskin_industrial.bridge.config import BridgeConfig, LogSettings, NodeConfig, SupervisionSettings
from eskin_industrial.bridge.supervise import SupervisedSink
from eskin_industrial.cli.bridge_cmd import _registers_to_the_console
from eskin_industrial.outputs.plc.options import PlcOptions
from eskin_industrial.outputs.web.options import WebOptions
from eskin_industrial.outputs.web.wire import decode
from tests.helpers.bridge import PAPER, Running, TimedPlc, running_bridge, wait_for
from tests.helpers.modbus import free_port
from tests.outputs.web.test_web import browser, call, command, login, users_file


def _config(web_port: int, plc: PlcOptions, users: str | None = None) -> BridgeConfig:
    node = NodeConfig.of("grip", PAPER, "scene", scene="hold")
    return BridgeConfig((node,), {"plc": plc, "web": WebOptions(bind=f"127.0.0.1:{web_port}", users_file=users)},
                        LogSettings(format="json", status_every_s=0),
                        supervision=SupervisionSettings(backoff_s=0.2, backoff_max_s=0.4, hang_s=0.5))


async def _block(http: aiohttp.ClientSession, base: str, want: Any = lambda b: True, timeout_s: float = 8.0) -> dict:
    """The first register block on node 0's page that ``want`` takes (as node.js reads it)."""
    end = time.monotonic() + timeout_s
    async with http.ws_connect(f"{base}/ws", headers={"Origin": base}) as ws:
        await ws.send_str(json.dumps({"watch": 0}))
        while time.monotonic() < end:
            msg = await ws.receive(timeout=max(0.1, end - time.monotonic()))
            assert msg.type == aiohttp.WSMsgType.BINARY, msg
            body = decode(msg.data)
            await ws.send_str('{"ack":1}')
            block = body.get("registers")
            if block is not None and want(block):
                return block
    raise AssertionError("no such register block on the node page")


def _web_sink(r: Running) -> SupervisedSink:
    return next(s for s in r.bridge.runs[0].sinks if isinstance(s, SupervisedSink) and s.kind == "web")


@pytest.mark.slow
def test_a_restart_of_the_web_output_keeps_the_register_block_and_the_operators_session(tmp_path) -> None:
    port = free_port()
    base = f"http://127.0.0.1:{port}"
    config = _config(port, PlcOptions(mode="server", host="127.0.0.1", port=free_port()), users_file(tmp_path))
    with running_bridge(config, before_start=_registers_to_the_console) as r:
        async def go() -> None:
            async with browser() as http:
                status, body = await login(http, base, "olga")
                assert status == 200
                csrf = body["session"]["csrf"]
                before = await _block(http, base, lambda b: "DATA_VALID" in b["bits"])
                assert before["source"] == "served" and before["values"]["METHOD_ID"] > 0

                def fault(*_: object) -> None:
                    raise RuntimeError("injected in publish")

                _web_sink(r).inner.publish = fault  # type: ignore[method-assign]
                while not r.log.events("output_restarted"):
                    await asyncio.sleep(0.05)
                assert r.log.events("output_failed")[0]["output"] == "web"
                # the fresh instance: the block still there, the session still commands
                after = await _block(http, base, lambda b: "DATA_VALID" in b["bits"])
                assert after["source"] == "served" and after["values"]["METHOD_ID"] == before["values"]["METHOD_ID"]
                assert await command(http, base, "disable", csrf) == (202, None)
                while r.bridge.runs[0].loop.status.enabled:
                    await asyncio.sleep(0.02)
                assert await command(http, base, "enable", csrf) == (202, None)

        call(go())
        assert r.counters("grip")["web_output_restarts"] == 1


@pytest.mark.slow
def test_in_client_mode_the_node_page_shows_the_image_last_written_and_whether_the_plc_acknowledged_it() -> None:
    port, plc_port = free_port(), free_port()
    base = f"http://127.0.0.1:{port}"
    plc = TimedPlc(plc_port).start()
    try:
        config = _config(port, PlcOptions(mode="client", host="127.0.0.1", port=plc_port))
        with running_bridge(config, before_start=_registers_to_the_console) as r:
            async def go() -> None:
                async with browser() as http:
                    # (an image is shown unacknowledged while its first write is in flight, and
                    # in an outage: on a loaded host, a write past its timeout is one)
                    written = await _block(http, base, lambda b: "DATA_VALID" in b["bits"] and b["acknowledged"])
                    assert written["source"] == "written"
                    last = plc.last()  # what the PLC holds is what the page says was written
                    assert last is not None and written["values"]["METHOD_ID"] == last["METHOD_ID"] > 0
                    assert written["values"]["STATE"] == last["STATE"]
                    plc.stop()  # the PLC goes away: the image is no longer acknowledged
                    gone = await _block(http, base, lambda b: b["acknowledged"] is False)
                    assert gone["source"] == "written" and "DATA_VALID" in gone["bits"]

            call(go())
            wait_for(lambda: r.counters("grip")["plc_write_failures"] > 0, what="the writer's failure counted")
    finally:
        plc.stop()


def test_a_reopen_keeps_the_sessions_of_the_users_the_file_still_gives_with_their_role(tmp_path) -> None:
    from eskin_industrial.outputs.web.server import Session, WebServer, Wiring
    from eskin_industrial.outputs.web.users import load_users

    wiring = Wiring()
    now = time.monotonic()
    wiring.sessions.update({"kept": Session("olga", "operator", "c1", now), "demoted": Session("rita", "operator", "c2", now),
                            "gone": Session("nobody", "reader", "c3", now)})
    server = WebServer(WebOptions(), [], [], load_users(users_file(tmp_path)), wiring)
    assert set(server.sessions) == {"kept"} and server.sessions is wiring.sessions
