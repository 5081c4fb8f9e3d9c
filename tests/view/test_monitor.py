"""`eskin-bus monitor --plain` end to end on python-can's virtual bus, against the
node simulator: the state-change lines are the offline pipeline's, and the counters
add up."""
from __future__ import annotations

import sys
import threading
import time
import uuid

import can.interfaces.virtual
import numpy as np
import pytest
from click.testing import CliRunner

from eskin_industrial.bus.can.layout import CanLayout
from eskin_industrial.bus.can.reader import open_bus
from eskin_industrial.calibration import Calibrator
from eskin_industrial.cli import main
from eskin_industrial.frames import RawScan
from eskin_industrial.pipeline import Pipeline
from eskin_industrial.scenes import render
from eskin_industrial.sim.can_node import CanNode, Faults
from eskin_industrial.view.live import change_line
from tests.helpers.paths import PROFILES
from tests.helpers.scenes import press_scene

PAPER = str(PROFILES / "paper-5x5.toml")

SCENE = press_scene("short-slide", 4.0, press_t=0.5, press_s=0.4, force_n=8.0, slide_t=2.5)


@pytest.fixture
def switch_interval():
    before = sys.getswitchinterval()  # the monitor shortens it for its reader thread
    yield
    sys.setswitchinterval(before)


def offline_changes(profile, raw: np.ndarray, rate: float) -> list[str]:
    pipe = Pipeline(profile, rate_hz=rate)
    lines, last = [], None
    for i, r in enumerate(raw):
        for u in pipe.push(RawScan(i, i / rate, r)):
            if u.state != last:
                last = u.state
                lines.append(change_line(u))
    return lines


def send_when_heard(profile, channel: str, raw: np.ndarray, rate: float, faults: Faults = Faults()) -> threading.Thread:
    """The node, in a burst, once the monitor's bus is open on the channel."""

    def run() -> None:
        deadline = time.monotonic() + 20
        while not can.interfaces.virtual.channels.get(channel) and time.monotonic() < deadline:
            time.sleep(0.01)
        with open_bus("virtual", channel) as tx:
            CanNode(CanLayout.from_profile(profile, fd=False), tx, raw, rate, profile.can.heartbeat_s, faults,
                    burst=True).run()

    return threading.Thread(target=run, name="test-node", daemon=True)


def monitor_plain(channel: str, *extra: str):
    return CliRunner().invoke(main, ["monitor", "-p", PAPER, "-i", "virtual", "-c", channel, "--idle-exit", "0.5",
                                     "--duration", "30", *extra], catch_exceptions=False)


def test_monitor_plain_prints_each_state_change_and_the_counters(paper_profile, tmp_path, switch_interval):
    (tmp_path / "s.toml").write_text(SCENE)
    rec = render(str(tmp_path / "s.toml"), 100.0, 5)
    raw = np.rint(Calibrator.from_section(paper_profile.calibration, 25).to_raw(rec.forces))
    ch = f"test-monitor-{uuid.uuid4().hex[:8]}"
    node = send_when_heard(paper_profile, ch, raw, 100.0)
    node.start()
    res = monitor_plain(ch, "--plain")
    node.join(timeout=10)
    assert res.exit_code == 0, res.output
    lines = res.stdout.splitlines()
    expected = offline_changes(paper_profile, raw, 100.0)
    assert any(" slip " in line for line in expected)  # the scene has a slip to show
    assert lines[:-1] == expected
    assert lines[-1].startswith("monitor: ")
    assert f"scans {len(raw)}, lost 0, torn 0, malformed 0, rx queue drops 0, bus errors 0, " \
           f"state changes {len(expected) - 1}" in lines[-1]  # the first line is the first state: no change
    assert "\x1b" not in res.stdout
    assert "eskin-bus monitor: paper-5x5 on" in res.stderr


def test_monitor_counts_what_a_faulty_node_loses(paper_profile, switch_interval):
    rec_raw = np.rint(Calibrator.from_section(paper_profile.calibration, 25).to_raw(np.full((300, 25), 0.3)))
    ch = f"test-monitor-{uuid.uuid4().hex[:8]}"
    node = send_when_heard(paper_profile, ch, rec_raw, 100.0, Faults(silent_at_s=1.0, silent_for_s=0.5))
    node.start()
    res = monitor_plain(ch, "--method", "paper")  # not a terminal: plain without asking
    node.join(timeout=10)
    assert res.exit_code == 0, res.output
    assert "scans 250, lost 50, torn 0" in res.stdout.splitlines()[-1]


def test_monitor_on_a_bus_that_cannot_be_opened_is_one_line():
    res = CliRunner().invoke(main, ["monitor", "-p", PAPER, "-i", "no-such-interface", "-c", "x", "--plain"])
    assert res.exit_code == 3
    assert res.stderr.count("\n") == 1 and "cannot open CAN bus" in res.stderr
    assert res.stdout == ""
