"""Store-and-forward of the Sparkplug edge node on real brokers: a broker killed and
another started on its port, every data message of the outage checked one by one as
``mosquitto_sub`` received it (decoded by the ``protobuf`` package), at the
specification's QoS 0 and at the opt-in QoS 1; the bound and its overflow counted
exactly, and a queue on disk that outlives the edge node."""

from __future__ import annotations

import os
import signal
import sqlite3
import struct
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from eskin_industrial.node import NodeSnapshot
from eskin_industrial.outputs.sparkplug.edge import EdgeNode
from eskin_industrial.outputs.sparkplug.kind import open_edge
from eskin_industrial.outputs.sparkplug.metrics import DEVICE_METRICS
from eskin_industrial.outputs.sparkplug.options import SparkplugOptions
from tests.helpers import sparkplug as spb
from tests.helpers.bridge import wait_for
from tests.helpers.modbus import free_port
from tests.helpers.snapshots import made
from tests.helpers.sparkplug import state_home  # noqa: F401  (autouse: a state folder of its own)

SLIP_EVENTS = next(i for i, m in enumerate(DEVICE_METRICS) if m.name == "Counters/Slip Events")
STATE_CODE = next(i for i, m in enumerate(DEVICE_METRICS) if m.name == "State Code")


def publication(i: int) -> NodeSnapshot:
    """The i-th publication: a state change every time (a DDATA at once), and ``i`` in
    the slip events counter, by which each message is known."""
    return made(state=i % 4, slip_events=i)


def edge(port: int, tmp_path: Path, **kw: Any) -> EdgeNode:
    opts = SparkplugOptions(f"mqtt://127.0.0.1:{port}", "g", "e", reconnect_min_s=2.0, reconnect_max_s=2.0, **kw)
    node = open_edge(opts, [("grip", {})])
    events: list = []
    node.events = events  # type: ignore[attr-defined]
    node.devices[0].on_events(lambda name, level, fields: events.append((name, level, fields)))
    return node


def ddata(msgs):
    """(slip events, historical, payload timestamp, metric timestamp) of every DDATA, in arrival order."""
    out = []
    for t, p in msgs:
        if "/DDATA/" not in t:
            continue
        payload = spb.parse(p)
        by_alias = {m.alias: m for m in payload.metrics}
        m = by_alias[1000 + SLIP_EVENTS]
        hist = {x.is_historical for x in payload.metrics}
        assert len(hist) == 1, "a message is historical as a whole"
        out.append((spb.value(m), hist.pop(), payload.timestamp, m.timestamp if m.HasField("timestamp") else None))
    return out


def births_then_data(msgs) -> None:
    kinds = [t.split("/")[2] for t, _ in msgs]
    assert kinds[:2] == ["NBIRTH", "DBIRTH"], kinds[:5]
    seqs = [spb.parse(p).seq for t, p in msgs if "/NDEATH/" not in t]
    assert seqs == [s % 256 for s in range(len(seqs))], "seq +1 from the NBIRTH, no gap"


@pytest.mark.slow
@pytest.mark.parametrize("qos1", [False, True], ids=["qos0", "nonconforming_qos1"])
def test_a_broker_killed_mid_run_loses_nothing_within_the_bound(tmp_path: Path, qos1: bool) -> None:
    """Messages flow at ~200/s while broker A is killed and broker B comes up on its
    port: each one arrives once live (at A or B) or as historical at B, after B's births;
    the historical ones in order, each metric with the time it was made, the payload
    with the time it was sent.  At QoS 0 what A had not handed back to the node (its
    own DDATA, subscribed) is sent again; at QoS 1 what A had not acknowledged."""
    first = spb.Broker(tmp_path)
    port = first.port
    cap_a = spb.Capture(port, tmp_path / "a.txt")
    second = cap_b = None
    node = edge(port, tmp_path, store_dir=str(tmp_path / "store"), nonconforming_qos1=qos1)
    made: dict[int, tuple[int, int]] = {}
    stop = threading.Event()
    dev = node.devices[0]

    def feed() -> None:
        i = 0
        while not stop.is_set():
            before = int(time.time() * 1000)
            dev.publish(publication(i))
            made[i] = (before, int(time.time() * 1000))
            i += 1
            time.sleep(0.005)

    feeder = threading.Thread(target=feed)
    try:
        node.start()
        assert node.wait_connected(5)
        feeder.start()
        wait_for(lambda: len(made) > 100, what="live traffic")
        first.kill()
        wait_for(lambda: node.failures == 1, what="the loss seen")
        cap_a.close()
        second = spb.Broker(tmp_path, port)  # the node retries 2 s after the loss: B and its
        cap_b = spb.Capture(port, tmp_path / "b.txt")  # subscriber are up before
        assert node.connects == 1, "reconnected before the subscriber was ready"
        wait_for(lambda: node.connects == 2, timeout_s=10, what="reconnected")
        wait_for(lambda: node.forwarder.pending == 0 and node.forwarder.forwarded > 0, what="forwarded")
        time.sleep(0.2)
        stop.set()
        feeder.join(5)
        n = len(made)
        msgs_b = cap_b.wait(lambda m: n - 1 in [v for v, *_ in ddata(m)])
        resent = node.counters()["sparkplug_resent"]
    finally:
        stop.set()
        node.close()
        for b in (first, second):
            if b is not None:
                b.kill()
        if cap_b is not None:
            cap_b.close()
    a = ddata(cap_a.messages())  # what A received before it died
    b = ddata(msgs_b)
    births_then_data(msgs_b)
    historical = [v for v, h, *_ in b if h]
    live_b = [v for v, h, *_ in b if not h]
    assert historical == sorted(historical) and len(set(historical)) == len(historical)
    assert historical, "the outage's messages came as historical"
    assert all(not h for _, h, *_ in a)
    received = [v for v, *_ in a] + historical + live_b
    assert sorted(set(received)) == list(range(n)), f"lost: {sorted(set(range(n)) - set(received))[:10]}"
    # a duplicate only where a message reached A and its acknowledgement (QoS 1) or its
    # echo (QoS 0) died with it: each one counted in sparkplug_resent
    dups = len(received) - n
    assert dups == len(set(v for v, *_ in a) & set(historical)) <= resent <= 20, (dups, resent)
    nbirth_ts = spb.parse(next(p for t, p in msgs_b if "/NBIRTH/" in t)).timestamp
    for v, h, ts, mts in b:
        if h:
            assert made[v][0] <= mts <= made[v][1], "a historical metric: the time it was made"
            # milliseconds: a scan made in the millisecond the NBIRTH was stamped, while the
            # session was not yet up, is held and sent after it with the same stamp
            assert ts >= nbirth_ts >= mts, "a historical payload: the time it was sent, after the births"
    assert node.forwarder.overflow == 0 and node.counters()["sparkplug_store_overflow"] == 0
    names = [e[0] for e in node.events]  # type: ignore[attr-defined]
    assert names.count("sparkplug_store_holding") == 1 and names.count("sparkplug_store_forwarded") == 1
    assert "sparkplug_store_full" not in names


@pytest.mark.slow
def test_frames_a_dying_broker_took_are_counted_not_sent_again(tmp_path: Path) -> None:
    """A frame is not held (the next one replaces it): what the connection takes with
    it unconfirmed is counted (``sparkplug_frames_lost``).  The broker is stopped
    (SIGSTOP: it reads nothing, hands nothing back) while 15 frames are written to it,
    then killed: those 15 are counted, the 20 before it, seen back, are not."""
    broker = spb.Broker(tmp_path)
    cap = spb.Capture(broker.port, tmp_path / "a.txt")
    node = edge(broker.port, tmp_path, frame_interval_s=0.05)
    dev = node.devices[0]

    def frames_seen() -> list[bytes]:
        return [spb.parse(p).metrics[0].bytes_value[:4] for t, p in cap.messages() if "/DDATA/" in t]

    try:
        node.start()
        assert node.wait_connected(5)
        for i in range(20):
            node.send_frame(dev, struct.pack("<25f", i, *([0.0] * 24)))
        wait_for(lambda: not node.inflight and len(frames_seen()) == 20, what="20 frames seen back")
        os.kill(broker.proc.pid, signal.SIGSTOP)
        for i in range(20, 35):
            node.send_frame(dev, struct.pack("<25f", i, *([0.0] * 24)))
        time.sleep(0.2)
        broker.kill()
        wait_for(lambda: node.failures == 1, what="the loss seen")
        counters = dev.counters()
    finally:
        node.close()
        broker.kill()
        cap.close()
    assert [struct.unpack("<f", b)[0] for b in frames_seen()] == list(range(20))
    assert counters["sparkplug_frames"] == 35 and counters["sparkplug_frames_lost"] == 15
    assert node.forwarder.held == 0, "frames are never held"


@pytest.mark.slow
def test_past_the_bound_the_overflow_is_counted_exactly(tmp_path: Path) -> None:
    """50 messages during an outage into a bound of 20: the first 20 arrive as
    historical, in order; 30 are counted (node metric, counter, one log line)."""
    first = spb.Broker(tmp_path)
    port = first.port
    second = cap = None
    node = edge(port, tmp_path, store_max=20)
    dev = node.devices[0]
    try:
        node.start()
        assert node.wait_connected(5)
        for i in range(5):
            dev.publish(publication(i))
        wait_for(lambda: not node.inflight, what="seen back from the broker")
        first.kill()
        wait_for(lambda: node.failures == 1, what="the loss seen")
        for i in range(5, 55):
            dev.publish(publication(i))
        second = spb.Broker(tmp_path, port)
        cap = spb.Capture(port, tmp_path / "b.txt")
        assert node.connects == 1
        wait_for(lambda: node.connects == 2, timeout_s=10, what="reconnected")
        msgs = cap.wait(lambda m: any("/NDATA/" in t for t, _ in m))
        c = node.counters()
    finally:
        node.close()
        for b in (first, second):
            if b is not None:
                b.kill()
        if cap is not None:
            cap.close()
    births_then_data(msgs)
    b = ddata(msgs)
    assert [v for v, h, *_ in b if h] == list(range(5, 25))
    assert c["sparkplug_store_overflow"] == 30 and c["sparkplug_store_held"] == 20
    assert c["sparkplug_store_forwarded"] == 20 and c["sparkplug_store_pending"] == 0
    nbirth = spb.parse(next(p for t, p in msgs if "/NBIRTH/" in t))
    assert spb.metric_value(nbirth, "Store/Overflow") == 30
    ndata = spb.parse(next(p for t, p in msgs if "/NDATA/" in t))
    assert {m.alias: spb.value(m) for m in ndata.metrics} == {5: 0, 6: 30}
    full = [e for e in node.events if e[0] == "sparkplug_store_full"]  # type: ignore[attr-defined]
    assert len(full) == 1 and full[0][1] == "warning" and full[0][2]["bound"] == 20
    (fwd,) = [e for e in node.events if e[0] == "sparkplug_store_forwarded"]  # type: ignore[attr-defined]
    assert fwd[2]["forwarded"] == 20 and fwd[2]["overflow"] == 30


@pytest.mark.slow
def test_the_queue_on_disk_outlives_the_edge_node(tmp_path: Path) -> None:
    """No broker at all: 30 messages held on disk when the node stops; a new node on the
    same folder sends them, as historical, after its births."""
    port = free_port()
    store = tmp_path / "store"
    node = edge(port, tmp_path, store_dir=str(store))
    node.start()
    for i in range(30):
        node.devices[0].publish(publication(i))
    wait_for(lambda: node.forwarder.rows == 30, what="on disk")
    node.close()
    assert sorted(f.name for f in store.iterdir()) == ["g-e.bdseq", "g-e.sqlite3"]  # (bdSeq: kept beside it)
    f = store / "g-e.sqlite3"
    with sqlite3.connect(f) as db:  # the file as any SQLite reader sees it
        assert db.execute("SELECT COUNT(*) FROM held").fetchone()[0] == 30
    broker = spb.Broker(tmp_path, port)
    cap = spb.Capture(port, tmp_path / "sub.txt")
    again = edge(port, tmp_path, store_dir=str(store))
    try:
        again.start()
        msgs = cap.wait(lambda m: any("/NDATA/" in t for t, _ in m))
    finally:
        again.close()
        broker.kill()
        cap.close()
    births_then_data(msgs)
    assert [(v, h) for v, h, *_ in ddata(msgs)] == [(i, True) for i in range(30)]
    with sqlite3.connect(f) as db:
        assert db.execute("SELECT COUNT(*) FROM held").fetchone()[0] == 0


def test_store_options_are_checked():
    with pytest.raises(ValueError, match="reconnect_max_s: 1 is below reconnect_min_s"):
        SparkplugOptions("mqtt://h:1", "g", "e", reconnect_min_s=2, reconnect_max_s=1)


def test_check_finds_a_store_dir_that_cannot_be_written(tmp_path):
    from eskin_industrial.outputs.sparkplug.kind import SparkplugKind

    f = tmp_path / "a-file"
    f.write_text("")
    with pytest.raises(ValueError, match="store_dir: .* is not a writable folder"):
        SparkplugKind.check(SparkplugOptions("mqtt://h:1", "g", "e", store_dir=str(f / "sub")), [])
    SparkplugKind.check(SparkplugOptions("mqtt://h:1", "g", "e", store_dir=str(tmp_path / "new" / "dir")), [])


def test_a_store_that_fails_to_write_is_counted_and_logged_and_goes_on():
    from eskin_industrial.outputs.sparkplug.store import Forwarder, Held

    events: list = []
    f = Forwarder(":memory:", 10, lambda *a: False, lambda: False, lambda *a, **k: events.append((a, k))).start()
    try:
        for i in range(3):
            f.hold(Held(i, "grip", 1000, i, ()))
        wait_for(lambda: f.rows == 3, what="written")
        f.db.close()  # any sqlite3.Error from here on
        for i in range(3, 5):
            f.hold(Held(i, "grip", 1000, i, ()))
        wait_for(lambda: f.failures == 1, what="the failure seen")
        assert f.overflow == 2 and f._thread.is_alive()
        ((name, level), fields) = [e for e in events if e[0][0] == "sparkplug_store_failed"][0]
        assert level == "error" and fields["failures"] == 1
    finally:
        f.stop()


def test_a_store_that_cannot_be_made_goes_on_in_memory_with_its_bound(tmp_path):
    """``store_dir`` under a file (the folder cannot be made): the store is in memory,
    the same bound, past it counted as overflow; one line at start, naming the file and
    the OS error (before: the exception, out of the edge node's constructor)."""
    from eskin_industrial.outputs.sparkplug.store import Forwarder, Held

    (tmp_path / "a-file").write_text("")
    path = str(tmp_path / "a-file" / "g-e.sqlite3")
    events: list = []
    f = Forwarder(path, 3, lambda *a: False, lambda: False, lambda *a, **k: events.append((a, k)))
    assert not f.on_disk and events == [], "said at start, once the node's log is there"
    f.start()
    try:
        for i in range(5):
            f.hold(Held(i, "grip", 1000, i, ()))
        wait_for(lambda: f.rows == 3 and f.overflow == 2, what="held in memory, the bound kept")
        lines = [(a, k) for a, k in events if a[0] == "sparkplug_store_in_memory"]
        assert len(lines) == 1 and lines[0][0][1] == "error", events
        fields = lines[0][1]
        assert fields["store"] == path and fields["error"] == "File exists" and fields["bound"] == 3, fields
    finally:
        f.close()
    assert not (tmp_path / "a-file").is_dir()


def test_a_store_whose_file_fails_mid_run_keeps_the_batch_in_memory_and_the_file_whole(tmp_path):
    """The file's connection fails between two writes: the batch goes to memory (none
    lost), one line; the rows already in the file stay there for the next start."""
    from eskin_industrial.outputs.sparkplug.store import Forwarder, Held

    path = str(tmp_path / "g-e.sqlite3")
    events: list = []
    f = Forwarder(path, 100, lambda *a: False, lambda: False, lambda *a, **k: events.append((a, k))).start()
    try:
        for i in range(3):
            f.hold(Held(i, "grip", 1000, i, ()))
        wait_for(lambda: f.rows == 3, what="on disk")
        f.db.close()  # any sqlite3.Error from here on
        for i in range(3, 7):
            f.hold(Held(i, "grip", 1000, i, ()))
        wait_for(lambda: f.rows == 4, what="in memory")
        assert not f.on_disk and f.overflow == 0 and f.left_on_disk == 3 and f.held == 7 and f.failures == 1
        assert [a[0] for a, _ in events if a[0].startswith("sparkplug_store_")] == [
            "sparkplug_store_holding", "sparkplug_store_in_memory"], events
    finally:
        f.close()
    with sqlite3.connect(path) as db:
        assert [r[0] for r in db.execute("SELECT serial FROM held ORDER BY serial")] == [0, 1, 2]
