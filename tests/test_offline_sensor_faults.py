"""Offline, the bridge's verdicts: a recording (or a CAN log) of a dead, frozen or
mistimed sensor gives, row by row, what the bridge's loop gives for the same scans
(docs/plc.md, sensor faults): no verdict while the fault lasts, the fault's bits in
``flags``.  The bridge side is the real loop on a replay of the same raw scans, its
rows written by the bridge's own recorder, and each row checked against the snapshot
the loop would publish at that moment."""

from __future__ import annotations

import io
from pathlib import Path

import can
import numpy as np
import pytest

from eskin_industrial.bridge.loop import NodeLoop
from eskin_industrial.bus.can.layout import CanLayout
from eskin_industrial.bus.replay import ReplaySource
from eskin_industrial.frames import SENSOR_FAULTS, FrameFlag
from eskin_industrial.outputs.recorder.sink import Recorder
from eskin_industrial.profile import Profile, load_profile
from eskin_industrial.recording import read_updates, write_recording
from tests.cli.test_cli_detect import cli
from tests.helpers.bridge import PAPER, hold_raw
from tests.helpers.can_frames import scans_to_messages

RATE_HZ = 100.0
DEAD, FROZEN, RATE = int(FrameFlag.DEAD_TAXELS), int(FrameFlag.FROZEN), int(FrameFlag.RATE)


@pytest.fixture(scope="module")
def paper() -> Profile:
    return load_profile(PAPER)


def dead(profile: Profile) -> tuple[np.ndarray, np.ndarray, float]:
    """A still grasp whose taxels all read NaN from 3 s on."""
    raw = hold_raw(profile, 500)
    raw[300:] = np.nan
    return np.arange(len(raw)) / RATE_HZ, raw, 3.0


def frozen(profile: Profile) -> tuple[np.ndarray, np.ndarray, float]:
    """The node repeats one buffer from 2 s on (FROZEN once 0.5 s of it has passed)."""
    raw = hold_raw(profile, 400, seed=3)
    raw[200:] = raw[199]
    return np.arange(len(raw)) / RATE_HZ, raw, 2.5


def mistimed(profile: Profile) -> tuple[np.ndarray, np.ndarray, float]:
    """3 s at 100 Hz, then 3 s of scans 40 Hz apart (RATE after one window of them)."""
    raw = hold_raw(profile, 420, seed=4)
    t = np.concatenate([np.arange(300) / RATE_HZ, 3.0 + np.arange(120) / 40.0])
    return t, raw, 3.0 + 32 / 40.0


def bridge_rows(profile: Profile, t: np.ndarray, raw: np.ndarray) -> str:
    """The same scans through the bridge's loop (replayed fast, times the recording's),
    the rows its recorder writes; each row's verdict checked against the snapshot of
    that moment as the loop would publish it."""
    out = io.StringIO()
    recorder = Recorder(out, "csv", "grip", where="memory", owned=False)
    loop = NodeLoop(profile, ReplaySource(profile, t, raw, rate_hz=50_000.0), [recorder], rate_hz=RATE_HZ)
    seen = 0
    while not loop.source.done:
        loop.step(timeout_s=0.0)
        if recorder.records == seen:
            continue
        seen = recorder.records
        # fresh: the replay's own frame age is wall-clock time, and a host that holds this
        # process for the stale limit between the step and here would make it stale
        health = loop.health()._replace(frame_age_s=0.0)
        snap = loop.status.snapshot(health, scans=0, t_event=0.0, wall_time_s=0.0, urgent=False)
        row = out.getvalue().splitlines()[-1].split(",")
        fault = int(row[8]) & SENSOR_FAULTS
        assert fault == snap.sensor_fault and int(row[4]) == int(snap.valid), (row, snap)
        assert (snap.state is None) == bool(fault)
    return out.getvalue()


def check_faulted(rows: dict[str, np.ndarray], bit: int, from_s: float) -> None:
    """No verdict from ``from_s`` on, with the fault's bit; verdicts before the fault."""
    t, flags = rows["t"], rows["flags"].astype(int)
    before, after = t < from_s - 0.6, t >= from_s + 0.02
    assert rows["valid"][before].any() and not (flags[before] & SENSOR_FAULTS).any()
    assert after.sum() > 50 and (flags[after] & bit).all()
    assert not rows["valid"][after].any()
    assert set(rows["state"][after]) == {"no_contact"} and np.isnan(rows["f_sum"][after]).all()
    assert np.isnan(rows["r_coe"][after]).all() and np.isnan(rows["score_a"][after]).all()


@pytest.mark.parametrize(("case", "bit"), [(dead, DEAD), (frozen, FROZEN), (mistimed, RATE)],
                         ids=["dead", "frozen", "rate"])
@pytest.mark.parametrize("engine", ["batch", "stream"])
def test_detect_on_a_recording_gives_the_bridges_verdicts(tmp_path: Path, paper: Profile, case, bit: int,
                                                          engine: str) -> None:
    t, raw, from_s = case(paper)
    path = tmp_path / "rec.csv"
    write_recording(path, t, raw, unit="raw")
    out = tmp_path / "out.csv"
    res = cli("detect", "-p", PAPER, str(path), "--rate", str(RATE_HZ), "--engine", engine, "-o", str(out))
    assert res.returncode == 0, res.stderr
    assert "under a sensor fault: no verdict" in res.stderr
    check_faulted(read_updates(out), bit, from_s)
    assert out.read_text() == bridge_rows(paper, t, raw)  # row by row, byte for byte


def test_detect_on_a_can_log_of_a_dead_node_gives_the_bridges_verdicts(tmp_path: Path, paper: Profile) -> None:
    raw = hold_raw(paper, 500)
    raw[300:] = 65535  # every taxel an open line from 3 s on
    log = tmp_path / "node.asc"
    with can.Logger(log) as writer:
        for m in scans_to_messages(CanLayout.from_profile(paper), np.arange(len(raw)), raw):
            writer.on_message_received(m)
    out = tmp_path / "out.csv"
    res = cli("detect", "-p", PAPER, "--can-log", str(log), "-o", str(out))
    assert res.returncode == 0, res.stderr
    check_faulted(read_updates(out), DEAD, 3.0)
    assert out.read_text() == bridge_rows(paper, np.arange(len(raw)) / RATE_HZ, raw)


@pytest.mark.parametrize("engine", ["batch", "stream"])
def test_filled_gaps_and_refused_times_keep_each_row_on_its_scan(tmp_path: Path, paper: Profile, engine: str) -> None:
    """Each update takes the fault of the scan that gave it: across a gap the detector
    fills (decided when the next scan comes) and around times it refuses."""
    raw = hold_raw(paper, 600, seed=5)
    raw[350:, 4] = np.nan  # one taxel dead from 3.5 s: held for hold_s, then DEAD_TAXELS
    t = np.arange(600) / RATE_HZ
    t[250], t[260] = t[249], t[255]  # a repeated time, a backward one
    keep = np.ones(600, bool)
    keep[200:203] = False  # 30 ms missing: filled
    t, raw = t[keep], raw[keep]
    path, out = tmp_path / "rec.csv", tmp_path / "out.csv"
    write_recording(path, t, raw, unit="raw")
    res = cli("detect", "-p", PAPER, str(path), "--rate", str(RATE_HZ), "--engine", engine, "-o", str(out))
    assert res.returncode == 0, res.stderr
    assert "(repeated_time 1, backward_time 1)" in res.stderr
    rows = read_updates(out)
    assert (rows["flags"].astype(int) & int(FrameFlag.FILLED)).any()
    check_faulted(rows, DEAD, 3.5 + paper.output.hold_s)
    assert out.read_text() == bridge_rows(paper, t, raw)
