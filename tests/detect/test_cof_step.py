"""The plain displacement rival (cof-step, detect/cof_step.py): its statistic against
its definition through the detector's own frame path, its silence on a still noisy
grip, a jump after a rest seen in two frames, and its test once per 10 ms at 1 kHz."""

from __future__ import annotations

import numpy as np
import pytest

from eskin_industrial.detect import GraspState, get_method
from eskin_industrial.detect.cof_step import CofStep
from eskin_industrial.detect.settings import DetectorSettings
from eskin_industrial.frames import FrameFlag

X = np.tile(np.arange(5) * 5.0, 5)
Y = np.repeat(np.arange(5) * 5.0, 5)


def frames(centres: np.ndarray, total: float = 8.0) -> np.ndarray:
    """Frames whose centre of force is each (x, y) in [0, 5] mm: the load shared by the
    four taxels at (0, 0), (5, 0), (0, 5) and (5, 5) in bilinear weights."""
    assert ((centres >= 0.0) & (centres <= 5.0)).all()  # (beyond, a weight would be negative and clipped)
    u, v = centres[:, 0] / 5.0, centres[:, 1] / 5.0
    f = np.zeros((len(centres), 25))
    f[:, 0], f[:, 1] = (1 - u) * (1 - v), u * (1 - v)
    f[:, 5], f[:, 6] = (1 - u) * v, u * v
    return f * total


def statistic(c: np.ndarray, k: int, newest: int, gap: int, base: int) -> float:
    """The rival's statistic by its definition, at sample k of the centres it counts."""
    b = c[k - gap - base + 1:k - gap + 1]
    d = c[k - newest + 1:k + 1].mean(axis=0) - b.mean(axis=0)
    return float(np.sqrt(((d / b.std(axis=0, ddof=1)) ** 2).sum()))


def test_the_streaming_statistic_is_its_definition_through_the_frame_path() -> None:
    rng = np.random.default_rng(2)
    k = 1400  # the sums are renewed from the ring twice on the way
    c = 1.5 + 0.05 * rng.standard_normal((k, 2)) + np.cumsum(rng.random((k, 1)) < 0.02, axis=0) * 0.05
    det = CofStep(DetectorSettings(), X, Y, 100.0, threshold=1.0)
    ups = det.feed(np.arange(k) / 100.0, frames(c))
    assert len(ups) == k  # an update a frame at 100 Hz
    settle = round(det.settle_s * 100)
    counted = c[settle:]  # its centres start once the grab has settled
    n = det.gap + det.base
    for i in range(k):
        j = i - settle  # the newest centre counted
        want = statistic(counted, j, det.newest, det.gap, det.base) if j >= n - 1 else 0.0
        assert ups[i].score_a == pytest.approx(want, rel=1e-9, abs=1e-12), i


def test_a_held_copy_is_no_sample() -> None:
    rng = np.random.default_rng(4)
    c = 2.5 + 0.05 * rng.standard_normal((300, 2))
    flags = np.zeros(300, int)
    flags[100:110] = int(FrameFlag.FILLED)
    f = frames(c)
    f[100:110] = f[99]  # the copies a gap is filled with
    det = CofStep(DetectorSettings(), X, Y, 100.0, threshold=1.0)
    ups = det.feed(np.arange(300) / 100.0, f, flags)
    keep = np.ones(300, bool)
    keep[100:110] = False
    counted = c[keep][round(det.settle_s * 100):]
    want = statistic(counted, len(counted) - 1, det.newest, det.gap, det.base)
    assert ups[-1].score_a == pytest.approx(want, rel=1e-9)


def test_a_still_noisy_grip_stays_stable_and_a_jump_after_a_rest_is_seen_in_two_frames() -> None:
    rng = np.random.default_rng(7)
    sigma = 0.04  # mm per axis: the 5x5 array's CoF at 8 N
    c = 2.5 + sigma * rng.standard_normal((6000, 2))
    c[5000:, 0] += 0.3  # a jump of 7.5 sigma after 50 s at rest
    ups = get_method("cof-step").stream(DetectorSettings(), X, Y, 100.0).feed(np.arange(6000) / 100.0, frames(c))
    state = np.array([u.state for u in ups])
    assert not (state[:5000] == GraspState.SLIP).any()
    assert (state[5000:5002] == GraspState.SLIP).any()


def test_at_1_khz_it_is_tested_once_per_10_ms() -> None:
    rng = np.random.default_rng(1)
    c = 2.5 + 0.04 * rng.standard_normal((3000, 2))
    det = CofStep(DetectorSettings(), X, Y, 1000.0, threshold=1.0)
    assert (det.newest, det.gap, det.base) == (20, 100, 500)  # the same times as at 100 Hz
    scores = [u.score_a for u in det.feed(np.arange(3000) / 1000.0, frames(c))]
    assert len(scores) == 300  # one update a hop
    tested = np.flatnonzero(np.asarray(scores) > 0)
    assert tested.size > 200 and np.all(np.diff(tested) == 1)  # each update reads its hop's one test
