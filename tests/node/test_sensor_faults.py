"""A verdict is valid only when it is one: a sensor whose taxels read an open line, a
short or NaN, a frozen sensor, a rate far from the profile's, and a node whose source
ended leave every output reading "I don't know" (docs/plc.md, sensor faults), logged
once and counted.

The bridges here replay recordings (raw units, as a node sends them) in real time
through the PLC server; the PLC's registers are read from the served block, and
Sparkplug's metrics and OPC UA's status codes are rendered from the snapshots the
same loop published."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
import pytest

from eskin_industrial.bridge.config import NodeConfig
from eskin_industrial.detect.integrity import RATE_WINDOW, IntegrityWatch
from eskin_industrial.frames import FrameFlag
from eskin_industrial.node import NodeSnapshot
from eskin_industrial.outputs.base import Sink
from eskin_industrial.outputs.opcua.status import BAD_SENSOR_FAILURE, quality
from eskin_industrial.outputs.plc.image import Status
from eskin_industrial.outputs.sparkplug.metrics import DEVICE_METRICS, metric_values
from eskin_industrial.profile import load_profile
from eskin_industrial.recording import write_recording
from tests.helpers.bridge import CLAIMS, PAPER, hold_raw, running_bridge, server_config, wait_for

RATE_HZ = 100.0
DEAD, FROZEN, RATE = int(FrameFlag.DEAD_TAXELS), int(FrameFlag.FROZEN), int(FrameFlag.RATE)
_VALID = DEVICE_METRICS.index(next(m for m in DEVICE_METRICS if m.name == "Data Valid"))
_FAULT = DEVICE_METRICS.index(next(m for m in DEVICE_METRICS if m.name == "Sensor Fault"))


def watch(**kw: float) -> IntegrityWatch:
    settings = {"hold_s": 0.25, "hold_share": 0.25, "frozen_s": 0.5, "rate_tolerance": 2.0} | kw
    return IntegrityWatch(25, RATE_HZ, **settings)


def run_watch(w: IntegrityWatch, t: np.ndarray, forces: np.ndarray, raw: np.ndarray) -> np.ndarray:
    return np.array([w.push(float(ti), f, r, bool(np.isnan(f).any())) for ti, f, r in zip(t, forces, raw)])


# -- the rules, scan by scan -----------------------------------------------------

def test_a_held_taxel_is_a_guess_for_a_limited_time_and_share():
    rng = np.random.default_rng(1)
    t = np.arange(200) / RATE_HZ
    f = rng.uniform(0.1, 0.5, (200, 25))
    f[50:55, 3] = np.nan  # a glitch of 50 ms on one taxel: held, still a verdict
    f[100:, 7] = np.nan  # one taxel dead for good from 1 s: held 0.25 s, then no verdict
    faults = run_watch(watch(), t, f, f)
    assert not faults[:126].any()
    assert (faults[127:] & DEAD).all()

    g = rng.uniform(0.1, 0.5, (100, 25))
    g[40:, :7] = np.nan  # 7 of 25 at once: more than a quarter of the frame made up
    faults = run_watch(watch(), t[:100], g, g)
    assert not faults[:40].any() and (faults[40:] & DEAD).all()


def test_identical_scans_freeze_and_a_rate_far_from_the_profile_is_refused():
    rng = np.random.default_rng(2)
    raw = rng.integers(13000, 14000, (200, 25)).astype(float)
    raw[100:] = raw[99]  # the node repeats its last buffer from 1 s on
    t = np.arange(200) / RATE_HZ
    faults = run_watch(watch(), t, raw, raw)
    assert not (faults[:150] & FROZEN).any()  # (0.5 s of identical scans is allowed)
    assert (faults[151:] & FROZEN).all()

    slow = np.arange(4 * RATE_WINDOW) / (RATE_HZ / 2.5)  # 40 Hz against 100 Hz
    faults = run_watch(watch(), slow, raw[: len(slow)] + rng.random((len(slow), 25)), raw[: len(slow)])
    assert (faults[RATE_WINDOW:] & RATE).all() and not (faults[: RATE_WINDOW - 1] & RATE).any()
    faults = run_watch(watch(), slow, raw[: len(slow)], raw[: len(slow)] + rng.random((len(slow), 25)))
    assert (faults[RATE_WINDOW:] & RATE).all()
    near = np.arange(4 * RATE_WINDOW) / (RATE_HZ / 1.5)  # within the factor of 2
    assert not run_watch(watch(), near, raw[: len(near)], raw[: len(near)] + rng.random((len(near), 25))).any()


# -- through the bridge: every output --------------------------------------------

class Snapshots(Sink):
    """Keeps every snapshot the loop publishes (what Sparkplug and OPC UA render)."""

    def __init__(self) -> None:
        super().__init__()
        self.seen: list[NodeSnapshot] = []
        self.lock = threading.Lock()

    def _publish(self, snapshot: NodeSnapshot) -> None:
        with self.lock:
            self.seen.append(snapshot)


def dead_recording(tmp_path: Path, dead: float, *, hold_s: float = 1.5, dead_s: float = 1.5) -> Path:
    """A still grasp in raw units (0.1 ohm), every taxel reading ``dead`` from
    ``hold_s`` on (65535: an open line; 0: a short; NaN)."""
    profile = load_profile(PAPER)
    n_hold, n_dead = int(hold_s * RATE_HZ), int(dead_s * RATE_HZ)
    raw = np.vstack([hold_raw(profile, n_hold), np.full((n_dead, profile.taxels), dead)])
    t = np.arange(len(raw)) / RATE_HZ
    path = tmp_path / "dead.csv"
    write_recording(path, t, raw, unit="raw")
    return path


def play(path: Path, until_s: float) -> tuple[list[tuple[float, dict[str, int]]], list[NodeSnapshot], list[dict],
                                                dict[str, int]]:
    """Replay ``path`` through a server-mode bridge; the block every 10 ms (time since
    start, named values), the snapshots, the log and the counters."""
    node = NodeConfig.of("grip", PAPER, "recording", path=str(path), loop=False)
    keeper = Snapshots()
    images: list[tuple[float, dict[str, int]]] = []
    with running_bridge(server_config(node),
                        before_start=lambda b: b.runs[0].loop.add_sink(keeper)) as run:
        t0 = time.monotonic()
        while time.monotonic() - t0 < until_s:
            images.append((time.monotonic() - t0, run.block(0)))
            time.sleep(0.01)
        counters = run.counters("grip")
        events = run.log.events()
    with keeper.lock:
        return images, list(keeper.seen), events, counters


@pytest.mark.parametrize("dead", [65535.0, 0.0, float("nan")], ids=["open-line", "short", "nan"])
def test_a_dead_sensor_is_no_verdict_on_every_output(tmp_path, dead):
    images, snaps, events, counters = play(dead_recording(tmp_path, dead), until_s=2.9)
    before = [v for t, v in images if 0.8 < t < 1.3]
    assert before and all(v["STATUS"] & Status.DATA_VALID for v in before)  # a verdict while it reads
    after = [v for t, v in images if 1.8 < t < 2.9]
    assert after
    for v in after:  # the PLC: nothing claimed, FLAGS say why, the bridge alive
        assert not v["STATUS"] & CLAIMS, Status(v["STATUS"])
        assert v["STATE"] == 0 and v["F_SUM"] == 0 and v["FLAGS"] & DEAD, v
    assert len({v["HEARTBEAT"] for v in after}) > 5
    dead_snaps = [s for s in snaps if s.sensor_fault]
    assert dead_snaps and all(s.state is None and not s.valid for s in dead_snaps)
    for s in dead_snaps:  # Sparkplug and OPC UA render the same snapshot
        metrics = metric_values(s)
        assert metrics[_VALID] is False and metrics[_FAULT] & DEAD
        assert quality(s).decision == BAD_SENSOR_FAILURE
    faults = [e for e in events if e["event"] == "sensor_fault"]
    assert len(faults) == 1 and "DEAD_TAXELS" in faults[0]["why"]  # said once, not per scan
    assert counters["sensor_faults"] == 1 and counters["fault_scans"] >= 100
    assert counters["invalid_scans"] >= counters["fault_scans"]


def test_a_frozen_sensor_is_no_verdict(tmp_path):
    profile = load_profile(PAPER)
    raw = hold_raw(profile, 250)
    raw[120:] = raw[119]  # the node repeats one buffer from 1.2 s on
    path = tmp_path / "frozen.csv"
    write_recording(path, np.arange(len(raw)) / RATE_HZ, raw, unit="raw")
    images, _, events, _ = play(path, until_s=2.3)
    assert all(v["STATUS"] & Status.DATA_VALID for t, v in images if 0.8 < t < 1.2)
    frozen = [v for t, v in images if 1.9 < t < 2.3]
    assert frozen and all(v["FLAGS"] & FROZEN and not v["STATUS"] & CLAIMS for v in frozen)
    assert [e["why"] for e in events if e["event"] == "sensor_fault"] == ["FROZEN"]


def test_a_node_whose_source_ended_claims_nothing_while_the_other_runs_on(tmp_path):
    profile = load_profile(PAPER)
    short = tmp_path / "short.csv"
    write_recording(short, np.arange(100) / RATE_HZ, hold_raw(profile, 100), unit="raw")
    long = tmp_path / "long.csv"
    write_recording(long, np.arange(400) / RATE_HZ, hold_raw(profile, 400, seed=1), unit="raw")
    a = NodeConfig.of("a", PAPER, "recording", path=str(short), loop=False, outputs={"plc": {"base_address": 0}})
    b = NodeConfig.of("b", PAPER, "recording", path=str(long), loop=False, outputs={"plc": {"base_address": 100}})
    with running_bridge(server_config(a, b)) as run:
        wait_for(lambda: run.log.events("source_ended"), timeout_s=5, what="node a's end")
        time.sleep(0.3)
        first = run.block(0)
        time.sleep(0.3)
        ended, other = run.block(0), run.block(1)
    assert ended["STATUS"] == Status.BRIDGE_OFFLINE, Status(ended["STATUS"])  # nothing else: no CONTACT, no VALID
    assert ended["STATE"] == 0 and ended["FRAME_AGE"] == 0xFFFF
    assert ended["HEARTBEAT"] == first["HEARTBEAT"]  # stopped, as documented
    assert other["STATUS"] & Status.DATA_VALID and not other["STATUS"] & Status.BRIDGE_OFFLINE
