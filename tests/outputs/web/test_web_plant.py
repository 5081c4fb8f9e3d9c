"""The plant page (``eskin-bus plant --web``): a real mosquitto, a real edge node (the
Sparkplug output's own) publishing into it, the command serving the page, and the
page's feeds (``/api/plant`` and the WebSocket, as a browser reads them) showing the
edge node and its device, then both offline when the node's session ends (NDEATH)."""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import aiohttp
import pytest

from eskin_industrial.cli.plant_cmd import plant_rows
from eskin_industrial.node import NodeSnapshot
from eskin_industrial.outputs.sparkplug.kind import open_edge
from eskin_industrial.outputs.sparkplug.options import SparkplugOptions
from eskin_industrial.outputs.sparkplug.properties import score_properties
from eskin_industrial.profile import load_profile
from tests.helpers import sparkplug as spb
from tests.helpers.bridge import PAPER
from tests.helpers.modbus import free_port
from tests.helpers.snapshots import made
from tests.helpers.sparkplug import state_home  # noqa: F401  (autouse: a state folder of its own)

pytestmark = pytest.mark.slow
PROFILE = load_profile(PAPER)


def snapshot(state: int, slips: int) -> NodeSnapshot:
    return made(state=state, slip_events=slips, valid=True, enabled=True, r_coe=0.0, r_dw=0.0, f_sum_n=0.0,
                xc_mm=0.0, yc_mm=0.0, score_a=0.0, score_b=0.0, frame_age_s=0.0)


@contextlib.contextmanager
def plant_page(tmp: Path, broker_port: int, *args: str) -> Iterator[str]:
    """``eskin-bus plant --web`` on a port of its own; its base URL once it listens."""
    port = free_port()
    err = (tmp / "plant.err").open("w")
    proc = subprocess.Popen([sys.executable, "-m", "eskin_industrial", "plant", f"mqtt://127.0.0.1:{broker_port}",
                             "--group-id", "g", "--plain", "--duration", "60", "--web", f"127.0.0.1:{port}", *args],
                            stdout=subprocess.DEVNULL, stderr=err, env={**os.environ, "PYTHONPATH": os.getcwd()})
    try:
        deadline = time.monotonic() + 15
        while "web_listening" not in (tmp / "plant.err").read_text():
            assert proc.poll() is None and time.monotonic() < deadline, (tmp / "plant.err").read_text()
            time.sleep(0.05)
        yield f"http://127.0.0.1:{port}"
    finally:
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(5)
        err.close()


async def next_plant(ws: aiohttp.ClientWebSocketResponse, until, timeout_s: float = 10.0) -> dict:
    """The WebSocket's plant messages, acknowledged as the page does, until one matches."""
    end = time.monotonic() + timeout_s
    while True:
        left = end - time.monotonic()
        assert left > 0, "no matching plant message"
        msg = json.loads((await ws.receive(timeout=left)).data)
        await ws.send_str('{"ack":1}')
        rows = {(r["edge"], r["device"]): r for r in msg["plant"]["rows"]}
        if until(rows):
            return rows


def test_the_page_shows_the_node_and_device_and_their_death(tmp_path: Path) -> None:
    with spb.broker(tmp_path) as port, plant_page(tmp_path, port) as base:
        async def go() -> tuple[dict, dict, dict, int]:
            async with aiohttp.ClientSession() as http:
                async with http.get(f"{base}/") as r:
                    assert r.status == 200 and "plant.js" in await r.text()
                with pytest.raises(aiohttp.WSServerHandshakeError) as refused:
                    await http.ws_connect(f"{base}/ws", headers={"Origin": "http://evil.example"})
                async with http.ws_connect(f"{base}/ws", headers={"Origin": base}) as ws:
                    edge = open_edge(SparkplugOptions(f"mqtt://127.0.0.1:{port}", "g", "e"), [("grip", score_properties(PROFILE))])
                    edge.start()
                    try:
                        assert edge.wait_connected(5)
                        for state, slips in ((1, 0), (3, 1), (1, 1)):
                            edge.devices[0].publish(snapshot(state, slips))
                            await asyncio.sleep(0.05)
                        live = await next_plant(ws, lambda rows: rows.get(("e", "grip"), {}).get("slips") == 1
                                                and rows[("e", "grip")]["state"] == "stable")
                        async with http.get(f"{base}/api/plant") as r:
                            assert r.status == 200
                            api = {(x["edge"], x["device"]): x for x in (await r.json())["rows"]}
                    finally:
                        edge.close()  # its NDEATH
                    dead = await next_plant(ws, lambda rows: rows.get(("e", None), {}).get("status") == "offline")
                return live, api, dead, refused.value.status

        live, api, dead, refused = asyncio.run(asyncio.wait_for(go(), 30))
    assert refused == 403
    assert live[("e", None)]["status"] == "online" and live[("e", None)]["group"] == "g"
    dev = live[("e", "grip")]
    assert dev["status"] == "online" and dev["valid"] is True and dev["last_slip_ms"] is not None
    assert dev["method"] == PROFILE.detector.method, "the DBIRTH's method"
    assert api[("e", "grip")]["status"] == "online"
    assert dead[("e", None)]["status"] == dead[("e", "grip")]["status"] == "offline"


def test_a_row_with_nothing_new_for_the_stale_time_is_stale() -> None:
    rows = [{"group": "g", "edge": "e", "online": True, "bdSeq": 0, "seq_gaps": 0},
            {"group": "g", "edge": "e", "device": "a", "online": True, "state": "stable", "valid": True,
             "last_slip_ms": None, "slips": 0, "rate": 0.0, "age_s": 12.0},
            {"group": "g", "edge": "f", "online": True, "bdSeq": 0, "seq_gaps": 0},
            {"group": "g", "edge": "f", "device": "b", "online": True, "state": "stable", "valid": True,
             "last_slip_ms": None, "slips": 0, "rate": 1.0, "age_s": 0.5},
            {"group": "g", "edge": "f", "device": "c", "online": False, "state": None, "valid": None,
             "last_slip_ms": None, "slips": None, "rate": 0.0, "age_s": 30.0}]
    assert [r.status for r in plant_rows(rows, 10.0)] == ["stale", "stale", "online", "online", "offline"]
    assert [r.status for r in plant_rows(rows, 15.0)] == ["online"] * 4 + ["offline"]
