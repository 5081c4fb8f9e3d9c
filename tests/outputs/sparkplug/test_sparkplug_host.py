"""Sparkplug 3.0 primary host awareness on a real broker: ``mosquitto_pub`` plays the
primary host and publishes its retained STATE (JSON); the edge node births only while
it is online; when the host goes offline it sends its NDEATH, disconnects and connects
again (a new session, the next bdSeq), holds its data while the host is away, and
births again when it is back (tck-id-message-flow-edge-node-birth-publish-phid-offline)."""

from __future__ import annotations

import json
import subprocess
import time
from pathlib import Path

import pytest

from eskin_industrial.bridge.config import BridgeConfig, LogSettings, NodeConfig
from eskin_industrial.outputs.sparkplug.options import SparkplugOptions
from tests.helpers import sparkplug as spb
from tests.helpers.bridge import PAPER, running_bridge, wait_for
from tests.helpers.modbus import need
from tests.helpers.sparkplug import state_home  # noqa: F401  (autouse: a state folder of its own)


def _state(port: int, online: bool | None, ts: int, raw: bytes | None = None) -> None:
    body = raw if raw is not None else json.dumps({"online": online, "timestamp": ts}).encode()
    subprocess.run([need("mosquitto_pub"), "-h", "127.0.0.1", "-p", str(port), "-q", "1", "-r",
                    "-t", "spBv1.0/STATE/scada1", "-s"], input=body, check=True, timeout=10)


def _kinds(msgs):
    return [t.split("/")[2] for t, _ in msgs if "/STATE/" not in t]


@pytest.mark.slow
def test_births_wait_for_the_primary_host_and_come_again_when_it_is_back(tmp_path: Path) -> None:
    with spb.broker(tmp_path) as port:
        cap = spb.Capture(port, tmp_path / "sub.txt")
        try:
            node = NodeConfig.of("grip", PAPER, "scene", scene="hold")
            opts = SparkplugOptions(f"mqtt://127.0.0.1:{port}", "g", "e", primary_host_id="scada1",
                                    min_interval_s=0.1)
            config = BridgeConfig((node,), {"sparkplug": opts}, LogSettings(format="json", status_every_s=0))
            with running_bridge(config) as run:
                c = lambda: run.counters("grip")  # noqa: E731
                wait_for(lambda: c()["sparkplug_connects"] == 1 and c()["sparkplug_store_held"] > 3,
                         what="connected, data held")
                _state(port, None, 0, raw=b"{not json")
                wait_for(lambda: c()["sparkplug_bad_states"] == 1, what="a bad STATE counted")
                assert _kinds(cap.messages()) == [], "nothing before the primary host is online"
                t0 = int(time.time() * 1000)
                _state(port, True, t0)
                first = cap.wait(lambda m: any("/NDATA/" in t for t, _ in m))  # the store forwarded
                _state(port, False, t0 + 10)
                wait_for(lambda: c()["sparkplug_host_online"] == 0, what="host offline seen")
                wait_for(lambda: c()["sparkplug_connects"] == 2, what="a new session")
                gone = len(_kinds(cap.messages()))
                _state(port, True, t0 + 5)  # older than the offline: stale, ignored
                time.sleep(0.5)
                assert c()["sparkplug_host_online"] == 0 and len(_kinds(cap.messages())) <= gone + 2
                _state(port, True, t0 + 20)
                msgs = cap.wait(lambda m: _kinds(m).count("NDATA") == 2)
                events = run.log.events("sparkplug_primary_host")
                c_end = c()
        finally:
            cap.close()
    kinds = _kinds(first)
    assert kinds[:2] == ["NBIRTH", "DBIRTH"]
    hist = [spb.parse(p) for t, p in first if "/DDATA/" in t]
    assert hist and all(m.is_historical for m in hist[0].metrics), "what came before: historical"
    ours = [(t, p) for t, p in msgs if "/STATE/" not in t]
    kinds = [t.split("/")[2] for t, _ in ours]
    births = [i for i, k in enumerate(kinds) if k == "NBIRTH"]
    assert len(births) == 2, "a rebirth when the host came back"
    # after the offline: what was under way, the NDEATH of the session, then nothing until the rebirth
    assert kinds[births[1] - 1] == "NDEATH" and kinds[gone - 1] == "NDEATH", kinds
    first_bd = spb.metric_value(spb.parse(ours[births[0]][1]), "bdSeq")
    assert spb.metric_value(spb.parse(ours[gone - 1][1]), "bdSeq") == first_bd
    reborn = spb.parse(ours[births[1]][1])
    assert reborn.seq == 0 and spb.metric_value(reborn, "bdSeq") == first_bd + 1, "a new session"
    assert c_end["sparkplug_host_sessions_ended"] == 1 and c_end["sparkplug_failures"] == 0
    second = [spb.parse(p) for t, p in ours[births[1]:] if "/DDATA/" in t]
    assert any(all(m.is_historical for m in p.metrics) for p in second), "the time away: historical"
    assert [(e["online"], e["level"]) for e in events] == [(1, "info"), (0, "warning"), (1, "info")]
