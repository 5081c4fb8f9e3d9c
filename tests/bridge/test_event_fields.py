"""The bridge's log events carry the fields ``docs/operations.md`` lists for them, and
an RTU node's ``bus_fault`` says what failed (before: always ``error=-``)."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from eskin_industrial.bus.modbus.rtu import RtuSource
from eskin_industrial.profile import load_profile
from tests.helpers.modbus import free_port, pty_pair
from tests.helpers.paths import PROFILES, ROOT

PAPER = str(PROFILES / "paper-5x5.toml")
OPERATIONS = ROOT / "docs" / "operations.md"


def documented_fields() -> dict[str, list[str]]:
    """event -> its fields, from the events table of docs/operations.md."""
    out: dict[str, list[str]] = {}
    for line in OPERATIONS.read_text().splitlines():
        m = re.match(r"\| (`[a-z_]+`(?: / `[a-z_]+`)?) \| [a-z /]+ \| ([^|]*) \|", line)
        if not m:
            continue
        fields = [f.strip() for f in m.group(2).split(",") if f.strip() and not f.strip().startswith("every ")]
        for name in re.findall(r"`([a-z_]+)`", m.group(1)):
            out[name] = fields
    return out


def bridge_events(tmp_path: Path, *args: str, timeout: float = 30) -> list[dict]:
    res = subprocess.run([sys.executable, "-m", "eskin_industrial", "bridge", *args, "--log-format", "json"],
                         capture_output=True, text=True, timeout=timeout)
    assert res.returncode == 0, res.stderr[-2000:]
    return [json.loads(line) for line in res.stderr.splitlines() if line.startswith("{")]


def assert_documented(events: list[dict], *names: str) -> None:
    docs = documented_fields()
    for name in names:
        seen = [e for e in events if e["event"] == name]
        assert seen, f"no {name} event in {[e['event'] for e in events]}"
        for e in seen:
            missing = [f for f in docs[name] if f not in e]
            assert not missing, f"{name} lacks documented fields {missing}: {e}"


def test_the_docs_list_the_events_this_test_reads():
    docs = documented_fields()
    assert docs["source_ended"] == ["node", "error"] and docs["bus_fault"] == ["node", "error"]
    assert docs["bus_ok"] == ["node", "error"] and "stopped" in docs


def test_a_scene_that_ends_logs_the_documented_fields(tmp_path):
    scene = tmp_path / "short.toml"
    builtin = ROOT / "eskin_industrial" / "scenes" / "builtin" / "case1.toml"
    text = builtin.read_text()
    assert "duration_s = 16.0" in text
    scene.write_text(text.replace("duration_s = 16.0", "duration_s = 0.6", 1))
    cfg = tmp_path / "b.toml"
    cfg.write_text(f'[plc]\nmode = "server"\nport = {free_port()}\n\n[[node]]\nname = "a"\nprofile = "{PAPER}"\n'
                   f'source = "scene"\nscene = "{scene}"\nloop = false\n')
    events = bridge_events(tmp_path, "--config", str(cfg), "--duration", "10", "--status-every", "0.2")
    assert_documented(events, "start", "state", "counters", "source_ended", "stopped", "final")
    ended = next(e for e in events if e["event"] == "source_ended")
    assert ended["node"] == "a" and ended["error"] == "-"  # it ended as scenes end: nothing failed


def test_an_rtu_node_that_does_not_answer_names_its_failure(tmp_path):
    """The source's ``last_error`` is what the ``bus_fault`` event carries."""
    prof = load_profile(PAPER)
    with pty_pair(tmp_path) as (_node_end, bridge_end):  # nobody answers on the node's end
        src = RtuSource(prof, bridge_end).open()
        try:
            assert src.health().last_error == ""
            for _ in range(prof.modbus.node.fault_after_failures):
                assert src.poll_once() is None
            health = src.health()
        finally:
            src.close()
    assert health.bus_fault and health.bus_errors == src.stats.timeouts > 0
    assert bridge_end in health.last_error and "timeout" in health.last_error, health.last_error


@pytest.mark.slow
def test_an_rtu_bus_fault_event_carries_the_error(tmp_path):
    with pty_pair(tmp_path) as (_node_end, bridge_end):
        events = bridge_events(tmp_path, "-p", PAPER, "--source", f"rtu:{bridge_end}",
                               "--plc", f"serve:127.0.0.1:{free_port()}", "--duration", "1.5")
    assert_documented(events, "bus_fault")
    fault = next(e for e in events if e["event"] == "bus_fault")
    assert fault["error"] != "-" and "timeout" in fault["error"] and bridge_end in fault["error"], fault


# -- counters -------------------------------------------------------------------------------
def documented_counters() -> set[str]:
    """Every counter named in the first column of docs/operations.md's counters table."""
    text = OPERATIONS.read_text()
    table = text[text.index("| counter | what it counts |"):text.index("## When something is wrong")]
    return {name for line in table.splitlines() if line.startswith("| `")
            for name in re.findall(r"`([a-z_]+)`", line.split(" | ")[0])}


def test_every_counter_of_a_can_bridge_node_is_documented_and_other_traffic_is_unrouted(paper_profile):
    """The bridge routes each frame by ID: other traffic counts in ``unrouted_frames``
    (documented as the bridge's count), ``foreign_frames`` stays 0 (documented so)."""
    import can

    from tests.helpers.bridge import can_node, channel, running_bridge, server_config, wait_for

    ch = channel()
    with running_bridge(server_config(can_node("grip", ch))) as run:
        with can.Bus(interface="virtual", channel=ch) as tx:
            for can_id in (0x100, 0x101, 0x7F0):
                tx.send(can.Message(arbitration_id=can_id, data=bytes(8), is_extended_id=False))
        wait_for(lambda: run.counters("grip")["unrouted_frames"] == 3, what="three frames of no node")
        counters = run.counters("grip")
    assert counters["foreign_frames"] == 0
    undocumented = set(counters) - documented_counters()
    assert not undocumented, f"counters the bridge reports that docs/operations.md does not list: {undocumented}"


def test_a_full_receive_queue_keeps_the_queued_frames_and_drops_the_newest():
    """docs/operations.md: the reader only appends, the loop only takes; a full queue
    drops (and counts) what arrives."""
    import can

    from eskin_industrial.bus.can.reader import BusReader, open_bus
    from tests.helpers.bridge import channel, wait_for

    ch, limit = channel(), 20
    reader = BusReader(lambda: open_bus("virtual", ch), queue_frames=limit).start()  # nobody takes from it
    try:
        with can.Bus(interface="virtual", channel=ch) as tx:
            for i in range(3 * limit):
                tx.send(can.Message(arbitration_id=0x200, data=i.to_bytes(2, "big"), is_extended_id=False))
        wait_for(lambda: reader.counters["rx_queue_drops"] == 2 * limit, what="the overflow counted")
        assert [int.from_bytes(m.data, "big") for m in reader.queue] == list(range(limit))
    finally:
        reader.stop()
