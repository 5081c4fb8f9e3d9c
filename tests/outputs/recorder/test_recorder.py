"""The recorder output kind: one module and one registry entry, run beside the PLC.

A bridge with two outputs, the PLC server block and the recorder, writes every
detector update to the recorder's file while the PLC reads the same verdicts; the
file is read back by the csv / json modules (not by the package's own reader) and
checked against the offline answer."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
import threading

import numpy as np
import pytest

from eskin_industrial.bridge.config import BridgeConfig, LogSettings, NodeConfig, load_bridge_config, resolve
from eskin_industrial.detect.state import LABELS
from eskin_industrial.detect.updates import COLUMNS
from eskin_industrial.errors import ProfileError
from eskin_industrial.outputs.base import SINKS, output_kind
from eskin_industrial.outputs.plc.image import Status
from eskin_industrial.outputs.recorder.kind import RecorderKind, RecorderOptions
from eskin_industrial.outputs.recorder.sink import Recorder
from tests.helpers.bridge import PAPER, channel, hold_raw, node_thread, running_bridge, server_config, wait_for


def test_the_recorder_is_one_registry_entry():
    assert SINKS["recorder"].endswith(":RecorderKind") and output_kind("recorder") is RecorderKind
    with pytest.raises(ProfileError, match="unknown output kind 'recorde'.*did you mean 'recorder'"):
        output_kind("recorde")


@pytest.mark.parametrize("fmt", ["csv", "jsonl"])
def test_a_bridge_writes_the_plc_block_and_the_record(paper_profile, tmp_path, fmt):
    ch = channel()
    path = tmp_path / f"updates-{{node}}.{fmt}"
    base = server_config(NodeConfig.of("grip", PAPER, "can", interface="virtual", channel=ch))
    config = BridgeConfig(base.node, {**base.outputs, "recorder": RecorderOptions(str(path))},
                          LogSettings(format="json", status_every_s=0))
    raw = hold_raw(paper_profile, 200)
    seen: list[dict[str, int]] = []  # the PLC block while the node sends, as a PLC polls it
    stop = threading.Event()
    with running_bridge(config) as run, node_thread(paper_profile, ch, raw) as node:
        def poll() -> None:
            while not stop.wait(0.005):
                seen.append(run.block(0))

        watcher = threading.Thread(target=poll, name="plc-poll", daemon=True)
        watcher.start()
        node.start()
        node.join(10)
        wait_for(lambda: run.counters("grip")["scans"] == 200, what="every scan decoded")
        stop.set()
        watcher.join(5)
    # the last verdict before the node fell silent: a block read after it stopped may
    # already be stale (stale_max_s after its last scan, on a loaded host)
    live = [b for b in seen if b["STATUS"] & Status.DATA_VALID and not b["STATUS"] & Status.SENSOR_STALE]
    assert live, "no valid verdict in the PLC block while the node sent"
    block = live[-1]
    counters = run.bridge.counters()["grip"]  # stopped: every update recorded and counted
    written = tmp_path / f"updates-grip.{fmt}"
    text = written.read_text()
    if fmt == "csv":
        rows = list(csv.DictReader(text.splitlines()))
        assert list(rows[0]) == list(COLUMNS)
    else:
        rows = [json.loads(line) for line in text.splitlines()]
        assert all(r["node"] == "grip" for r in rows)
    # every update, none twice; the PLC's verdict is the record's last one
    assert len(rows) == counters["updates"] == counters["recorded_updates"] > 0
    assert counters["record_write_errors"] == 0
    times = [float(r["t"]) for r in rows]
    assert times == sorted(times) and len(set(times)) == len(times)
    assert rows[-1]["state"] == LABELS[block["STATE"]] == "stable"
    assert int(rows[-1]["valid"]) == 1


def test_recorder_rows_equal_detect_output(paper_profile, tmp_path):
    """The CSV the recorder streams is byte for byte what ``eskin-bus detect`` writes
    for the same updates (one format, two writers)."""
    from eskin_industrial.detect.updates import UpdateTable
    from eskin_industrial.frames import RawScan
    from eskin_industrial.pipeline import Pipeline
    from eskin_industrial.recording import write_updates

    pipe = Pipeline(paper_profile)
    raw = hold_raw(paper_profile, 120)
    updates = []
    for k, r in enumerate(raw):
        updates += pipe.push(RawScan(k, k / 100.0, r))
    out = tmp_path / "rec.csv"
    with open(out, "w", newline="") as stream:
        rec = Recorder(stream, "csv", "n", where=str(out), owned=False)
        for u in updates:
            rec.on_update(u)
        rec.close()
    ref = tmp_path / "ref.csv"
    write_updates(ref, UpdateTable.from_updates(updates))
    assert out.read_text() == ref.read_text() and len(updates) > 3


def test_a_full_disk_is_counted_and_the_bridge_goes_on(paper_profile):
    """/dev/full fails every write: each is counted, nothing raises."""
    from eskin_industrial.frames import RawScan
    from eskin_industrial.pipeline import Pipeline

    stream = open("/dev/full", "w", buffering=1)
    rec = Recorder(stream, "jsonl", "n", where="/dev/full", owned=True, flush_every_s=0.0)
    pipe = Pipeline(paper_profile)
    for k, r in enumerate(hold_raw(paper_profile, 60)):
        for u in pipe.push(RawScan(k, k / 100.0, r)):
            rec.on_update(u)
    rec.close()
    assert rec.records == 0 and rec.counters()["record_write_errors"] > 0
    assert rec.health().failures == rec.write_errors and "No space" in rec.health().last_error


def test_recorder_section_in_a_file_and_its_errors(tmp_path):
    cfg = tmp_path / "b.toml"
    body = (f'[recorder]\npath = "{tmp_path}/r-{{node}}.jsonl"\n\n[plc]\nmode = "server"\nport = 15999\n\n'
            f'[[node]]\nname = "a"\nprofile = "{PAPER}"\ninterface = "virtual"\nchannel = "x"\n\n'
            f'[[node]]\nname = "b"\nprofile = "{PAPER}"\ninterface = "virtual"\nchannel = "x"\nbase_id = 0x210\n'
            f'[node.plc]\nbase_address = 100\n')
    cfg.write_text(body)
    config = load_bridge_config(cfg)
    assert list(config.output_kinds()) == ["plc", "recorder"]
    assert config.outputs["recorder"].resolved_format == "jsonl"
    resolve(config)
    cfg.write_text(body.replace("r-{node}", "r"))
    with pytest.raises(ProfileError, match=r"\[recorder\] path: several nodes would write one file"):
        resolve(load_bridge_config(cfg))
    cfg.write_text(body.replace("[recorder]\npath", "[recorder]\npaht"))
    with pytest.raises(ProfileError, match=r"\[recorder\] paht: unknown key; did you mean 'path'"):
        load_bridge_config(cfg)
    cfg.write_text(body.replace("[recorder]", "[recordr]"))
    with pytest.raises(ProfileError, match=r"\[recordr\]: unknown section; did you mean 'recorder'"):
        load_bridge_config(cfg)


@pytest.mark.slow
def test_bridge_command_records_a_scene_with_no_plc(tmp_path):
    """``--record`` alone: the one output (no PLC is contacted), and ``--check`` says so."""
    out = tmp_path / "case2.csv"
    exe = [sys.executable, "-m", "eskin_industrial", "bridge", "-p", PAPER, "--source", "scene:case2",
           "--record", str(out)]
    res = subprocess.run([*exe, "--check"], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr
    assert f"scene case2 -> record csv {out}" in res.stdout and "PLC" not in res.stdout
    res = subprocess.run([*exe, "--duration", "3", "--status-every", "0"], capture_output=True, text=True,
                         timeout=60)
    assert res.returncode == 0, res.stderr
    rows = list(csv.DictReader(out.read_text().splitlines()))
    assert len(rows) > 10 and {r["state"] for r in rows} <= set(LABELS)
    assert "plc_" not in res.stderr  # no PLC output, no PLC counters
    assert f"recorded_updates={len(rows)}" in res.stderr  # the final counters line (plain log)
    assert np.all(np.diff([float(r["t"]) for r in rows]) > 0)
