"""The delay's bound (evaluation/bound.py): the oracle that knows the onset and the
path needs (z sigma / d)^2 frames for a jump d, and the ramp law's
(z sigma sqrt(3) / (v T))^(2/3) for a ramp; on the scenes it finds every slide; and the
CLI prints it beside the methods, per family too."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from eskin_industrial.evaluation.bound import oracle_delays, oracle_score
from eskin_industrial.evaluation.families import get_family

RATE = 100.0


def _scene(path: np.ndarray, sigma: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A still contact for 10 s, then ``path`` (mm along x, from the onset on), with
    white noise of ``sigma`` on the measured centre; labels: slip while it moves."""
    rng = np.random.default_rng(seed)
    k0 = 1000
    t = np.arange(k0 + len(path)) / RATE
    true = np.zeros((t.size, 2))
    true[k0:, 0] = path
    noisy = true + sigma * rng.standard_normal(true.shape)
    labels = np.full(t.size, "stable", dtype=object)
    labels[k0:] = "slip"
    return true, noisy, t, labels


@pytest.mark.parametrize("jump, sigma", [(0.3, 0.05), (0.2, 0.08), (1.0, 0.04)])
def test_a_jump_is_seen_after_z_sigma_over_its_size_squared_frames(jump, sigma) -> None:
    true, noisy, t, labels = _scene(np.full(200, jump), sigma)
    z = 5.5
    (delay,) = oracle_delays(true, noisy, t, labels, z)
    frames = math.ceil((z * sigma / jump) ** 2)  # SNR^2 = n (jump / sigma)^2 after n frames
    assert delay is not None
    # (sigma is measured over the half-second before: within a frame or two of the law)
    assert abs(round(delay * RATE) + 1 - frames) <= max(1, 0.25 * frames)


def test_a_ramp_is_seen_after_the_ramp_laws_frames() -> None:
    v, sigma, z = 3.0 / RATE, 0.06, 5.5  # 3 mm/s at 100 Hz, the 5x5 array at about 5 N
    true, noisy, t, labels = _scene(v * np.arange(1, 301), sigma)
    (delay,) = oracle_delays(true, noisy, t, labels, z)
    law = (z * sigma * math.sqrt(3) / v) ** (2 / 3)  # SNR^2 = (v / sigma)^2 n^3 / 3
    assert delay is not None and abs(delay * RATE - law) <= 0.2 * law


def test_a_slide_that_never_stands_out_is_not_found() -> None:
    true, noisy, t, labels = _scene(np.full(50, 0.01), 0.05)
    assert oracle_delays(true, noisy, t, labels, 5.5) == [None]


def test_on_the_scenes_it_finds_every_slide_and_jumps_sooner_than_ramps() -> None:
    """The step-slip family's slides (jumps with rests) against the same slides as the
    suite has them (a ramp with a sawtooth), seeds 0-1: a jump of a tenth of a
    millimetre and more stands out sooner than a ramp of the same speed."""
    steps, ramps = get_family("step-slip"), get_family("stick-slip")
    s, per = oracle_score(("case3", "case6"), (0, 1), 5.5, spec_hook=steps.hook, stream=steps.stream)
    r, _ = oracle_score(("case3", "case6"), (0, 1), 5.5, stream=ramps.stream)
    assert s.found == s.events == r.found == r.events == 10 and set(per) == {"case3", "case6"}
    assert 0.0 < np.median(s.delays_s) < np.median(r.delays_s)


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "eskin_industrial", "evaluate", *args], capture_output=True, text=True,
                          timeout=300)


def test_the_cli_prints_the_oracle_beside_the_methods() -> None:
    md = _cli("-m", "cof-step", "-s", "case2", "--seeds", "0", "--oracle")
    assert md.returncode == 0, md.stderr
    row = next(line for line in md.stdout.splitlines() if line.startswith("| oracle (knows onset and path, z 5.5) |"))
    assert row.split("|")[2:4] == [" 1 ", " 1 "]
    js = _cli("--per-family", "--family", "step-slip", "-m", "cof-step", "--seeds", "0", "--oracle",
              "--condition", "speed=2", "--format", "json")
    assert js.returncode == 0, js.stderr
    doc = json.loads(js.stdout)
    assert doc["conditions"] == ["speed=2"] and doc["oracle"]["step-slip"]["found"] >= 1
    assert set(doc["oracle"]["step-slip"]["per_scene"]) == set(get_family("step-slip").scenes)
    bad = _cli("--hold-out-family", "torsion", "--oracle")
    assert bad.returncode == 2 and "leave out --condition and --oracle" in bad.stderr
