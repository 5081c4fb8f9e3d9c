"""`eskin-bus detect` on recordings whose numbers or times are wrong: flagged, counted,
refused with one line, never a traceback, never lost silently."""
from __future__ import annotations

import math

import numpy as np
import pytest

from eskin_industrial.frames import FrameFlag
from eskin_industrial.recording import read_updates, write_recording
from tests.cli.test_cli_detect import PAPER, cli
from tests.helpers.scenes import grasp

RATE = 200.0
K = 1400


def recording(tmp_path, t=None, f=None, name="rec.csv"):
    if f is None:
        f = grasp(K, seed=11)
        f[:200] = 0.0
    path = tmp_path / name
    write_recording(path, np.arange(K) / RATE if t is None else t, f)
    return path


def one_line_error(res) -> str:
    assert res.returncode == 2, res.stderr
    assert "Traceback" not in res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("eskin-bus: error: "), res.stderr
    return lines[0]


def test_forces_past_full_scale_in_a_newton_csv_are_clamped_and_flagged(tmp_path):
    f = grasp(K, seed=11)
    f[:200] = 0.0
    f[700, 3] = 500.0  # full_scale_n is 10 N
    f[900, 4] = 1e160
    out = tmp_path / "out.csv"
    res = cli("detect", "-p", PAPER, str(recording(tmp_path, f=f)), "-o", str(out))
    assert res.returncode == 0, res.stderr
    cols = read_updates(out)
    flagged = cols["t"][(cols["flags"].astype(int) & FrameFlag.SATURATED) != 0]
    # the update whose hop holds each frame (and no other) says SATURATED
    assert len(flagged) == 2
    assert all(np.any(np.abs(flagged - when) < 0.05) for when in (700 / RATE, 900 / RATE))
    # (the idle start's exact zeros are a frozen sensor's: no verdict and no force there, as in the bridge)
    assert np.nanmax(cols["f_sum"]) < 25 * 10.0 + 1e-6


def test_a_time_of_inf_is_refused_and_counted(tmp_path):
    t = np.arange(K) / RATE
    t[700] = math.inf
    res = cli("detect", "-p", PAPER, str(recording(tmp_path, t=t)), "-o", str(tmp_path / "o.csv"))
    assert res.returncode == 0, res.stderr
    assert "1 frames refused for their time (not_a_time 1)" in res.stderr


def test_a_backward_jump_is_counted_and_can_fail_the_run(tmp_path):
    t = np.arange(K) / RATE
    t[700:] -= 3.0 + 0.5 / RATE  # 3 s back: the next 600 frames come before the newest kept time
    rec = recording(tmp_path, t=t)
    res = cli("detect", "-p", PAPER, str(rec), "-o", str(tmp_path / "a.csv"))
    assert res.returncode == 0, res.stderr
    assert "600 frames refused for their time (backward_time 600)" in res.stderr
    out = tmp_path / "b.csv"
    res = cli("detect", "-p", PAPER, str(rec), "-o", str(out), "--fail-on-time-faults", "-q")
    line = one_line_error(res)
    assert "600 frames refused for their time (backward_time 600)" in line
    assert len(read_updates(out)["t"]) > 0  # the output is written before the verdict


@pytest.mark.parametrize("times,expect", [
    (np.zeros(K), "never advance"),  # all equal: was 1 update of 1,400 with exit 0
    (np.arange(K) / RATE * 1e-6, "Hz, implausible for profile paper-5x5's rate_hz 100 Hz"),  # was 0 updates
    (np.arange(K) / RATE * 1e3, "0.2 Hz, implausible"),  # milliseconds read as seconds
])
def test_a_recording_at_an_implausible_rate_is_refused(tmp_path, times, expect):
    res = cli("detect", "-p", PAPER, str(recording(tmp_path, t=times)), "-o", str(tmp_path / "o.csv"))
    assert expect in one_line_error(res)


def test_the_rate_is_checked_against_an_explicit_rate_too(tmp_path):
    rec = recording(tmp_path)  # 200 Hz
    assert cli("detect", "-p", PAPER, str(rec), "--rate", "150", "-q").returncode == 0
    assert "implausible for --rate 5000 Hz" in one_line_error(cli("detect", "-p", PAPER, str(rec), "--rate", "5000"))
