"""``eskin-bus plant``: the model fed with payloads the ``protobuf`` package encodes,
and the command on a real broker watching an edge node, checked against what
``mosquitto_sub`` received (decoded by protobuf)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from eskin_industrial.node import NodeSnapshot
from eskin_industrial.outputs.sparkplug.kind import open_edge
from eskin_industrial.outputs.sparkplug.options import SparkplugOptions
from eskin_industrial.outputs.sparkplug.watch import PlantModel
from eskin_industrial.view.plant_table import plant_lines
from tests.helpers import sparkplug as spb
from tests.helpers.snapshots import made
from tests.helpers.sparkplug import state_home  # noqa: F401  (autouse: a state folder of its own)


def _p(seq=None, ts=1000, **metrics) -> bytes:
    p = spb.Payload(timestamp=ts)
    if seq is not None:
        p.seq = seq
    for kw in metrics.values():
        p.metrics.add(**kw)
    return p.SerializeToString()


def test_the_model_follows_births_deaths_aliases_and_seq():
    m = PlantModel()
    t = "spBv1.0/g/{}/e"
    assert m.take(t.format("NBIRTH"), _p(0, bdSeq=dict(name="bdSeq", datatype=4, long_value=3)), 0.0) == \
        [{"event": "online", "group": "g", "edge": "e", "bdSeq": 3}]
    birth = _p(1, a=dict(name="State", alias=1000, datatype=12, string_value="stable"),
               b=dict(name="Data Valid", alias=1004, datatype=11, boolean_value=True),
               c=dict(name="Slip", alias=1002, datatype=11, boolean_value=False),
               d=dict(name="Counters/Slip Events", alias=1015, datatype=7, int_value=0))
    ev = m.take(t.format("DBIRTH") + "/grip", birth, 0.0)
    assert [e["event"] for e in ev] == ["online", "state"] and ev[1]["state"] == "stable"
    slip = _p(2, ts=5000, a=dict(alias=1000, datatype=12, string_value="slip"),
              c=dict(alias=1002, datatype=11, boolean_value=True), d=dict(alias=1015, datatype=7, int_value=1))
    (ev,) = m.take(t.format("DDATA") + "/grip", slip, 1.0)
    assert (ev["event"], ev["state"], ev["slips"]) == ("state", "slip", 1)
    gap = m.take(t.format("DDATA") + "/grip", _p(7, a=dict(alias=1000, datatype=12, string_value="stable")), 2.0)
    assert gap[0] == {"event": "seq_gap", "group": "g", "edge": "e", "expected": 3, "seq": 7}
    assert m.take(t.format("DDATA") + "/grip", b"\xff\xff", 2.0) == [{"event": "malformed",
                                                                        "topic": "spBv1.0/g/DDATA/e/grip"}]
    assert m.take(t.format("NDEATH"), _p(bdSeq=dict(name="bdSeq", datatype=4, long_value=2)), 3.0) == [], \
        "the death of an older session"
    (dev,) = [r for r in m.rows(3.0) if "device" in r]
    assert dev["online"] and dev["last_slip_ms"] == 5000 and dev["slips"] == 1 and dev["rate"] == 0.2  # two DDATA in 10 s
    assert m.take(t.format("NDEATH"), _p(bdSeq=dict(name="bdSeq", datatype=4, long_value=3)), 4.0)[0]["event"] == \
        "offline"
    rows = m.rows(4.0)
    assert not any(r["online"] for r in rows) and rows[0]["seq_gaps"] == 1
    lines = plant_lines(rows, "title", 100, 10)
    assert "1 edge node, 1 device" in lines[0] and "OFFLINE" in lines[2] and "  grip" in lines[3]


def _pub(state: int, slips: int) -> NodeSnapshot:
    return made(state=state, slip_events=slips, valid=True, enabled=True, r_coe=0.0, r_dw=0.0, f_sum_n=0.0,
                xc_mm=0.0, yc_mm=0.0, score_a=0.0, score_b=0.0, frame_age_s=0.0)


@pytest.mark.slow
def test_the_command_shows_what_the_subscriber_received(tmp_path):
    with spb.broker(tmp_path) as port:
        cap = spb.Capture(port, tmp_path / "sub.txt")
        proc = subprocess.Popen([sys.executable, "-m", "eskin_industrial", "plant", f"mqtt://127.0.0.1:{port}",
                                 "--group-id", "g", "--json", "--duration", "8"], stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True, env={**os.environ, "PYTHONPATH": os.getcwd()})
        lines: list[str] = []
        reader = threading.Thread(target=lambda: lines.extend(proc.stdout), daemon=True)
        reader.start()
        try:
            deadline = time.monotonic() + 10
            while not any('"connected"' in x for x in lines):
                assert time.monotonic() < deadline and proc.poll() is None, lines
                time.sleep(0.05)
            edge = open_edge(SparkplugOptions(f"mqtt://127.0.0.1:{port}", "g", "e"), [("grip", {})])
            edge.start()
            assert edge.wait_connected(5)
            for state, slips in ((0, 0), (1, 0), (3, 1), (1, 1), (3, 2), (0, 2)):
                edge.devices[0].publish(_pub(state, slips))
                time.sleep(0.05)
            edge.close()
            msgs = cap.wait(lambda m: any("/NDEATH/" in t for t, _ in m))
            proc.wait(15)
            reader.join(5)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait(5)
            reader.join(5)
            err = proc.stderr.read()
            proc.stdout.close()
            proc.stderr.close()
            cap.close()
    assert proc.returncode == 0, err
    assert "plant: " in err and "1 edge nodes, 1 devices" in err
    events = [json.loads(x) for x in lines]
    names = {m.alias: m.name for t, p in msgs if "/DBIRTH/" in t for m in spb.parse(p).metrics}
    received = [spb.value(m) for t, p in msgs if "/DDATA/" in t for m in spb.parse(p).metrics
                if names.get(m.alias) == "State"]
    shown = [e["state"] for e in events if e["event"] == "state"]
    assert shown == received == ["no_contact", "stable", "slip", "stable", "slip", "no_contact"]
    kinds = [(e["event"], "device" in e) for e in events if e["event"] in ("online", "offline")]
    assert kinds == [("online", False), ("online", True), ("offline", True), ("offline", False)]
    summary = [e for e in events if e["event"] == "summary"]
    (dev,) = [e for e in summary if "device" in e]
    assert dev["slips"] == 2 and dev["last_slip_ms"] is not None and not dev["online"]
    assert [e for e in summary if "device" not in e][0]["seq_gaps"] == 0


def test_historical_values_are_history_not_the_live_state() -> None:
    """After an outage the node sends what it held, is_historical, after its births:
    the view shows it as history (an event with its time) and keeps the births' live
    state; a slip while away is still the last slip."""
    m = PlantModel()
    t = "spBv1.0/g/{}/e"
    m.take(t.format("NBIRTH"), _p(0, bdSeq=dict(name="bdSeq", datatype=4, long_value=0)), 0.0)
    birth = _p(1, a=dict(name="State", alias=1000, datatype=12, string_value="stable"),
               c=dict(name="Slip", alias=1002, datatype=11, boolean_value=False))
    m.take(t.format("DBIRTH") + "/grip", birth, 0.0)
    held = _p(2, ts=9000, a=dict(alias=1000, timestamp=4000, string_value="slip", is_historical=True),
              c=dict(alias=1002, timestamp=4000, boolean_value=True, is_historical=True))
    ev = m.take(t.format("DDATA") + "/grip", held, 1.0)
    assert ev == [{"event": "historical", "group": "g", "edge": "e", "device": "grip", "state": "slip",
                   "timestamp": 4000}]
    (dev,) = [r for r in m.rows(1.0) if "device" in r]
    assert dev["state"] == "stable" and dev["last_slip_ms"] == 4000


def test_data_before_any_birth_is_an_unborn_node_once():
    m = PlantModel()
    first = m.take("spBv1.0/g/DDATA/e/grip", _p(4, a=dict(alias=1000, datatype=12, string_value="slip")), 0.0)
    assert first == [{"event": "unborn", "group": "g", "edge": "e"}], "aliases unknown: no state shown"
    assert m.take("spBv1.0/g/DDATA/e/grip", _p(5, a=dict(alias=1000, datatype=12, string_value="stable")), 0.1) == []


@pytest.mark.slow
def test_rebirth_asks_a_node_born_before_the_view_started(tmp_path: Path) -> None:
    with spb.broker(tmp_path) as port:
        edge = open_edge(SparkplugOptions(f"mqtt://127.0.0.1:{port}", "g", "e"), [("grip", {})])
        edge.start()
        try:
            assert edge.wait_connected(5)
            edge.devices[0].publish(_pub(1, 0))
            proc = subprocess.Popen([sys.executable, "-m", "eskin_industrial", "plant", f"mqtt://127.0.0.1:{port}",
                                     "--json", "--rebirth", "--duration", "4"], stdout=subprocess.PIPE,
                                    stderr=subprocess.DEVNULL, text=True, env={**os.environ, "PYTHONPATH": os.getcwd()})
            first = proc.stdout.readline()  # "connected": its subscription in place (the SUBACK)
            edge.devices[0].publish(_pub(3, 1))  # data of a node the view has not seen born
            out, _ = proc.communicate(timeout=15)
            out = first + out
            rebirths = edge.rebirths
        finally:
            edge.close()
    events = [json.loads(x) for x in out.splitlines()]
    names = [e["event"] for e in events]
    assert names[:2] == ["connected", "unborn"] and rebirths == 1
    assert names.count("online") == 2
    states = [e["state"] for e in events if e["event"] == "state"]
    assert states == ["slip"], "the rebirth's DBIRTH carries the newest values"
