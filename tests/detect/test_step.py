"""The step channel of cof-track (detect/step.py): its streaming state against the
batch answer, its own noise against a white-noise model's where the centre wanders,
its silence while the force's level moves (a soft pad's swing), and none under a
stick-slip ripple about a constant level, where the ramp's own silence falls and the
jumps would wait for the fast displacement."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from eskin_industrial.detect import GraspState
from eskin_industrial.detect.cof_track import CofTrack
from eskin_industrial.detect.step import StepTest, step_batch
from eskin_industrial.evaluation.suite import DEFAULT_SETTINGS

X = np.tile(np.arange(5) * 5.0, 5)
Y = np.repeat(np.arange(5) * 5.0, 5)
RATE = 100.0


@pytest.mark.parametrize("newest, gap, base", [(2, 10, 50), (1, 1, 3), (20, 100, 500), (3, 3, 7)])
def test_streaming_equals_batch(newest: int, gap: int, base: int) -> None:
    rng = np.random.default_rng(1)
    k = 3000  # the sums are renewed from the ring several times on the way
    c = 10 + 0.05 * rng.standard_normal((k, 3)) + np.cumsum(rng.random((k, 3)) < 0.01, axis=0) * 0.3
    c[:, 2] *= 1.0 + 0.5 * np.sin(np.arange(k) * 2.3)  # (a total that swings: the weights differ)
    test = StepTest(newest, gap, base)
    want = step_batch(c, newest, gap, base)
    for i in range(k):
        test.push(*c[i])
        d = test.difference()
        if d is None:
            assert np.isnan(want[i]).all() and test.level_change() == 0.0 and test.weight == 0.0
        else:
            np.testing.assert_allclose([*d, test.level_change(), test.weight], want[i], rtol=1e-12, atol=1e-12)
    test.reset()
    test.push(1.0, 1.0, 1.0)
    assert test.difference() is None


def frames(centres: np.ndarray, totals: np.ndarray, rng: np.random.Generator, sigma: float = 0.01) -> np.ndarray:
    """Frames whose centre of force is each (x, y) in [0, 5] mm and whose total is each
    total (bilinear weights over the taxels at (0, 0), (5, 0), (0, 5), (5, 5)), every
    taxel with ``sigma`` of noise and clipped at 0 as the scenes' sensor does."""
    assert ((centres >= 0.0) & (centres <= 5.0)).all()
    u, v = centres[:, 0] / 5.0, centres[:, 1] / 5.0
    f = np.zeros((len(centres), 25))
    f[:, 0], f[:, 1] = (1 - u) * (1 - v), u * (1 - v)
    f[:, 5], f[:, 6] = (1 - u) * v, u * v
    return np.maximum(f * totals[:, None] + sigma * rng.standard_normal(f.shape), 0.0)


def run(f: np.ndarray, **overrides: float) -> tuple[CofTrack, np.ndarray]:
    det = CofTrack(DEFAULT_SETTINGS, X, Y, RATE, **overrides)
    ups = det.feed(np.arange(len(f)) / RATE, f)
    return det, np.array([u.state for u in ups])


def _learnt_and_spread(wander_mm: float, seed: int = 3) -> tuple[float, float, float]:
    """cof-track's learnt step noise along x times the centres' weight at 8 N, the
    statistic's own spread, and the white-noise model's, in force units, on an 8 N grip whose centre wanders about its
    place (a first-order process of ``wander_mm`` with a 0.3 s time constant) beside
    the taxels' noise."""
    rng = np.random.default_rng(seed)
    k, phi = 3000, np.exp(-1 / 30)
    w = np.zeros((k, 2))
    kicks = rng.standard_normal((k, 2)) * wander_mm * np.sqrt(1 - phi ** 2)
    for i in range(1, k):
        w[i] = phi * w[i - 1] + kicks[i]
    f = frames(2.5 + w, np.full(k, 8.0), rng)
    det, _ = run(f)
    s = f.sum(axis=1)
    seen = np.column_stack([f @ X / s, f @ Y / s])
    jumps = det._jumps
    d = step_batch(seen, jumps.newest, jumps.gap, jumps.base)[1000:, 0]
    white = float(np.var(np.diff(seen[:, 0]))) / 2.0 * (1 / jumps.newest + 1 / jumps.base)
    return det._step_vx * (1 / jumps.newest + 1 / jumps.base), float(np.nanvar(d)) * 64.0, white * 64.0


def test_its_noise_is_its_own_where_the_centre_wanders() -> None:
    """On a still grip the learnt noise is the statistic's spread (and the white-noise
    model's: the frame-to-frame noise times 1 / J + 1 / B); where the centre also
    wanders slowly about its place (30 um with a 0.3 s time constant), the spread over
    the step's 0.6 s is twice the model's, and the learnt noise follows the spread."""
    learnt, spread, white = _learnt_and_spread(0.0)
    assert learnt == pytest.approx(spread, rel=0.25) and spread == pytest.approx(white, rel=0.25)
    learnt, spread, white = _learnt_and_spread(0.03)
    assert spread > 1.8 * white and learnt > 1.4 * white


def test_a_stick_slip_ripple_leaves_it_open_where_the_ramp_falls_silent() -> None:
    """Jumps of 0.15 mm every 150 ms, at rest between them (1 mm/s), with the normal
    force rippling 4 % about its 8 N in step with them (dropping at each jump, the
    step-slip family's stick-slip): cof-track's own force-rate test reads the ripple as
    a varying force and silences the ramp, so without the step channel the slide waits
    for the fast displacement; the step channel's silence looks at the force's level
    over 0.1 s and 0.5 s means, which the ripple does not move, and finds the jumps
    within 30 ms (ten grips; none flags slip in its 10 s of holding before)."""
    k, onset, every = 1600, 1000, 15
    t = np.arange(k) / RATE
    path = np.zeros(k)
    path[onset:] = 0.15 * (1 + np.arange(k - onset) // every)
    phase = np.where(t >= t[onset], ((np.arange(k) - onset) % every) / every, 0.5)
    totals = 8.0 * (1.0 + 0.04 * (2.0 * phase - 1.0) * (t >= t[onset]))
    c = np.column_stack([0.5 + np.minimum(path, 4.0), np.full(k, 2.5)])  # (it stops at the array's far side)
    with_step, without = [], []
    for seed in range(10):
        f = frames(c, totals, np.random.default_rng(seed))
        for overrides, out in (({}, with_step), ({"step_s": 0.0}, without)):
            _, state = run(f, **overrides)
            assert not (state[:onset] == GraspState.SLIP).any()
            out.append(int(np.argmax(state[onset:] == GraspState.SLIP)))
    assert np.median(with_step) <= 3 and np.median(without) >= 3 * max(1.0, np.median(with_step))


def test_a_soft_pads_swing_keeps_it_silent() -> None:
    """A load swinging 15 % at 1 Hz whose centre follows its force by 0.15 mm (a soft
    pad, 6 N): the step's own statistic passes its threshold in every swing (by the
    white-noise model of its noise), yet with the step channel on no update reads slip:
    its silence while the force's level moves, and for a second after, holds it."""
    k = 1600
    t = np.arange(k) / RATE
    swing = np.where(t >= 8.0, 0.15 * np.sin(2 * np.pi * (t - 8.0)), 0.0)
    c = np.column_stack([2.5 + 1.0 * swing, np.full(k, 2.5)])
    for seed in range(6):
        f = frames(c, 6.0 * (1.0 + swing), np.random.default_rng(seed))
        det, state = run(f)
        assert not (state == GraspState.SLIP).any()
        s = f.sum(axis=1)
        seen = np.column_stack([f @ X / s, f @ Y / s])
        jumps = det._jumps
        d = step_batch(seen, jumps.newest, jumps.gap, jumps.base)[:, 0]
        sd = np.std(np.diff(seen[200:800, 0])) / np.sqrt(2.0) * np.sqrt(1 / jumps.newest + 1 / jumps.base)
        assert np.nanmax(np.abs(d[t >= 8.0])) > det._step_z * sd  # ungated, it would


def test_a_profile_can_turn_it_off_and_refuses_a_threshold_out_of_range() -> None:
    from eskin_industrial import ProfileError
    from eskin_industrial.profile import parse_profile
    from tests.helpers.paths import PROFILES

    text = (PROFILES / "paper-5x5.toml").read_text()
    off = parse_profile(text + "\n[detector.cof_track]\nstep_s = 0.0\n", "p.toml").detector
    assert CofTrack(off, X, Y, RATE)._jumps is None
    with pytest.raises(ProfileError, match=r"step_z: expected a value in \[3, 12\]"):
        parse_profile(text + "\n[detector.cof_track]\nstep_z = 1.0\n", "p.toml")
    assert replace(DEFAULT_SETTINGS.cof_track, step_z=7.0).step_z == 7.0



def test_a_total_shaken_between_light_and_firm_weighs_each_centre_by_its_own() -> None:
    """The hand's light hold (`hand-hold`, about 3 N) shaken by 2 N of machine vibration
    at 37 Hz from 3 s on: its total swings between 1 and 5 N from one frame to the next,
    and a centre taken at the light end is several times noisier than one at the firm
    end.  The step channel weighs each centre by its own total, and raises no slip of
    its own there (as many false alarms as without the channel); scaled by the newest
    total alone, as it once was, the same differences cross its threshold."""
    from eskin_industrial.evaluation import conditions
    from eskin_industrial.evaluation.metrics import score_scene
    from eskin_industrial.evaluation.suite import coordinates, run_one
    from eskin_industrial.scenes import load_scene, render

    r = render(conditions.vibration_onset(2.0)(load_scene("hand-hold")), RATE, 0)
    off = replace(DEFAULT_SETTINGS, cof_track=replace(DEFAULT_SETTINGS.cof_track, step_s=0.0))
    alarms = [score_scene(run_one(CofTrack, settings, r)[0], r.t, r.labels).false_alarms
              for settings in (DEFAULT_SETTINGS, off)]
    assert alarms[0] <= alarms[1]
    x, y = coordinates(r)
    det = CofTrack(DEFAULT_SETTINGS, x, y, RATE)
    det.feed(r.t, r.forces)
    s = r.forces.sum(axis=1)
    held = (s > 0.5) & (r.t > 4.0) & (r.labels == "stable")
    seen = np.column_stack([r.forces @ x / np.maximum(s, 1e-9), r.forces @ y / np.maximum(s, 1e-9), np.maximum(s, 1e-9)])
    jumps = det._jumps
    out = step_batch(seen, jumps.newest, jumps.gap, jumps.base)
    q = np.array([det._noise_x, det._noise - det._noise_x])  # (the learnt noise, force units)
    unweighted = (out[:, :2] ** 2 / q).sum(axis=1) * s ** 2 / (1 / jumps.newest + 1 / jumps.base)
    weighted = (out[:, :2] ** 2 / q).sum(axis=1) / out[:, 3]
    assert (np.sqrt(unweighted[held]) > det._step_z).sum() > 3 * max(1, (np.sqrt(weighted[held]) > det._step_z).sum())
