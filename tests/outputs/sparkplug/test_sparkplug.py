"""The Sparkplug B output kind on a real broker: mosquitto on a loopback port of the
test's own, ``mosquitto_sub`` capturing what is published, and every payload decoded
by the ``protobuf`` package from the tests' own schema (not by the package's codec)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from eskin_industrial.bridge.config import BridgeConfig, LogSettings, NodeConfig
from eskin_industrial.errors import ProfileError
from eskin_industrial.outputs.base import SINKS, output_kind
from eskin_industrial.outputs.sparkplug import payload as pb
from eskin_industrial.outputs.sparkplug.commands import COMMANDS
from eskin_industrial.outputs.sparkplug.kind import SparkplugKind, open_edge
from eskin_industrial.outputs.sparkplug.metrics import DEVICE_METRICS
from eskin_industrial.outputs.sparkplug.options import SparkplugOptions
from tests.helpers import sparkplug as spb
from tests.helpers.bridge import PAPER, channel, node_thread, running_bridge, server_config, slip_raw, wait_for
from tests.helpers.paths import PROFILES
from tests.helpers.snapshots import made
from tests.helpers.sparkplug import state_home  # noqa: F401  (autouse: a state folder of its own)

# -- the codec against protobuf ------------------------------------------------------
_VALUES = {
    pb.INT8: st.integers(-128, 127), pb.INT32: st.integers(-2**31, 2**31 - 1), pb.UINT32: st.integers(0, 2**32 - 1),
    pb.INT64: st.integers(-2**63, 2**63 - 1), pb.UINT64: st.integers(0, 2**64 - 1),
    pb.FLOAT: st.floats(width=32, allow_nan=False), pb.DOUBLE: st.floats(allow_nan=False),
    pb.BOOLEAN: st.booleans(), pb.STRING: st.text(max_size=20), pb.BYTES: st.binary(max_size=20),
}
_metric = st.sampled_from(sorted(_VALUES)).flatmap(lambda dt: st.builds(
    pb.Metric, name=st.none() | st.text(max_size=10), alias=st.none() | st.integers(0, 2**64 - 1),
    timestamp=st.none() | st.integers(0, 2**64 - 1), datatype=st.just(dt), value=_VALUES[dt],
    properties=st.lists(st.tuples(st.text(max_size=5), st.tuples(st.just(pb.STRING), st.text(max_size=5))),
                        max_size=2).map(tuple)))
_payload = st.builds(pb.Payload, timestamp=st.none() | st.integers(0, 2**64 - 1),
                     metrics=st.lists(_metric, max_size=4).map(tuple), seq=st.none() | st.integers(0, 255))


def _same(ours: pb.Payload, theirs) -> None:
    assert theirs.HasField("timestamp") == (ours.timestamp is not None)
    assert (theirs.timestamp if theirs.HasField("timestamp") else None) == ours.timestamp
    assert (theirs.seq if theirs.HasField("seq") else None) == ours.seq
    assert len(theirs.metrics) == len(ours.metrics)
    for a, b in zip(ours.metrics, theirs.metrics):
        assert (b.name if b.HasField("name") else None) == a.name
        assert (b.alias if b.HasField("alias") else None) == a.alias
        assert b.datatype == a.datatype and spb.value(b) == a.value
        assert [(k, (v.type, v.string_value)) for k, v in zip(b.properties.keys, b.properties.values)] == \
            list(a.properties)


@settings(max_examples=200, deadline=None)
@given(_payload)
def test_our_encoding_reads_back_with_protobuf_and_theirs_with_ours(p):
    _same(p, spb.parse(pb.encode(p)))
    # protobuf's encoding of the same message, read by our decoder
    assert pb.decode(spb.parse(pb.encode(p)).SerializeToString()) == p


@given(st.binary(max_size=40))
def test_garbage_is_one_error_or_a_payload(data):
    try:
        pb.decode(data)
    except pb.PayloadError:
        pass


# -- options ------------------------------------------------------------------------
def test_the_kind_is_one_registry_entry_and_checks_its_options():
    assert output_kind("sparkplug") is SparkplugKind and "sparkplug" in SINKS
    with pytest.raises(ValueError, match="expected mqtt://HOST:PORT"):
        SparkplugOptions("tcp://x:1", "g", "e")
    with pytest.raises(ValueError, match="expected mqtt://HOST:PORT"):
        SparkplugOptions("mqtt://x:99999", "g", "e")
    with pytest.raises(ValueError, match="group_id: 'a/b' is not a Sparkplug id"):
        SparkplugOptions("mqtt://x:1", "a/b", "e")
    with pytest.raises(ValueError, match="edge_node_id: '#' is not"):
        SparkplugOptions("mqtt://x:1", "g", "#")
    assert SparkplugKind.options_from_cli({}) is None
    with pytest.raises(ValueError, match="give --group-id and --edge-node-id"):
        SparkplugKind.options_from_cli({"sparkplug": "mqtt://h:1", "group_id": "g"})


def test_sparkplug_section_in_a_file(tmp_path):
    from eskin_industrial.bridge.config import load_bridge_config, resolve

    cfg = tmp_path / "b.toml"
    body = (f'[sparkplug]\nbroker = "mqtt://127.0.0.1:1883"\ngroup_id = "plant1"\nedge_node_id = "cell7"\n'
            f'deadband = 0.05\n\n[[node]]\nname = "grip"\nprofile = "{PAPER}"\nsource = "scene"\nscene = "case2"\n')
    cfg.write_text(body)
    config = load_bridge_config(cfg)
    assert list(config.output_kinds()) == ["sparkplug"] and config.outputs["sparkplug"].deadband == 0.05
    resolve(config)
    cfg.write_text(body.replace('name = "grip"', 'name = "a+b"'))
    with pytest.raises(ProfileError, match=r"\[sparkplug\].*'a\+b' is not a Sparkplug id"):
        resolve(load_bridge_config(cfg))
    cfg.write_text(body.replace("mqtt://", "http://"))
    with pytest.raises(ProfileError, match="expected mqtt://HOST:PORT"):
        load_bridge_config(cfg)


# -- on a real broker ------------------------------------------------------------------
def _decoded(msgs):
    """Every message the node published (the commands sent to it left out)."""
    return [(t.split("/")[2], t, spb.parse(p)) for t, p in msgs if "/NCMD/" not in t]


def _check_sequence(decoded, device="grip"):
    """NBIRTH first with seq 0; seq +1 mod 256 over everything but NDEATH; aliases."""
    kinds = [k for k, _, _ in decoded]
    assert kinds[0] == "NBIRTH" and decoded[0][2].seq == 0
    bd_seq = spb.metric_value(decoded[0][2], "bdSeq")
    seqs = [p.seq for k, _, p in decoded if k not in ("NDEATH", "NCMD")]
    for a, b in zip(seqs, seqs[1:]):
        assert b == (a + 1) % 256 or b == 0, seqs  # 0: a rebirth's NBIRTH
    assert [k for k in kinds if k not in ("NCMD",)][-2:] == ["DDEATH", "NDEATH"]
    assert spb.metric_value(decoded[-1][2], "bdSeq") == bd_seq
    births = [p for k, _, p in decoded if k == "DBIRTH"]
    assert births
    declared = {m.alias: (m.name, m.datatype) for m in births[0].metrics}
    assert [n for n, _ in declared.values()] == [m.name for m in DEVICE_METRICS] + [c.name for c in COMMANDS]
    assert all(dt == m.datatype for (_, dt), m in zip(declared.values(), DEVICE_METRICS))
    units = {m.name: dict(zip(m.properties.keys, [v.string_value for v in m.properties.values]))
             for m in births[0].metrics}
    assert units["Total Force"] == {"engUnit": "N"}
    # the deciding method's scores, declared with whose and which they are
    assert (units["Score A"]["method"], units["Score A"]["score"]) == ("cof-track", "onset_score")
    assert (units["Score B"]["method"], units["Score B"]["score"]) == ("cof-track", "slow_score")
    states = []
    for k, t, p in decoded:
        if k == "DDATA":
            assert t.endswith(f"/{device}")
            for m in p.metrics:
                assert not m.HasField("name") and m.alias in declared
                if declared[m.alias][0] == "State":
                    states.append(spb.value(m))
                elif declared[m.alias][0] == "Score A":
                    states.append(("Score A", spb.value(m)))
                elif declared[m.alias][0] == "Turn Unseen":
                    states.append(("Turn Unseen", spb.value(m)))
    return states, bd_seq


@pytest.mark.slow
@pytest.mark.parametrize("with_plc", [False, True])
def test_a_bridge_publishes_births_the_slip_and_deaths(paper_profile, tmp_path, with_plc):
    ch = channel()
    with spb.broker(tmp_path) as port:
        cap = spb.Capture(port, tmp_path / "sub.txt")
        try:
            node = NodeConfig.of("grip", PAPER, "can", interface="virtual", channel=ch)
            outputs = {"sparkplug": SparkplugOptions(f"mqtt://127.0.0.1:{port}", "plant1", "cell7")}
            if with_plc:
                outputs = {**server_config(node).outputs, **outputs}
            config = BridgeConfig((node,), outputs, LogSettings(format="json", status_every_s=0))
            raw, _ = slip_raw(paper_profile)
            with running_bridge(config) as run:
                wait_for(lambda: run.bridge.counters()["grip"]["sparkplug_connects"] == 1, what="connected")
                cap.wait(lambda m: any("/DBIRTH/" in t for t, _ in m))
                with node_thread(paper_profile, ch, raw) as nt:
                    nt.start()
                    nt.join(15)
                cap.wait(lambda m: any(b"slip" in p for t, p in m if "/DDATA/" in t))
            msgs = cap.wait(lambda m: any("/NDEATH/" in t for t, _ in m))
        finally:
            cap.close()
    decoded = _decoded(msgs)
    states, _ = _check_sequence(decoded)
    # cof-track's onset score passes its threshold (1) in the slide
    scores = [s[1] for s in states if isinstance(s, tuple) and s[0] == "Score A"]
    assert scores and max(scores) > 1.0
    # TURN_UNSEEN: set on contact until the torsion channel has looked at the block's
    # footprint, then clear (a 20 mm block shows a turn), each change sent at once
    unseen = [s[1] for s in states if isinstance(s, tuple) and s[0] == "Turn Unseen"]
    assert unseen[-2:] == [True, False], unseen
    states = [s for s in states if not isinstance(s, tuple)]
    assert "slip" in states and states[states.index("slip") - 1] != "slip"
    topics = {t for _, t, _ in decoded}
    # NDATA: the store's metrics, when what came before the connection was forwarded
    assert topics - {"spBv1.0/plant1/NDATA/cell7"} == {f"spBv1.0/plant1/{k}/cell7" for k in ("NBIRTH", "NDEATH")} | \
        {f"spBv1.0/plant1/{k}/cell7/grip" for k in ("DBIRTH", "DDATA", "DDEATH")}


@pytest.mark.slow
def test_ncmd_rebirth_and_malformed_commands(tmp_path):
    import paho.mqtt.client as mqtt

    with spb.broker(tmp_path) as port:
        cap = spb.Capture(port, tmp_path / "sub.txt")
        try:
            node = NodeConfig.of("grip", PAPER, "scene", scene="hold")
            config = BridgeConfig((node,), {"sparkplug": SparkplugOptions(f"mqtt://127.0.0.1:{port}", "g", "e")},
                                  LogSettings(format="json", status_every_s=0))
            with running_bridge(config) as run:
                cap.wait(lambda m: any("/DBIRTH/" in t for t, _ in m))
                cmd = spb.Payload(timestamp=1)
                m = cmd.metrics.add(name="Node Control/Rebirth", datatype=11, boolean_value=True)
                assert m.boolean_value
                pub = mqtt.Client(callback_api_version=mqtt.CallbackAPIVersion.VERSION2)
                pub.connect("127.0.0.1", port)
                pub.loop_start()
                try:
                    pub.publish("spBv1.0/g/NCMD/e", b"\xff\xff\xff", qos=1).wait_for_publish(5)
                    pub.publish("spBv1.0/g/NCMD/e", cmd.SerializeToString(), qos=1).wait_for_publish(5)
                    wait_for(lambda: run.bridge.counters()["grip"]["sparkplug_rebirths"] == 1, what="rebirth")
                    assert run.bridge.counters()["grip"]["sparkplug_bad_commands"] == 1
                    cap.wait(lambda m: sum("/NBIRTH/" in t for t, _ in m) == 2
                             and sum("/DBIRTH/" in t for t, _ in m) == 2)
                finally:
                    pub.disconnect()
                    pub.loop_stop()
                    pub._reset_sockets()  # its wake-up socket pair (tests/test_private_apis.py)
            msgs = cap.wait(lambda m: any("/NDEATH/" in t for t, _ in m))
        finally:
            cap.close()
    decoded = _decoded(msgs)
    _check_sequence(decoded)
    nbirths = [p for k, _, p in decoded if k == "NBIRTH"]
    assert [p.seq for p in nbirths] == [0, 0]
    assert spb.metric_value(nbirths[0], "bdSeq") == spb.metric_value(nbirths[1], "bdSeq")


def _cli(port: int, *extra: str) -> list[str]:
    return [sys.executable, "-m", "eskin_industrial", "bridge", "-p", str(PROFILES / "paper-5x5.toml"),
            "--source", "scene:case2", "--sparkplug", f"mqtt://127.0.0.1:{port}", "--group-id", "plant1",
            "--edge-node-id", "cell7", *extra]


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM, signal.SIGHUP], ids=lambda s: s.name)
def test_the_command_line_bridge_dies_with_ndeath(tmp_path, sig):
    """SIGKILL: the broker delivers the will; SIGTERM and SIGHUP (a closed terminal):
    the bridge sends DDEATH and NDEATH, and exits 0."""
    with spb.broker(tmp_path) as port:
        cap = spb.Capture(port, tmp_path / "sub.txt")
        proc = subprocess.Popen(_cli(port), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                env={**os.environ, "PYTHONPATH": os.getcwd()})
        try:
            cap.wait(lambda m: any("/DDATA/" in t for t, _ in m), timeout_s=20)
            os.kill(proc.pid, sig)
            proc.wait(10)
            msgs = cap.wait(lambda m: any("/NDEATH/" in t for t, _ in m), timeout_s=10)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait(5)
            proc.stderr.close()
            cap.close()
    decoded = _decoded(msgs)
    kinds = [k for k, _, _ in decoded]
    assert kinds[0] == "NBIRTH" and kinds[-1] == "NDEATH"
    assert spb.metric_value(decoded[-1][2], "bdSeq") == spb.metric_value(decoded[0][2], "bdSeq")
    assert ("DDEATH" in kinds) == (sig != signal.SIGKILL)
    assert proc.returncode == (-signal.SIGKILL if sig == signal.SIGKILL else 0)


def test_check_describes_the_output(tmp_path):
    out = subprocess.run(_cli(1883, "--check"), capture_output=True, text=True, timeout=60,
                         env={**os.environ, "PYTHONPATH": os.getcwd()})
    assert out.returncode == 0, out.stderr
    assert "Sparkplug B spBv1.0/plant1/DDATA/cell7/" in out.stdout + out.stderr
    bad = subprocess.run(_cli(1883)[:-6] + ["--sparkplug", "mqtt:/nohost", "--group-id", "g", "--edge-node-id", "e",
                                            "--check"], capture_output=True, text=True, timeout=60,
                         env={**os.environ, "PYTHONPATH": os.getcwd()})
    assert bad.returncode != 0 and "expected mqtt://HOST:PORT" in bad.stderr


def test_the_metric_table_in_the_docs_is_the_code():
    from eskin_industrial.outputs.sparkplug.metrics import metric_table
    from tests.helpers.paths import ROOT

    text = (ROOT / "docs" / "plant.md").read_text()
    assert "\n".join(metric_table()) in text


@pytest.mark.slow
def test_a_broker_restart_is_a_new_session_with_the_next_bdseq(tmp_path):
    """The broker dies and comes back on its port: the node reconnects by itself and
    births again with bdSeq + 1 (its will for the new session)."""
    first = spb.Broker(tmp_path)
    second = None
    try:
        node = NodeConfig.of("grip", PAPER, "scene", scene="hold")
        config = BridgeConfig((node,), {"sparkplug": SparkplugOptions(f"mqtt://127.0.0.1:{first.port}", "g", "e")},
                              LogSettings(format="json", status_every_s=0))
        with running_bridge(config) as run:
            counters = lambda: run.bridge.counters()["grip"]  # noqa: E731
            wait_for(lambda: counters()["sparkplug_connects"] == 1, what="connected")
            first.kill()
            wait_for(lambda: counters()["sparkplug_failures"] == 1, what="the loss seen")
            second = spb.Broker(tmp_path, first.port)
            cap = spb.Capture(second.port, tmp_path / "sub.txt")
            try:
                wait_for(lambda: counters()["sparkplug_connects"] == 2, timeout_s=15, what="reconnected")
                # the births of the reconnect may precede the subscription: ask again
                spb.send_rebirth(second.port, "g", "e", tmp_path)
                msgs = cap.wait(lambda m: any("/DBIRTH/" in t for t, _ in m))
            finally:
                cap.close()
    finally:
        first.kill()
        if second is not None:
            second.kill()
    nbirths = [spb.parse(p) for t, p in msgs if "/NBIRTH/" in t]
    assert all(p.seq == 0 and spb.metric_value(p, "bdSeq") == 1 for p in nbirths) and nbirths


def _check(*extra: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(_cli(1883, *extra, "--check"), capture_output=True, text=True, timeout=60,
                          env={**os.environ, "PYTHONPATH": os.getcwd(), **(env or {})})


def test_qos_1_for_data_is_an_explicit_opt_in_warned_about(tmp_path: Path) -> None:
    """Sparkplug's QoS 0 for births and data is the default; ``qos = 1`` is refused in
    one line naming the file and the key and the opt-in; ``nonconforming_qos1`` is
    warned about by ``--check`` (and at start, below)."""
    cfg = tmp_path / "b.toml"
    cfg.write_text(f'[sparkplug]\nbroker = "mqtt://127.0.0.1:1883"\ngroup_id = "g"\nedge_node_id = "e"\nqos = 1\n\n'
                   f'[[node]]\nname = "grip"\nprofile = "{PAPER}"\nsource = "scene"\nscene = "case2"\n')
    bad = subprocess.run([sys.executable, "-m", "eskin_industrial", "bridge", "--config", str(cfg), "--check"],
                         capture_output=True, text=True, timeout=60, env={**os.environ, "PYTHONPATH": os.getcwd()})
    lines = bad.stderr.strip().splitlines()
    assert bad.returncode == 2 and len(lines) == 1 and str(cfg) in lines[0] and "qos" in lines[0] and \
        "nonconforming_qos1 = true" in lines[0], bad.stderr
    quiet = _check()
    assert quiet.returncode == 0 and "warning" not in quiet.stderr, quiet.stderr
    loud = _check("--sparkplug-nonconforming-qos1")
    assert loud.returncode == 0 and "eskin-bus: warning: [sparkplug] nonconforming_qos1: " in loud.stderr, loud.stderr


def test_a_state_folder_that_cannot_be_written_is_a_warning_not_an_error(tmp_path: Path) -> None:
    """bdSeq kept across restarts needs a folder: without one (here the state folder
    is under a file) the run goes on from 0 at each start, and says so."""
    f = tmp_path / "a-file"
    f.write_text("")
    out = _check(env={"STATE_DIRECTORY": str(f / "sub")})
    assert out.returncode == 0 and "warning: [sparkplug] bdSeq is not kept across restarts" in out.stderr, out.stderr
    assert "give store_dir" in out.stderr
    assert "warning" not in _check("--sparkplug-store-dir", str(tmp_path / "store"),
                                   env={"STATE_DIRECTORY": str(f / "sub")}).stderr


@pytest.mark.slow
def test_nonconforming_qos1_publishes_at_qos_1_and_says_so(tmp_path: Path) -> None:
    broker = spb.Broker(tmp_path)
    cap = spb.Capture(broker.port, tmp_path / "sub.txt", detail=True)
    edge = open_edge(SparkplugOptions(f"mqtt://127.0.0.1:{broker.port}", "g", "e", nonconforming_qos1=True),
                     [("grip", {})])
    events: list = []
    edge.devices[0].on_events(lambda name, level, fields: events.append((name, level, fields)))
    try:
        edge.start()
        assert edge.wait_connected(5)
        edge.devices[0].publish(made(state=1))
        recs = cap.wait(lambda m: any("/DDATA/" in t for t, _ in m)) and cap.records()
    finally:
        edge.close()
        cap.close()
        broker.kill()
    assert {(t.split("/")[2], q) for t, q, _, _ in recs} == {("NBIRTH", 1), ("DBIRTH", 1), ("DDATA", 1)}
    (warned,) = [e for e in events if e[0] == "sparkplug_nonconforming"]
    assert warned[1] == "warning" and "QoS 1" in warned[2]["what"]


def test_the_bdseq_file_goes_on_from_the_last_connect_and_wraps(tmp_path: Path) -> None:
    from eskin_industrial.outputs.sparkplug.bdseq import BdSeqFile, bdseq_path

    path = bdseq_path(str(tmp_path / "store"), "g", "e")
    assert path == tmp_path / "store" / "g-e.bdseq"
    f = BdSeqFile(path)
    assert f.error is None and f.previous() is None and f.first() == 0, "a first start: 0"
    assert f.write(7) is None and path.read_text() == "7\n" and BdSeqFile(path).first() == 8
    assert f.write(255) is None and BdSeqFile(path).first() == 0, "255 wraps to 0"
    path.write_text("not a number\n")
    assert BdSeqFile(path).first() == 0, "an unreadable file is a first start"
    blocked = tmp_path / "a-file"
    blocked.write_text("")
    g = BdSeqFile(blocked / "sub" / "g-e.bdseq")
    assert g.error is not None and "is not a writable folder" in g.error and g.write(1) == g.error


def test_every_key_but_qos_is_a_command_line_option() -> None:
    """docs/plant.md: every ``[sparkplug]`` key but ``qos`` (kept for old files) is also
    an option of the command line, each option sets its key, and none takes the
    password itself."""
    import dataclasses

    keys = {f.name for f in dataclasses.fields(SparkplugOptions)}
    by_option = SparkplugKind._CLI_KEYS
    assert keys - set(by_option.values()) == {"broker", "group_id", "edge_node_id", "qos"}
    dests = {o.dest: o for o in SparkplugKind.cli_options}
    assert {"sparkplug", "group_id", "edge_node_id"} <= set(dests) and set(by_option) <= set(dests)
    assert not any("password" == k for k in keys)
    sample = {bool: True, int: 7, float: 0.25, str: "x"}
    for dest, key in by_option.items():
        if key in ("cert_file", "key_file", "ca_file", "password_file", "password_env", "username", "store_dir"):
            continue  # (their files and pairs are checked elsewhere; the mapping above covers them)
        value = sample[dests[dest].type]
        opts = SparkplugKind.options_from_cli({"sparkplug": "mqtt://127.0.0.1:1883", "group_id": "g",
                                                 "edge_node_id": "e", dest: value})
        assert getattr(opts, key) == value, (dest, key)
