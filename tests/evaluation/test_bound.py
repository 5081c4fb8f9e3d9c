"""The delay's bound (evaluation/bound.py): the oracle that knows the onset and the
path needs (z sigma / d)^2 frames for a jump d, and the ramp law's
(z sigma sqrt(3) / (v T))^(2/3) for a ramp; on the scenes it finds every slide; the
one watching the whole distribution finds the turns the centre of force cannot see,
and no slide later; and the CLI prints both beside the methods, per family too."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from eskin_industrial.evaluation.bound import distribution_path, oracle_delays, oracle_score
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
    s, per = oracle_score(("case3", "case6"), (0, 1), 5.5, spec_hook=steps.hook, stream=steps.stream)["cof"]
    r, _ = oracle_score(("case3", "case6"), (0, 1), 5.5, stream=ramps.stream)["cof"]
    assert s.found == s.events == r.found == r.events == 10 and set(per) == {"case3", "case6"}
    assert 0.0 < np.median(s.delays_s) < np.median(r.delays_s)


def _turning_square(deg_per_frame: float, sigma: float, seed: int = 0) -> tuple[np.ndarray, ...]:
    """A 4 x 4 mm square of uniform pressure on a 1 mm grid of 12 x 12 taxels, still for
    2 s at 100 Hz, then turning about its centre; white noise of ``sigma`` a taxel."""
    xs = np.arange(12) - 5.5
    gx, gy = (a.ravel() for a in np.meshgrid(xs, xs))
    k0, k1 = 200, 260
    frames = []
    for k in range(k1):
        a = np.deg2rad(deg_per_frame * max(0, k - k0 + 1))
        u, v = np.cos(a) * gx + np.sin(a) * gy, -np.sin(a) * gx + np.cos(a) * gy
        # (a soft edge, so that the turn changes the taxels smoothly)
        frames.append(np.clip(2.5 - np.maximum(abs(u), abs(v)), 0.0, 1.0))
    clean = np.array(frames) * 0.5
    noisy = clean + sigma * np.random.default_rng(seed).standard_normal(clean.shape)
    t = np.arange(k1) / RATE
    labels = np.full(k1, "stable", dtype=object)
    labels[k0:] = "slip"
    return clean, noisy, gx, gy, t, labels


def test_the_distributions_oracle_sees_a_turn_that_leaves_the_centre_in_place() -> None:
    from eskin_industrial.evaluation.bound import cof_path

    clean, noisy, gx, gy, t, labels = _turning_square(0.5, 0.03)
    (by_cof,) = oracle_delays(cof_path(clean, gx, gy), cof_path(noisy, gx, gy), t, labels, 5.5)
    (by_image,) = oracle_delays(distribution_path(clean), distribution_path(noisy), t, labels, 5.5)
    assert by_cof is None  # (a square turning about its centre keeps its centre)
    assert by_image is not None and 0.02 <= by_image <= 0.1
    # (more noise, later; a faster turn, sooner)
    (noisier,) = oracle_delays(distribution_path(clean), distribution_path(_turning_square(0.5, 0.1)[1]), t,
                               labels, 5.5)
    fast = _turning_square(2.0, 0.03)
    (faster,) = oracle_delays(distribution_path(fast[0]), distribution_path(fast[1]), t, labels, 5.5)
    assert noisier is not None and faster is not None and faster < by_image < noisier


def test_on_the_scenes_the_distributions_oracle_is_never_later_and_finds_the_turns() -> None:
    """Seeds 0-1: on the stick-slip family's slides the whole distribution's oracle is at
    or before the centre's at the median; on the torsion family only it finds the turns."""
    ramps, turns = get_family("stick-slip"), get_family("torsion")
    r = oracle_score(("case3", "case4"), (0, 1), 5.5, stream=ramps.stream)
    q = oracle_score(("case2", "twist"), (0, 1), 5.5, spec_hook=turns.hook, stream=turns.stream)
    assert r["cof"][0].found == r["distribution"][0].found == 4
    assert np.median(r["distribution"][0].delays_s) <= np.median(r["cof"][0].delays_s)
    assert q["cof"][0].found == 0 and q["distribution"][0].found == q["distribution"][0].events == 4


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "eskin_industrial", "evaluate", *args], capture_output=True, text=True,
                          timeout=300)


def test_the_cli_prints_the_oracle_beside_the_methods() -> None:
    md = _cli("-m", "cof-step", "-s", "case2", "--seeds", "0", "--oracle")
    assert md.returncode == 0, md.stderr
    row = next(line for line in md.stdout.splitlines() if line.startswith("| oracle (knows onset and path, z 5.5) |"))
    assert row.split("|")[2:4] == [" 1 ", " 1 "]
    image = next(line for line in md.stdout.splitlines()
                 if line.startswith("| oracle, whole distribution (knows onset and path, z 5.5) |"))
    assert image.split("|")[2:4] == [" 1 ", " 1 "]
    js = _cli("--per-family", "--family", "step-slip", "-m", "cof-step", "--seeds", "0", "--oracle",
              "--condition", "speed=2", "--format", "json")
    assert js.returncode == 0, js.stderr
    doc = json.loads(js.stdout)
    assert doc["conditions"] == ["speed=2"] and doc["oracle"]["step-slip"]["found"] >= 1
    assert set(doc["oracle"]["step-slip"]["per_scene"]) == set(get_family("step-slip").scenes)
    assert doc["oracle_distribution"]["step-slip"]["found"] >= doc["oracle"]["step-slip"]["found"]
    turns = _cli("--per-family", "--family", "torsion", "-m", "cof-step", "--seeds", "0", "--oracle")
    assert turns.returncode == 0, turns.stderr
    rows = {line.split("|")[2].strip(): line.split("|")[4].strip() for line in turns.stdout.splitlines()
            if line.startswith("| torsion | oracle")}
    assert rows == {"oracle (knows onset and path, z 5.5)": "0",
                    "oracle, whole distribution (knows onset and path, z 5.5)": "9"}
    bad = _cli("--hold-out-family", "torsion", "--oracle")
    assert bad.returncode == 2 and "leave out --condition and --oracle" in bad.stderr
