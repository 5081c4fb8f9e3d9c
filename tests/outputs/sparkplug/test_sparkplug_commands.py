"""Sparkplug device commands (DCMD Tare, Enable, Acknowledge Slip) on a real broker,
written by ``mosquitto_pub`` with payloads the ``protobuf`` package encodes, applied by
the bridge's loop under the PLC's rule; and whatever else arrives on the command
topics (garbage, unknown metrics, unknown devices) counted and logged, never a crash."""

from __future__ import annotations

import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

from eskin_industrial.bridge.config import BridgeConfig, LogSettings, NodeConfig
from eskin_industrial.node import Command
from eskin_industrial.outputs.sparkplug import payload as pb
from eskin_industrial.outputs.sparkplug.commands import COMMAND_ALIAS, COMMANDS, BadCommand, parse_device_command
from eskin_industrial.outputs.sparkplug.metrics import DEVICE_METRICS
from eskin_industrial.outputs.sparkplug.options import SparkplugOptions
from eskin_industrial.profile import Profile
from tests.helpers import sparkplug as spb
from tests.helpers.bridge import PAPER, channel, node_thread, running_bridge, to_raw, wait_for
from tests.helpers.modbus import need
from tests.helpers.sparkplug import state_home  # noqa: F401  (autouse: a state folder of its own)

ENABLED = 1000 + next(i for i, m in enumerate(DEVICE_METRICS) if m.name == "Enabled")


# -- the pure part ---------------------------------------------------------------------
def _cmd(*metrics: pb.Metric) -> pb.Payload:
    return pb.Payload(1, metrics)


def test_commands_by_name_and_by_alias():
    tare, ack, enable = (c.name for c in COMMANDS)
    got = parse_device_command(_cmd(pb.Metric(tare, None, None, pb.BOOLEAN, True),
                                    pb.Metric(None, 2000 + COMMAND_ALIAS + 1, None, pb.BOOLEAN, True),
                                    pb.Metric(enable, None, None, pb.BOOLEAN, False)), base=2000)
    assert got == [Command("tare"), Command("ack"), Command("disable")]


@pytest.mark.parametrize("metric, error", [
    (pb.Metric("Device Control/Tare", None, None, pb.BOOLEAN, False), "only true is a command"),
    (pb.Metric("Device Control/Tare", None, None, pb.INT32, 1), "expected a Boolean value, got 1"),
    (pb.Metric("State", None, None, pb.STRING, "slip"), "metric 'State' is not a command"),
    (pb.Metric(None, 1000 + COMMAND_ALIAS, None, pb.BOOLEAN, True), "'alias 1100' is not a command"),
    (pb.Metric(None, None, None, pb.BOOLEAN, True), "'alias None' is not a command"),
])
def test_what_is_not_a_command(metric, error):
    with pytest.raises(BadCommand, match=error):
        parse_device_command(_cmd(metric), base=2000)
    with pytest.raises(BadCommand, match="no metrics"):
        parse_device_command(_cmd(), base=2000)


# -- on a broker -------------------------------------------------------------------------
def _publish(port: int, topic: str, data: bytes, tmp_path) -> None:
    f = tmp_path / "cmd.bin"
    f.write_bytes(data)
    subprocess.run([need("mosquitto_pub"), "-h", "127.0.0.1", "-p", str(port), "-q", "1", "-t", topic, "-f", str(f)],
                   check=True, timeout=10)


def _dcmd(**named: bool) -> bytes:
    p = spb.Payload(timestamp=int(time.time() * 1000))
    for name, value in named.items():
        p.metrics.add(name=f"Device Control/{name.replace('_', ' ')}", datatype=11, boolean_value=value)
    return p.SerializeToString()


def _config(port: int, node: NodeConfig) -> BridgeConfig:
    return BridgeConfig((node,), {"sparkplug": SparkplugOptions(f"mqtt://127.0.0.1:{port}", "g", "e")},
                        LogSettings(format="json", status_every_s=0))


@pytest.mark.slow
def test_dcmds_are_applied_by_the_loop_and_garbage_is_counted(paper_profile: Profile, tmp_path: Path) -> None:
    ch = channel()
    unloaded = to_raw(paper_profile, np.zeros((400, paper_profile.taxels)))
    dcmd = "spBv1.0/g/DCMD/e/grip"
    with spb.broker(tmp_path) as port:
        cap = spb.Capture(port, tmp_path / "sub.txt")
        try:
            node = NodeConfig.of("grip", PAPER, "can", interface="virtual", channel=ch)
            with running_bridge(_config(port, node)) as run:
                c = lambda: run.counters("grip")  # noqa: E731
                loop = run.bridge.runs[0].loop
                cap.wait(lambda m: any("/DBIRTH/" in t for t, _ in m))
                # no scan yet: nothing says the gripper is open
                _publish(port, dcmd, _dcmd(Tare=True), tmp_path)
                wait_for(lambda: c()["sparkplug_commands_refused"] == 1, what="refused")
                # garbage of every kind: counted, logged, and the bridge goes on
                _publish(port, dcmd, b"\x0a\xff\xff", tmp_path)
                _publish(port, dcmd, _dcmd(Rebirth=True), tmp_path)
                _publish(port, "spBv1.0/g/DCMD/e/nosuch", _dcmd(Tare=True), tmp_path)  # not subscribed
                _publish(port, "spBv1.0/g/NCMD/e", b"\xff", tmp_path)
                wait_for(lambda: c()["sparkplug_bad_commands"] == 3, what="counted")
                time.sleep(1.05)  # one line a second: the next one counts those left out
                _publish(port, "spBv1.0/g/NCMD/e", b"\x08", tmp_path)
                wait_for(lambda: c()["sparkplug_bad_commands"] == 4, what="counted")
                with node_thread(paper_profile, ch, unloaded) as nt:
                    nt.start()
                    wait_for(lambda: loop.status.update is not None and loop.status.update.valid, timeout_s=10,
                             what="a valid no-contact state")
                    _publish(port, dcmd, _dcmd(Tare=True), tmp_path)
                    wait_for(lambda: loop.tares == 1, what="the tare applied by the loop")
                    enable = spb.Payload(timestamp=1)  # by alias, as a host that read the DBIRTH writes
                    enable.metrics.add(alias=1000 + COMMAND_ALIAS + 2, datatype=11, boolean_value=False)
                    _publish(port, dcmd, enable.SerializeToString(), tmp_path)
                    wait_for(lambda: not loop.status.enabled, what="disabled")
                    _publish(port, dcmd, _dcmd(Acknowledge_Slip=True, Enable=True), tmp_path)
                    wait_for(lambda: loop.status.enabled, what="enabled again")
                    msgs = cap.wait(lambda m: [spb.value(x) for t, p in m if "/DDATA/" in t for x in
                                               spb.parse(p).metrics if x.alias == ENABLED][-2:] == [False, True])
                    nt.join(15)
                assert c()["sparkplug_commands"] == 4 and c()["sparkplug_commands_refused"] == 1
                c_end = c()
                events = run.log.events()
        finally:
            cap.close()
    assert not run.bridge.failure
    dbirth = spb.parse(next(p for t, p in msgs if "/DBIRTH/" in t))
    declared = {m.name: (m.alias, m.datatype, spb.value(m)) for m in dbirth.metrics}
    for i, cdef in enumerate(COMMANDS):  # Enable born as Enabled reads, the others false
        want = declared["Enabled"][2] if cdef.name == "Device Control/Enable" else False
        assert declared[cdef.name] == (1000 + COMMAND_ALIAS + i, pb.BOOLEAN, want)
    names = [e["event"] for e in events]
    refused = [e for e in events if e["event"] == "sparkplug_command_refused"]
    assert [(e["command"], e["reason"], e["level"]) for e in refused] == [("tare", "contact_unknown", "warning")]
    bad = [e for e in events if e["event"] == "sparkplug_bad_command"]
    assert bad and bad[0]["topic"] == dcmd and "truncated" in bad[0]["error"]
    assert [e["not_logged"] for e in bad] == [0, 2], "one line a second, with the count of those left out"
    # each device's DCMD topic is subscribed on its own: another device's never arrives
    assert c_end["sparkplug_unknown_devices"] == 0 and "sparkplug_unknown_device" not in names
    # the loop's own record of what it applied (an acknowledge with nothing latched changes nothing)
    assert [e["command"] for e in events if e["event"] == "plc_command"] == ["tare", "disable", "enable"]
    assert "loop_failed" not in names


@pytest.mark.slow
def test_no_tare_while_something_is_held(tmp_path):
    """The "hold" scene presses at 1 s: a tare then is refused (in_contact), as a PLC's is."""
    with spb.broker(tmp_path) as port:
        node = NodeConfig.of("grip", PAPER, "scene", scene="hold")
        with running_bridge(_config(port, node)) as run:
            loop = run.bridge.runs[0].loop
            wait_for(lambda: loop.status.update is not None and loop.status.update.valid
                     and loop.status.update.state != 0, timeout_s=10, what="held")
            _publish(port, "spBv1.0/g/DCMD/e/grip", _dcmd(Tare=True), tmp_path)
            wait_for(lambda: run.counters("grip")["sparkplug_commands_refused"] == 1, what="refused")
            time.sleep(0.2)
            assert loop.tares == 0
            (e,) = run.log.events("sparkplug_command_refused")
            assert e["reason"] == "in_contact"


def _props(metric) -> dict:
    out = {}
    for k, v in zip(metric.properties.keys, metric.properties.values):
        field = {11: "boolean_value", 12: "string_value", 10: "double_value", 4: "long_value"}[v.type]
        out[k] = getattr(v, field)
    return out


@pytest.mark.slow
def test_a_source_that_ends_is_a_ddeath_while_the_bridge_goes_on(tmp_path):
    """Two nodes; one's scene ends after 2 s: its DDEATH, while the other's DDATA goes on;
    DBIRTH carries the layout and the method with its thresholds; a scans counter."""
    from eskin_industrial import scenes
    from eskin_industrial.profile import load_profile

    short = tmp_path / "short.toml"
    hold = Path(scenes.__file__).parent / "builtin" / "hold.toml"
    short.write_text(hold.read_text().replace("duration_s = 72.0", "duration_s = 2.0"))
    with spb.broker(tmp_path) as port:
        cap = spb.Capture(port, tmp_path / "sub.txt")
        try:
            nodes = (NodeConfig.of("short", PAPER, "scene", scene=str(short), loop=False),
                     NodeConfig.of("long", PAPER, "scene", scene="hold", outputs={"plc": {"base_address": 100}}))
            config = BridgeConfig(nodes, {"sparkplug": SparkplugOptions(f"mqtt://127.0.0.1:{port}", "g", "e",
                                                                        min_interval_s=0.1)},
                                  LogSettings(format="json", status_every_s=0))
            with running_bridge(config) as run:
                before = cap.wait(lambda m: any(t.endswith("/DDEATH/e/short") for t, _ in m), timeout_s=15)
                cap.wait(lambda m: len(m) > len(before) + 3
                         and any(t.endswith("/DDATA/e/long") for t, _ in m[len(before):]))
                assert run.bridge.runs[1].loop.source.done is False
            scans = {r.name: r.loop.pipeline.counters.scans for r in run.bridge.runs}
            msgs = cap.wait(lambda m: any("/NDEATH/" in t for t, _ in m))
        finally:
            cap.close()
    topics = [t for t, _ in msgs]
    ends = [i for i, t in enumerate(topics) if t.endswith("/DDEATH/e/short")]
    assert len(ends) == 1, "one DDEATH"
    assert not any(t.endswith("/short") and "/DDATA/" in t for t in topics[ends[0]:])
    assert any(t.endswith("/DDATA/e/long") for t in topics[ends[0]:topics.index("spBv1.0/g/DDEATH/e/long")])
    assert topics[-1] == "spBv1.0/g/NDEATH/e" and topics.count("spBv1.0/g/NDEATH/e") == 1
    # the DBIRTH's properties, against the profile read here
    profile = load_profile(PAPER)
    dbirth = spb.parse(next(p for t, p in msgs if t == "spBv1.0/g/DBIRTH/e/long"))
    by_name = {m.name: m for m in dbirth.metrics}
    assert _props(by_name["CoF X"]) == {"engUnit": "mm", "rows": 5, "cols": 5, "pitch_mm": profile.layout.pitch_mm}
    method = _props(by_name["State"])
    assert method["method"] == profile.detector.method == "cof-track"
    assert method["detector.cof_track.z"] == profile.detector.cof_track.z
    assert method["detector.contact_threshold_n"] == profile.detector.contact_threshold_n
    assert method["detector.cof_track.ramp_horizons_s"] == ",".join(f"{v:g}" for v in
                                                                    profile.detector.cof_track.ramp_horizons_s)
    # the scans counter: by exception, rising, never past what the loop counted
    alias = by_name["Counters/Scans"].alias
    seen = [spb.value(m) for t, p in msgs if t == "spBv1.0/g/DDATA/e/long" for m in spb.parse(p).metrics
            if m.alias == alias]
    assert len(seen) > 3 and seen == sorted(seen) and 0 < seen[-1] <= scans["long"]
