"""The web console over HTTP and WebSocket, without a browser: a bridge playing case 2
in real time with the console beside it, and aiohttp's client as the browser.  Who may
command (an operator's session, its CSRF token, the console's own Origin), the Origin
checked on every WebSocket upgrade, a console with no users read-only, an open bind
refused without TLS and users, and a browser that takes nothing sent at most two
messages, then dropped."""

from __future__ import annotations

import asyncio
import contextlib
import json
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import aiohttp
import numpy as np
import pytest
from click.testing import CliRunner

from eskin_industrial.bridge.config import BridgeConfig, LogSettings, NodeConfig
from eskin_industrial.cli import main
from eskin_industrial.outputs.base import SINKS, output_kind
from eskin_industrial.outputs.opcua.users import add_user
from eskin_industrial.outputs.web import server as web_server
from eskin_industrial.outputs.web.options import WebOptions
from eskin_industrial.outputs.web.wire import decode
from tests.helpers.bridge import PAPER, Running, running_bridge, wait_for
from tests.helpers.modbus import free_port

PASSWORDS = {"olga": "operator-pass", "rita": "reader-pass"}


def users_file(tmp: Path) -> str:
    """The users file the OPC UA output's command writes: one file serves both outputs."""
    path = tmp / "users.toml"
    add_user(path, "olga", "operator", PASSWORDS["olga"])
    add_user(path, "rita", "reader", PASSWORDS["rita"])
    return str(path)


def scene_config(port: int, users: str | None = None, scene: str = "case2") -> BridgeConfig:
    node = NodeConfig.of("grip", PAPER, "scene", scene=scene)
    return BridgeConfig(node=(node,), outputs={"web": WebOptions(bind=f"127.0.0.1:{port}", users_file=users)},
                        log=LogSettings(format="json", status_every_s=0))


@contextlib.contextmanager
def console(tmp: Path, users: bool = True, scene: str = "case2") -> Iterator[tuple[Running, str]]:
    port = free_port()
    with running_bridge(scene_config(port, users_file(tmp) if users else None, scene)) as run:
        yield run, f"http://127.0.0.1:{port}"


def browser() -> aiohttp.ClientSession:
    """A client that keeps the console's cookies as a browser does (aiohttp's jar
    refuses cookies of an IP address unless told)."""
    return aiohttp.ClientSession(cookie_jar=aiohttp.CookieJar(unsafe=True))


def call(coro):  # a test's coroutine, run to its end within 20 s
    return asyncio.run(asyncio.wait_for(coro, 20))


async def login(http: aiohttp.ClientSession, base: str, user: str, password: str | None = None) -> tuple[int, dict]:
    r = await http.post(f"{base}/api/login", json={"user": user, "password": password or PASSWORDS[user]},
                        headers={"Origin": base})
    return r.status, await r.json()


async def command(http: aiohttp.ClientSession, base: str, name: str, csrf: str | None,
                  origin: str | None = None) -> tuple[int, str | None]:
    headers = {"Origin": origin or base}
    if csrf is not None:
        headers["X-CSRF-Token"] = csrf
    r = await http.post(f"{base}/api/nodes/0/command", json={"command": name}, headers=headers)
    return r.status, (await r.json()).get("error")


def test_the_kind_is_one_registry_entry() -> None:
    assert SINKS["web"] == "eskin_industrial.outputs.web.kind:WebKind"
    assert output_kind("web").name == "web"
    assert [o.flag for o in output_kind("web").cli_options][0] == "--web"


def test_an_open_bind_needs_tls_and_users() -> None:
    assert WebOptions().loopback and WebOptions().bind == "127.0.0.1:8080"
    with pytest.raises(ValueError, match=r"bind: on 0\.0\.0\.0, not loopback, the console needs TLS .* and users"):
        WebOptions(bind="0.0.0.0:8080")
    with pytest.raises(ValueError, match=r"needs TLS \(tls_cert, tls_key\)$"):
        WebOptions(bind="0.0.0.0:8080", users_file="users.toml")
    with pytest.raises(ValueError, match="tls_cert: give tls_cert and tls_key together"):
        WebOptions(tls_cert="cert.pem")
    assert not WebOptions(bind="[::]:8443", users_file="u.toml", tls_cert="c.pem", tls_key="k.pem").loopback


@pytest.mark.slow
def test_check_refuses_an_open_bind_and_describes_a_loopback_one(tmp_path: Path) -> None:
    res = CliRunner().invoke(main, ["bridge", "-p", PAPER, "--source", "scene:case2", "--web", "0.0.0.0:8080",
                                    "--check"])
    assert res.exit_code == 2, res.output
    assert "not loopback, the console needs TLS (tls_cert, tls_key) and users (users_file)" in res.output
    port = free_port()
    res = CliRunner().invoke(main, ["bridge", "-p", PAPER, "--source", "scene:case2", "--web", f"127.0.0.1:{port}",
                                    "--web-users-file", users_file(tmp_path), "--check"])
    assert res.exit_code == 0, res.output
    assert f"web console http://127.0.0.1:{port}/ (no TLS; users from" in res.output


@pytest.mark.slow
def test_commands_need_an_operators_session_its_csrf_token_and_the_consoles_origin(tmp_path: Path) -> None:
    with console(tmp_path) as (run, base):
        wait_for(lambda: run.counters("grip")["scans"] > 250, what="the hold under way")  # 8 N held from 1.5 s

        async def go() -> None:
            async with browser() as anonymous:
                assert await command(anonymous, base, "ack", None) == (401, "login")
                r = await anonymous.get(f"{base}/api/info")
                assert "nodes" not in await r.json()  # with users, no value without a login
                assert await login(anonymous, base, "olga", "wrong") == (401, {"error": "wrong user name or password"})
                assert await login(anonymous, base, "nobody", "x") == (401, {"error": "wrong user name or password"})
            async with browser() as reader:
                status, body = await login(reader, base, "rita")
                assert status == 200 and body["session"]["role"] == "reader"
                assert await command(reader, base, "ack", body["session"]["csrf"]) == (403, "role")
            async with browser() as operator:
                r = await operator.post(f"{base}/api/login", json={"user": "olga", "password": PASSWORDS["olga"]},
                                        headers={"Origin": base})
                cookie = r.headers["Set-Cookie"]
                assert "HttpOnly" in cookie and "SameSite=Strict" in cookie, cookie
                csrf = (await r.json())["session"]["csrf"]
                assert await command(operator, base, "ack", None) == (403, "csrf")
                assert await command(operator, base, "ack", "not-the-token") == (403, "csrf")
                assert await command(operator, base, "ack", csrf, origin="http://evil.example") == (403, "origin")
                # the one refusal rule: no tare while something is held
                assert await command(operator, base, "tare", csrf) == (409, "in_contact")
                before = run.counters("grip")["commands"]
                assert await command(operator, base, "disable", csrf) == (202, None)
                wait_for(lambda: run.counters("grip")["commands"] == before + 1, what="the disable applied")
                assert not run.bridge.runs[0].loop.status.enabled
                assert await command(operator, base, "enable", csrf) == (202, None)
                wait_for(lambda: run.bridge.runs[0].loop.status.enabled, what="the enable applied")

        call(go())
        c = run.counters("grip")
        assert c["web_commands"] == 2 and c["web_commands_refused"] == 6 and c["web_logins_refused"] == 2
        wait_for(lambda: len(run.log.events("web_command_refused")) == 6, what="each refusal logged")
        refused = run.log.events("web_command_refused")
        assert {e["reason"] for e in refused} == {"login", "role", "csrf", "origin", "in_contact"}


@pytest.mark.slow
def test_the_websocket_upgrade_checks_the_origin(tmp_path: Path) -> None:
    with console(tmp_path, users=False, scene="hold") as (run, base):
        async def go() -> None:
            async with browser() as http:
                for origin in ("http://evil.example", f"{base}.evil.example", None):
                    headers = {"Origin": origin} if origin else {}
                    with pytest.raises(aiohttp.WSServerHandshakeError) as refused:
                        await http.ws_connect(f"{base}/ws", headers=headers)
                    assert refused.value.status == 403
                async with http.ws_connect(f"{base}/ws", headers={"Origin": base}) as ws:
                    await ws.send_str(json.dumps({"watch": 0}))
                    msg = decode((await ws.receive(timeout=5)).data)
                    assert msg["nodes"][0]["i"] == 0
                # no users: the console is read-only, for everyone
                assert await command(http, base, "ack", None) == (403, "read_only")

        call(go())
        assert run.counters("grip")["web_origin_refused"] == 3


@pytest.mark.slow
def test_a_browser_that_takes_nothing_gets_two_messages_then_is_dropped(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setattr(web_server, "SEND_TIMEOUT_S", 1.0)
    with console(tmp_path, users=False, scene="hold") as (run, base):
        async def go() -> tuple[int, list[float], float]:
            async with browser() as http:
                # a page that draws slowly: it acknowledges a message every 0.3 s
                slow_t: list[float] = []
                async with http.ws_connect(f"{base}/ws", headers={"Origin": base}) as ws:
                    await ws.send_str(json.dumps({"watch": 0}))
                    end = time.monotonic() + 2.0
                    while time.monotonic() < end:
                        msg = decode((await ws.receive(timeout=5)).data)
                        if "frame" in msg:
                            slow_t.append(msg["frame"]["t"])
                        await asyncio.sleep(0.3)
                        await ws.send_str('{"ack":1}')
                # a page that acknowledges nothing: two messages, then nothing, then dropped
                got = 0
                async with http.ws_connect(f"{base}/ws", headers={"Origin": base}) as ws:
                    await ws.send_str(json.dumps({"watch": 0}))
                    t0 = time.monotonic()
                    while True:
                        msg = await ws.receive(timeout=5)
                        if msg.type != aiohttp.WSMsgType.BINARY:
                            break
                        got += 1
                    return got, slow_t, time.monotonic() - t0

        got, slow_t, dropped_after = call(go())
        assert got == web_server.IN_FLIGHT
        assert 0.8 < dropped_after < 3.0, dropped_after
        assert run.counters("grip")["web_clients_dropped"] == 1
        wait_for(lambda: run.log.events("web_client_dropped"), what="web_client_dropped logged")
        # the slow page saw the newest frame each time, not a backlog 30 ms apart
        steps = [b - a for a, b in zip(slow_t, slow_t[1:])]
        assert steps and min(steps) >= 0.2, steps


@pytest.mark.slow
def test_monitor_serves_the_console_beside_its_view() -> None:
    port = free_port()
    answers: list[dict] = []

    async def ask() -> None:
        async with browser() as http:
            for _ in range(100):
                try:
                    r = await http.get(f"http://127.0.0.1:{port}/api/info")
                    answers.append(await r.json())
                    return
                except aiohttp.ClientConnectionError:
                    await asyncio.sleep(0.05)

    asker = threading.Thread(target=lambda: call(ask()))
    asker.start()
    res = CliRunner().invoke(main, ["monitor", "-p", PAPER, "-i", "virtual", "-c", f"web-{port}", "--duration", "2",
                                    "--plain", "--web", f"127.0.0.1:{port}"])
    asker.join(timeout=10)
    assert res.exit_code == 0, res.output
    assert answers and answers[0]["nodes"][0]["method"] == "cof-track", answers
    assert answers[0]["session"] == {"user": None, "role": None, "csrf": None, "login": False, "commands": False}


@pytest.mark.slow
def test_the_bridge_shows_the_served_plc_block_on_the_node_page() -> None:
    port, plc_port = free_port(), free_port()
    blocks: list[dict] = []

    async def watch() -> None:
        async with browser() as http:
            for _ in range(200):
                try:
                    ws = await http.ws_connect(f"http://127.0.0.1:{port}/ws", headers={"Origin": f"http://127.0.0.1:{port}"})
                    break
                except aiohttp.ClientConnectionError:
                    await asyncio.sleep(0.05)
            async with ws:
                await ws.send_str(json.dumps({"watch": 0}))
                while not blocks:
                    msg = decode((await ws.receive(timeout=5)).data)
                    await ws.send_str('{"ack":1}')
                    if "registers" in msg and "DATA_VALID" in msg["registers"]["bits"]:
                        blocks.append(msg["registers"])

    watcher = threading.Thread(target=lambda: call(watch()))
    watcher.start()
    res = CliRunner().invoke(main, ["bridge", "-p", PAPER, "--source", "scene:hold", "--plc",
                                    f"serve:127.0.0.1:{plc_port}", "--web", f"127.0.0.1:{port}", "--duration", "4"])
    watcher.join(timeout=10)
    assert res.exit_code == 0, res.output
    assert blocks, "no register block on the node page"
    assert "DATA_VALID" in blocks[0]["bits"] and blocks[0]["values"]["METHOD_ID"] > 0


def test_the_feed_keeps_each_capture_window_and_at_most_the_newest_captures() -> None:
    from eskin_industrial.detect.state import GraspState
    from eskin_industrial.detect.updates import Update
    from eskin_industrial.frames import Frame
    from eskin_industrial.outputs.web.hub import CAPTURES_MAX, NodeFeed

    feed = NodeFeed(0, 100.0, capture_pre_s=0.5, capture_post_s=0.2, frame_interval_s=0.03)
    kicks = []
    feed.kick = lambda: kicks.append(1)
    k = 0
    for _episode in range(CAPTURES_MAX + 3):
        for state in (GraspState.STABLE, GraspState.SLIP):
            for _ in range(100):  # 1 s of each, a scan every 10 ms
                t = k / 100.0
                # a new array a scan, as the calibration makes: the feed keeps references
                feed.frame(Frame(k, t, np.full(25, t)))
                feed.update(Update(t, 0.0, 0.0, int(state), True, 1.0, 0.0, 0.0, 0))
                feed.freeze_captures()
                k += 1
    assert len(feed.ring) <= (0.5 + 0.2 + 1.0) * 100 + 8  # the window and a margin: bounded
    kept = [e for e in feed.episodes if e.rows is not None]
    assert len(kept) == CAPTURES_MAX and len(feed.episodes) == CAPTURES_MAX + 3
    assert [e.id for e in kept] == [e.id for e in list(feed.episodes)[-CAPTURES_MAX:]]
    for e in kept:
        t = e.rows[:, 0]
        assert t[0] == pytest.approx(e.t - 0.5) and t[-1] == pytest.approx(e.t + 0.2)
        assert np.allclose(e.rows[:, 1], t)  # each scan's own forces, not the newest frame's
    assert not any(e.waiting for e in feed.episodes)
    assert 0 < len(kicks) < k  # woken, and not once a scan


@pytest.mark.slow
def test_tls_serves_https_and_wss_with_secure_cookies(tmp_path: Path) -> None:
    import ssl

    from tests.helpers.sparkplug import certificates

    pem = certificates(tmp_path)
    port = free_port()
    base = f"https://127.0.0.1:{port}"
    # a key that is not the certificate's: refused before the run
    res = CliRunner().invoke(main, ["bridge", "-p", PAPER, "--source", "scene:hold", "--web", f"127.0.0.1:{port}",
                                    "--web-tls-cert", str(pem["server"]), "--web-tls-key", str(pem["client_key"]),
                                    "--check"])
    assert res.exit_code == 2 and "tls_cert: " in res.output and "cannot load with its key" in res.output, res.output
    options = WebOptions(bind=f"127.0.0.1:{port}", users_file=users_file(tmp_path), tls_cert=str(pem["server"]),
                         tls_key=str(pem["server_key"]))
    config = BridgeConfig(node=(NodeConfig.of("grip", PAPER, "scene", scene="hold"),), outputs={"web": options},
                          log=LogSettings(format="json", status_every_s=0))
    trust = ssl.create_default_context(cafile=str(pem["ca"]))

    async def go() -> None:
        async with browser() as http:
            r = await http.post(f"{base}/api/login", json={"user": "olga", "password": PASSWORDS["olga"]},
                                headers={"Origin": base}, ssl=trust)
            assert r.status == 200
            assert "Secure" in r.headers["Set-Cookie"] and "max-age" in r.headers["Strict-Transport-Security"]
            async with http.ws_connect(f"wss://127.0.0.1:{port}/ws", headers={"Origin": base}, ssl=trust) as ws:
                msg = decode((await ws.receive(timeout=5)).data)
                assert msg["nodes"][0]["i"] == 0
            with pytest.raises(aiohttp.ClientError):  # plain HTTP is not served
                await http.get(f"http://127.0.0.1:{port}/api/info")

    with running_bridge(config):
        call(go())


@pytest.mark.slow
def test_logins_are_hashed_one_at_a_time_and_a_flood_is_refused(tmp_path: Path) -> None:
    with console(tmp_path, scene="hold") as (run, base):
        async def go() -> list[int]:
            async with browser() as http:
                answers = await asyncio.gather(*(login(http, base, "olga", f"guess-{i}") for i in range(12)))
                return [status for status, _ in answers]

        statuses = call(go())
        assert set(statuses) == {401, 429}, statuses
        assert run.counters("grip")["web_logins_refused"] == 12
