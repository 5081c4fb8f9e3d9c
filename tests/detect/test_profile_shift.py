"""The profile channel of cof-track (detect/profile_shift.py): its streaming state
against the batch answer, its tail against the chi-square's, and on a synthetic
footprint: a translation off the array's edge is found sooner than by the centre of
force's ramp, while a still footprint and a change of force alone are not found."""

from __future__ import annotations

import math

import numpy as np
import pytest

from eskin_industrial.detect.profile_shift import (
    ProfileShift,
    chi2_tail,
    chi2_threshold,
    profile_batch,
    profile_groups,
)
from eskin_industrial.detect.ramp import RampBank
from eskin_industrial.scenes.physics import footprint_forces
from eskin_industrial.scenes.spec import ArraySpec, Footprint

HORIZONS, BASE = (5, 10, 20), 20
ARRAY = ArraySpec()  # 5 x 5, 5 mm pitch: the cells span -2.5 .. 22.5 mm
XS, YS = (np.arange(25) % 5) * 5.0, (np.arange(25) // 5) * 5.0
GROUPS = profile_groups(XS, YS)
SIGMA = 0.01  # N per taxel, the scenes' default


def test_groups_are_the_column_then_the_row_sums() -> None:
    frame = np.arange(25.0)
    p = frame @ GROUPS
    grid = frame.reshape(5, 5)
    np.testing.assert_array_equal(p[:5], grid.sum(axis=0))
    np.testing.assert_array_equal(p[5:], grid.sum(axis=1))
    # a strip (one row) has no row sums: they would be the total alone
    assert profile_groups(np.arange(5) * 5.0, np.zeros(5)).shape == (5, 5)


def test_chi_square_tail_and_threshold() -> None:
    for x in (0.5, 3.0, 30.0):
        assert chi2_tail(x, 2) == pytest.approx(math.exp(-x / 2))
        assert chi2_tail(x, 1) == pytest.approx(math.erfc(math.sqrt(x / 2)))
        assert chi2_tail(x, 3) == pytest.approx(math.erfc(math.sqrt(x / 2)) + math.sqrt(2 * x / math.pi) * math.exp(-x / 2))
    # two degrees of freedom: Rayleigh's own tail, so z^2
    assert chi2_threshold(5.5, 2) == pytest.approx(5.5 ** 2, rel=1e-9)
    # more freedom, a higher threshold for the same tail
    assert chi2_threshold(5.5, 8) > 1.5 * 5.5 ** 2
    assert chi2_tail(chi2_threshold(5.5, 8), 8) == pytest.approx(math.exp(-5.5 ** 2 / 2), rel=1e-6)


@pytest.mark.parametrize("every", [1, 10])
def test_streaming_equals_batch(every: int) -> None:
    k = 150 * every
    rng = np.random.default_rng(4)
    frames = rng.uniform(0.1, 0.5, 25) + np.cumsum(rng.normal(0, 0.004, (k, 25)), axis=0)
    var = rng.uniform(0.5, 2.0, 25) * 1e-4
    batch = profile_batch(frames, GROUPS, var, HORIZONS, BASE, z=5.5, every=every)
    ps = ProfileShift(GROUPS, HORIZONS, BASE, z=5.5, every=every, noise_n=300)
    ps.set_noise(var)
    stream = []
    for i in range(k):
        ps.push(frames[i])
        score = ps.score()
        if (i + 1) % every == 0:
            stream.append(score)
        else:  # mid-block: the last block's score stands
            assert score == (stream[-1] if stream else 0.0)
    n = max(HORIZONS) + BASE
    assert stream[:n - 1] == [0.0] * (n - 1)
    np.testing.assert_allclose(stream[n - 1:], batch[n - 1:], rtol=1e-9)
    assert max(stream) > 1.0  # (the wandering map is found: the comparison is not vacuous)
    ps.reset()
    ps.push(frames[0])
    assert ps.score() == 0.0


def _footprint(centre_x: np.ndarray, force: np.ndarray) -> np.ndarray:
    foot = Footprint(size_mm=(20.0, 20.0), centre_mm=(10.0, 10.0))
    centre = np.column_stack([centre_x, np.full(len(centre_x), 10.0)])
    return footprint_forces(ARRAY, foot, centre, force)


def _cof_ramp(frames: np.ndarray) -> np.ndarray:
    """The ramp channel's score on the same frames, with the same noise (per axis, in
    force units over S^2, as cof-track learns it)."""
    bank = RampBank(HORIZONS, BASE, 5.5)
    s = frames.sum(axis=1)
    xc, yc = frames @ XS / s, frames @ YS / s
    # a centre's variance per axis: sigma^2 sum (x_i - xc)^2 / S^2
    qx = SIGMA ** 2 * float(((XS - xc.mean()) ** 2).sum())
    qy = SIGMA ** 2 * float(((YS - yc.mean()) ** 2).sum())
    out = []
    for i in range(len(frames)):
        bank.push(float(xc[i]), float(yc[i]), 1.0 / float(s[i]) ** 2)
        out.append(bank.score(qx, qy, 0.0))
    return np.array(out)


def _first(score: np.ndarray, onset: int) -> int:
    hit = np.flatnonzero(score[onset:] > 1.0)
    return int(hit[0]) if hit.size else len(score) - onset


def test_a_slide_back_onto_the_array_is_found_sooner_than_by_the_centre_of_force() -> None:
    """case6's slides back: the contact 2.5 mm off the array's edge moves back at
    2 mm/s.  Only one edge column changes, and the centre of force moves at about half
    the slide's speed: the sums' test must cross its threshold clearly sooner.  And a
    still footprint, on the same noise, must not cross it at all."""
    rng = np.random.default_rng(8)
    k, onset, v = 200, 100, 2.0 / 100  # 100 Hz, mm per sample
    x = np.full(k, 15.0)
    x[onset:] -= v * np.arange(1, k - onset + 1)
    clean = _footprint(x, np.full(k, 6.0))
    still = _footprint(np.full(k, 15.0), np.full(k, 6.0))
    var = np.full(25, SIGMA ** 2)
    delays_sums, delays_cof, still_max = [], [], []
    for _ in range(12):
        frames = clean + rng.normal(0, SIGMA, clean.shape)
        delays_sums.append(_first(profile_batch(frames, GROUPS, var, HORIZONS, BASE, z=5.5), onset))
        delays_cof.append(_first(_cof_ramp(frames), onset))
        noisy = still + rng.normal(0, SIGMA, still.shape)
        still_max.append(float(np.nanmax(profile_batch(noisy, GROUPS, var, HORIZONS, BASE, z=5.5))))
    assert 0 < np.median(delays_sums) < 0.8 * np.median(delays_cof)
    assert min(delays_sums) > 0  # nothing before the onset
    assert max(still_max) < 1.0


def test_a_change_of_force_alone_is_no_shift() -> None:
    """A squeeze scales the whole profile: that direction is projected out, so a 20 %
    force ramp on a still footprint scores as the same noise on a constant force does,
    though the sums change by ten times their noise and more."""
    rng = np.random.default_rng(9)
    k = 200
    noise = rng.normal(0, SIGMA, (k, 25))
    var = np.full(25, SIGMA ** 2)
    squeezed = _footprint(np.full(k, 12.0), np.linspace(6.0, 7.2, k)) + noise
    held = _footprint(np.full(k, 12.0), np.full(k, 6.0)) + noise
    score = profile_batch(squeezed, GROUPS, var, HORIZONS, BASE, z=5.5)
    same = profile_batch(held, GROUPS, var, HORIZONS, BASE, z=5.5)
    assert float(np.nanmax(score)) < 1.0
    np.testing.assert_allclose(score[~np.isnan(score)], same[~np.isnan(same)], atol=0.05)
    p = squeezed @ GROUPS  # (the squeeze is large: the comparison is not vacuous)
    assert float(np.abs(p[-1] - p[0]).max()) > 10 * math.sqrt(5) * SIGMA  # a sum of 5 taxels


def test_white_noise_crosses_the_threshold_as_rarely_as_its_chi_square_tail() -> None:
    """Under white taxel noise (each taxel its own level) the statistic exceeds its
    threshold at the chi-square tail's rate per horizon; the bank of three, strongly
    correlated, stays within three times one horizon's."""
    rng = np.random.default_rng(12)
    k = 40_000
    sigma = rng.uniform(0.5, 2.0, 25) * SIGMA
    frames = 0.3 + rng.normal(0, 1, (k, 25)) * sigma
    z = 2.5
    score = profile_batch(frames, GROUPS, sigma ** 2, HORIZONS, BASE, z=z)
    rate = float(np.mean(score[~np.isnan(score)] > 1.0))
    one = math.exp(-z * z / 2)
    assert one < rate < 3 * one


def test_the_learnt_noise_is_the_taxels_and_a_still_map_stays_quiet() -> None:
    """Streaming, with its noise learnt from calm blocks (10 frames each): learnt near
    the true per-taxel variance of a block mean, and a still noisy map never crosses."""
    rng = np.random.default_rng(13)
    every, k = 10, 6000
    ps = ProfileShift(GROUPS, HORIZONS, BASE, z=5.5, every=every, noise_n=300)
    frames = _footprint(np.full(k, 12.0), np.full(k, 6.0)) + rng.normal(0, SIGMA, (k, 25))
    top = 0.0
    for i in range(k):
        ps.push(frames[i])
        top = max(top, ps.score())
        ps.calm()
    np.testing.assert_allclose(ps._var, SIGMA ** 2 / every, rtol=0.35)
    assert 0.0 <= top < 1.0


def _slip_times(profile_shift: bool, name: str, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    from eskin_industrial.detect.cof_track import CofTrack
    from eskin_industrial.detect.settings import CofTrackSettings, DetectorSettings
    from eskin_industrial.detect.state import GraspState
    from eskin_industrial.evaluation.corpus import coordinates
    from eskin_industrial.scenes import render

    rec = render(name, 100.0, seed)
    x, y = coordinates(rec)
    # the torsion channel off: the sums alone are what is tested here
    settings = DetectorSettings(cof_track=CofTrackSettings(profile_shift=profile_shift, profile_z=6.0, torsion=False))
    ups = CofTrack(settings, x, y, 100.0).feed(rec.t, rec.forces)
    t = np.array([u.t for u in ups])
    slip = np.array([u.state == GraspState.SLIP for u in ups])
    return t, slip, rec.t[rec.labels == "slip"]


def test_a_turn_the_centre_of_force_does_not_see_is_found_by_the_sums() -> None:
    """The twist scene turns an 8 N block 30 degrees about its own centre: the CoF stays,
    so cof-track without the channel (and without its torsion channel) reads no slip at all; the sums' outline turns, and
    with it the turn is found, and nothing before it."""
    t, slip, truth = _slip_times(False, "twist", 0)
    assert not slip.any()
    t, slip, truth = _slip_times(True, "twist", 0)
    onset = float(truth.min())
    assert slip[(t >= onset) & (t <= truth.max() + 0.5)].any()
    assert not slip[t < onset].any()
