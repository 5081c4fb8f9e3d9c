"""A second host, independent of this project's codec: Eclipse Tahu's JavaScript payload
codec (npm ``sparkplug-payload``, the Sparkplug project's reference implementation,
pinned by ``tests/sparkplug_peer``'s lock file) under a small host application
(``tests/sparkplug_peer/host.js``: births, aliases, seq, bdSeq), against a default run
of the bridge on a real mosquitto.  What it reads is checked against the ``protobuf``
package's decoding with the specification's schema, message by message, metric by
metric.
"""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from tests.helpers import sparkplug as spb
from tests.helpers.bridge import wait_for
from tests.helpers.opcua import need_node_peer
from tests.helpers.paths import PROFILES, ROOT

pytestmark = pytest.mark.slow

PEER = ROOT / "tests" / "sparkplug_peer"
UINT32 = 7  #: the one datatype the specification and Tahu's JavaScript codec carry in different fields


def _same(tahu: Any, ours: Any) -> bool:
    if isinstance(ours, float):
        return isinstance(tahu, (int, float)) and (tahu == ours or (math.isnan(ours) and tahu == "NaN"))
    if isinstance(ours, bytes):
        return tahu == ours.hex()
    return bool(tahu == ours)


def test_a_host_on_tahus_codec_reads_a_default_run(tmp_path: Path) -> None:
    node = need_node_peer(PEER, "sparkplug-payload")
    broker = spb.Broker(tmp_path)
    cap = spb.Capture(broker.port, tmp_path / "cap.txt", detail=True)
    url = f"mqtt://127.0.0.1:{broker.port}"
    errors = tmp_path / "host.err"
    with open(errors, "w") as err:
        host = subprocess.Popen([node, str(PEER / "host.js"), url], cwd=PEER, stdin=subprocess.PIPE,
                                stdout=subprocess.PIPE, stderr=err, text=True)
    lines: list[dict[str, Any]] = []
    assert host.stdout is not None
    reader = threading.Thread(target=lambda: lines.extend(json.loads(s) for s in host.stdout), daemon=True)  # type: ignore[union-attr]
    reader.start()
    bridge = None
    try:
        wait_for(lambda: any(x.get("event") == "ready" for x in lines), 30.0, "the host's subscription")
        bridge = subprocess.Popen(
            [sys.executable, "-m", "eskin_industrial", "bridge", "-p", str(PROFILES / "paper-5x5.toml"),
             "--source", "scene:case2", "--sparkplug", url, "--group-id", "plant1", "--edge-node-id", "cell7"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            env={**os.environ, "PYTHONPATH": str(ROOT), "XDG_STATE_HOME": str(tmp_path / "state")})
        wait_for(what="the slip", timeout_s=60.0, cond=lambda: any(x.get("kind") == "DDATA" and any(
            m["name"] == "State" and m["value"] == "slip" for m in x["metrics"]) for x in lines))
        bridge.send_signal(signal.SIGTERM)
        bridge.wait(20)
        wait_for(lambda: any(x.get("kind") == "NDEATH" for x in lines) and any(
            "/NDEATH/" in t for t, _ in cap.messages()), 30.0, "NDEATH at the host and at the capture")
        time.sleep(0.3)
    finally:
        if bridge is not None and bridge.poll() is None:
            bridge.kill()
            bridge.wait(5)
        assert host.stdin is not None
        host.stdin.close()
        try:
            host.wait(10)
        except subprocess.TimeoutExpired:
            host.kill()
            host.wait(5)
        reader.join(5)
        host.stdout.close()
        cap.close()
        broker.kill()

    assert not [x for x in lines if x.get("event") == "error"], (lines, errors.read_text())
    read = [x for x in lines if "kind" in x]
    ours = [(t, spb.parse(p)) for t, _, _, p in cap.records()
            if t.split("/")[2] in ("NBIRTH", "DBIRTH", "NDATA", "DDATA", "DDEATH", "NDEATH")]
    assert [x["topic"] for x in read] == [t for t, _ in ours], "every message, in the same order"
    assert [p for x in read for p in x["problems"]] == [], "nothing a host could not make sense of"
    assert [x["kind"] for x in read][:2] == ["NBIRTH", "DBIRTH"] and [x["kind"] for x in read][-2:] == [
        "DDEATH", "NDEATH"]

    born: dict[tuple[str, int], tuple[str, int]] = {}  #: (device, alias) -> (name, datatype)
    compared = 0
    for x, (topic, p) in zip(read, ours):
        assert x["seq"] == (p.seq if p.HasField("seq") else None) and x["timestamp"] == p.timestamp, topic
        device = topic.split("/")[4] if topic.split("/")[2][0] == "D" else ""
        assert len(x["metrics"]) == len(p.metrics)
        for t, m in zip(x["metrics"], p.metrics):
            if m.HasField("name") and m.HasField("alias"):
                born[(device, m.alias)] = (m.name, m.datatype)
            name, datatype = born[(device, m.alias)] if m.HasField("alias") else (m.name, m.datatype)
            assert t["name"] == name and t["timestamp"] == m.timestamp and t["historical"] == m.is_historical, (topic, t)
            value = None if m.is_null else spb.value(m)
            assert _same(t["value"], value), (topic, name, t["value"], value)
            compared += 1
    assert compared > 100
    # Tahu's JavaScript codec (1.0.3) reads a UInt32 from long_value, where the
    # specification (6.4.16) has a uint32, int_value: the edge node declares none.
    assert UINT32 not in {datatype for _, datatype in born.values()}
