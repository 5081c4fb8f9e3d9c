"""The streaming detector (frame by frame, any chunking) gives the batch answer."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from eskin_industrial.detect import COLUMNS, PaperDetector, UpdateTable, paper_batch
from tests.helpers.scenes import grasp


def faulty_recording(seed: int, k: int = 1500, n: int = 25, rate: float = 100.0):
    """A grasp with contact changes, a slide, NaN, negatives, duplicates, gaps."""
    rng = np.random.default_rng(seed)
    t = np.arange(k) / rate + rng.normal(0, 0.05 / rate, k)
    f = grasp(k, n, seed=seed, noise=0.02)
    f[: k // 10] = 0.0  # no contact at first
    a, b = k // 3, k // 3 + 80
    f[a:b] = np.roll(f[a:b], 1, axis=1) * np.linspace(1, 1.5, b - a)[:, None]  # shifted footprint
    f[rng.integers(0, k, 5)] = np.nan
    f[rng.integers(0, k, 5), rng.integers(0, n, 5)] = np.inf
    f[rng.integers(0, k, 5), rng.integers(0, n, 5)] = -0.3
    dup = rng.integers(1, k, 4)
    t[dup] = t[dup - 1]  # duplicated timestamps
    t[k // 2] = t[k // 2 - 3]  # out of order
    t[2 * k // 3:] += 0.07  # short gap: filled
    t[4 * k // 5:] += 2.0  # long gap: reset
    return t, f


def stream_in_chunks(det: PaperDetector, t, f, sizes) -> UpdateTable:
    out, i = [], 0
    for size in sizes:
        out.extend(det.feed(t[i:i + size], f[i:i + size]))
        i += size
    out.extend(det.feed(t[i:], f[i:]))
    return UpdateTable.from_updates(out)


def assert_same(a: UpdateTable, b: UpdateTable) -> None:
    assert len(a) == len(b) > 0
    for col in COLUMNS:
        x, y = getattr(a, col), getattr(b, col)
        if col in ("state", "flags", "valid"):
            np.testing.assert_array_equal(x, y, err_msg=col)
        else:
            np.testing.assert_allclose(x, y, rtol=1e-9, atol=1e-9, err_msg=col)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_random_chunks_give_the_batch_answer(paper_profile, seed):
    x, y = paper_profile.coordinates_mm
    t, f = faulty_recording(seed)
    batch = paper_batch(paper_profile.detector, x, y, 100.0, t, f)
    rng = np.random.default_rng(seed + 100)
    sizes = rng.integers(1, 60, 200)
    streamed = stream_in_chunks(PaperDetector(paper_profile.detector, x, y, 100.0), t, f, sizes)
    assert_same(batch, streamed)
    assert np.isfinite(batch.r_coe).all() and np.isfinite(batch.r_dw).all()
    assert (batch.flags != 0).any()


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    hop_samples=st.integers(1, 9),
    blocks=st.integers(1, 6),
    lag_samples=st.integers(1, 12),
    wavelet=st.sampled_from(["db1", "db2", "db3", "db4", "sym5"]),
    ratio_mode=st.sampled_from(["symmetric", "rise"]),
)
def test_any_geometry_streams_like_batch(hand_profile, seed, hop_samples, blocks, lag_samples, wavelet, ratio_mode):
    rate = 100.0
    cfg = replace(hand_profile.detector, hop_s=hop_samples / rate, window_s=hop_samples * blocks / rate,
                  lag_s=lag_samples / rate, wavelet=wavelet, ratio_mode=ratio_mode)
    x, y = hand_profile.coordinates_mm
    t, f = faulty_recording(seed, k=400, n=20)
    batch = paper_batch(cfg, x, y, rate, t, f)
    sizes = np.random.default_rng(seed).integers(1, 30, 40)
    assert_same(batch, stream_in_chunks(PaperDetector(cfg, x, y, rate), t, f, sizes))


@pytest.mark.parametrize("seed", [4, 5])
def test_contact_at_the_threshold_streams_like_batch(paper_profile, seed):
    # the total wanders through the contact rule's band (0.1-0.2 N), where contact
    # depends on the frames before: both engines must carry that memory alike,
    # across a long gap (restart: out of contact again) too
    rng = np.random.default_rng(seed)
    k = 1200
    t = np.arange(k) / 100.0
    t[700:] += 1.0
    total = np.clip(0.15 + 0.1 * np.sin(t * 3.0) + 0.04 * rng.standard_normal(k), 0.0, None)
    total[:30] = 0.0  # a settled, unloaded start (a total in the band from the first frame is the film's own)
    f = np.tile(total[:, None] / 25.0, (1, 25)) * (1 + 0.3 * rng.random((k, 25)))
    x, y = paper_profile.coordinates_mm
    cfg = replace(paper_profile.detector, hop_s=0.05, window_s=0.2)
    batch = paper_batch(cfg, x, y, 100.0, t, f)
    assert_same(batch, stream_in_chunks(PaperDetector(cfg, x, y, 100.0), t, f, rng.integers(1, 40, 80)))
    s = batch.f_sum
    band = (s > 0.1) & (s < 0.2)
    # the band holds updates in contact and out of it: the memory mattered
    assert (batch.state[band] == 0).any() and (batch.state[band] != 0).any()
