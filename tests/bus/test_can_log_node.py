"""CAN without hardware: the node simulator and the scene simulator write CAN logs
(``--can-log FILE``) that ``detect --can-log`` and ``receive --can-log`` read, and that
decoders nobody here wrote read too: python-can's own readers, can-utils' ``log2asc``,
cantools through the profile's DBC."""
from __future__ import annotations

import re
import shutil
import subprocess
import sys

import can
import cantools
import numpy as np
import pytest

from eskin_industrial.calibration import Calibrator
from eskin_industrial.profile import load_profile
from eskin_industrial.scenes import render

RATE = 100.0


def eskin_bus(*args: str, timeout: float = 120, cwd: str | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "eskin_industrial", *args], capture_output=True, text=True,
                          timeout=timeout, cwd=cwd)


def slip_span() -> tuple[float, float]:
    """The scene's labelled slip, [start, end) in seconds."""
    scene = render("case2", RATE, 0)
    t = scene.t[scene.labels == "slip"]
    return float(t[0]), float(t[-1]) + 1.0 / RATE


def changes(csv_text: str) -> list[tuple[float, str]]:
    rows = [line.split(",") for line in csv_text.splitlines()[1:]]
    return [(float(r[0]), r[3]) for r in rows]


@pytest.mark.parametrize("suffix", [".log", *(pytest.param(s, marks=pytest.mark.slow)
                                               for s in (".asc", ".blf", ".csv", ".trc"))])
def test_node_writes_a_log_detect_finds_the_scenes_slip(tmp_path, suffix):
    log = tmp_path / f"node{suffix}"
    res = eskin_bus("node", "-p", "paper-5x5", "--scene", "case2", "--can-log", str(log))
    assert res.returncode == 0, res.stderr
    sent = int(re.search(r"(\d+) frames in", res.stderr).group(1))
    # python-can's own reader: every frame, in order, on the node's clock (scan k at k / rate)
    with can.LogReader(str(log)) as reader:
        frames = list(reader)
    assert len(frames) == sent == 1400 * 9 + 140
    data = [m for m in frames if m.arbitration_id == 0x200]
    steps = np.diff([m.timestamp for m in data])
    np.testing.assert_allclose(steps, 1.0 / RATE, atol=1e-5)
    res = eskin_bus("detect", "-p", "paper-5x5", "--can-log", str(log), "--changes")
    assert res.returncode == 0, res.stderr
    lo, hi = slip_span()
    slips = [t for t, state in changes(res.stdout) if state == "slip"]
    assert slips and all(lo <= t < hi for t in slips), (slips, lo, hi)


@pytest.mark.slow
def test_simulate_writes_the_same_log_a_node_would(tmp_path):
    """simulate --can-log stamps from 0 and gives the same frames as the node: the same
    updates from detect, byte for byte."""
    res = eskin_bus("simulate", "case2", "--can-log", str(tmp_path / "sim.log"), "--labels", str(tmp_path / "l.csv"))
    assert res.returncode == 0 and res.stdout == "", res.stderr
    res = eskin_bus("node", "-p", "paper-5x5", "--scene", "case2", "--can-log", str(tmp_path / "node.blf"))
    assert res.returncode == 0, res.stderr
    with can.LogReader(str(tmp_path / "sim.log")) as reader:
        first = next(iter(reader))
    assert first.timestamp == 0.0
    outs = []
    for name in ("sim.log", "node.blf"):
        res = eskin_bus("detect", "-p", "paper-5x5", "--can-log", str(tmp_path / name), "-o", "-")
        assert res.returncode == 0, res.stderr
        outs.append(res.stdout)
    assert outs[0] == outs[1] and "slip" in outs[0]


def test_a_live_candump_stream_from_the_node_to_detect(tmp_path):
    """``--can-log -``: candump -L lines on stdout, piped into detect as they come."""
    node = subprocess.Popen([sys.executable, "-m", "eskin_industrial", "simulate", "case2", "--can-log", "-"],
                            stdout=subprocess.PIPE)
    try:
        res = subprocess.run([sys.executable, "-m", "eskin_industrial", "detect", "-p", "paper-5x5", "--can-log", "-",
                              "--changes"], stdin=node.stdout, capture_output=True, text=True, timeout=120)
    finally:
        node.stdout.close()
        assert node.wait(timeout=60) == 0
    assert res.returncode == 0, res.stderr
    assert "slip" in [s for _, s in changes(res.stdout)]


@pytest.mark.skipif(shutil.which("log2asc") is None, reason="can-utils' log2asc is not installed (can-utils)")
def test_can_utils_and_cantools_decode_the_nodes_log_to_the_scenes_forces(tmp_path):
    log = tmp_path / "node.log"
    res = eskin_bus("node", "-p", "paper-5x5", "--scene", "case2", "--seed", "3", "--can-log", str(log))
    assert res.returncode == 0, res.stderr
    dbc = eskin_bus("profile", "dbc", "paper-5x5")
    assert dbc.returncode == 0, dbc.stderr
    db = cantools.database.load_string(dbc.stdout, "dbc")
    # can-utils parses our candump file (its own parser, not python-can's)
    asc = subprocess.run(["log2asc", "-I", str(log), "vcan0"], capture_output=True, text=True, timeout=60, check=True)
    rows = [line.split() for line in asc.stdout.splitlines() if re.match(r"\s*\d+\.\d+ \d+ ", line)]
    prof = load_profile("paper-5x5")
    scene = render("case2", RATE, 3)
    theirs = np.full(scene.forces.shape, np.nan)
    times = np.full(len(scene.forces), np.nan)
    for t, _ch, can_id, _dir, _d, dlc, *data in rows:
        assert len(data) == int(dlc)
        message = db.get_message_by_frame_id(int(can_id, 16))
        values = message.decode(bytes.fromhex("".join(data)))
        if "SEQ" not in values:
            continue  # the heartbeat
        k = int(values["SEQ"]) + 4096 * (int(float(t) * RATE + 0.5) // 4096)
        times[k] = float(t)
        for name, value in values.items():
            if re.fullmatch(r"F\d+", name):
                theirs[k, int(name[1:])] = value
    assert not np.isnan(theirs).any()
    np.testing.assert_allclose(times, scene.t, atol=1e-5)  # the node's clock, through log2asc
    # the scene's forces, to the node's resolution: half a raw count, in newtons
    cal = Calibrator.from_section(prof.calibration, prof.taxels)
    half_count = 0.5 * cal.raw_scale / np.abs(cal.per_newton)
    assert np.all(np.abs(theirs - scene.forces) <= half_count + 1e-9)


@pytest.mark.slow
def test_receive_replays_the_nodes_log_as_if_received(tmp_path):
    """receive --can-log: the log at its own pace (14 s) through the live source; the
    same updates as detect gives."""
    log = tmp_path / "node.asc"
    assert eskin_bus("simulate", "case2", "--can-log", str(log)).returncode == 0
    res = eskin_bus("receive", "-p", "paper-5x5", "--can-log", str(log), "-o", str(tmp_path / "rx.csv"))
    assert res.returncode == 0, res.stderr
    assert '"scans": 1400' in res.stderr and '"lost_scans": 0' in res.stderr
    res = eskin_bus("detect", "-p", "paper-5x5", "--can-log", str(log), "-o", str(tmp_path / "det.csv"))
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "rx.csv").read_text() == (tmp_path / "det.csv").read_text()


@pytest.mark.parametrize("args, needle", [
    (["--can-log", "x.mp3"], "expected a CAN log ending in .asc, .blf"),
    (["--can-log", "x.log", "-i", "virtual"], "without -i/-c"),
    (["--can-log", "no/such/dir/x.log"], "x.log: cannot write: No such file or directory"),
])
def test_a_log_that_cannot_be_written_is_one_usage_line(tmp_path, args, needle):
    res = eskin_bus("node", "-p", "paper-5x5", "--scene", "case2", *args, cwd=str(tmp_path))
    assert res.returncode == 2 and needle in res.stderr, res.stderr
