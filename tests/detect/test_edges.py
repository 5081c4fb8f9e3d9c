"""Every edge the method note names: a defined output, no NaN, no exception, the
offending frame flagged."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from eskin_industrial import FrameFlag
from eskin_industrial.detect import GraspState, PaperDetector, paper_batch
from tests.helpers.scenes import grasp

RATE = 100.0


def run(profile, f, t=None, cfg=None, rate=RATE):
    cfg = cfg or profile.detector
    t = np.arange(len(f)) / rate if t is None else t
    x, y = profile.coordinates_mm
    table = paper_batch(cfg, x, y, rate, t, f)
    assert np.isfinite(table.r_coe).all() and np.isfinite(table.r_dw).all()
    assert np.isfinite(table.f_sum).all() and np.isfinite(table.xc).all() and np.isfinite(table.yc).all()
    return table


def test_zero_total_force_is_no_contact(paper_profile):
    table = run(paper_profile, np.zeros((300, 25)))
    assert (table.state == GraspState.NO_CONTACT).all()
    assert (table.r_coe == 0).all() and (table.r_dw == 0).all()


def test_uniform_and_constant_distribution(paper_profile):
    table = run(paper_profile, np.full((300, 25), 0.3))  # zero variance in space and time
    assert (table.state[table.valid] == GraspState.STABLE).all()
    assert table.valid.any()
    assert np.abs(table.r_coe).max() < 1e-6 and np.abs(table.r_dw).max() < 1e-6


def test_still_grasp_at_the_noise_floor_never_slips(paper_profile):
    for seed in range(5):
        table = run(paper_profile, grasp(3000, seed=seed, noise=0.01))
        assert not (table.state == GraspState.SLIP).any()
        assert table.valid[5:].all()


def test_still_grasp_without_floor_is_where_the_paper_rule_is_fragile(paper_profile):
    # With no noise floor both window sums are noise, and their ratio jumps: this is
    # the failure the floor exists for. Still no NaN, still defined.
    cfg = replace(paper_profile.detector, coe_floor=0.0, dw_floor_mm2=0.0)
    bare = run(paper_profile, grasp(3000, seed=1, noise=0.01), cfg=cfg)
    floored = run(paper_profile, grasp(3000, seed=1, noise=0.01))
    assert bare.r_dw.max() > floored.r_dw.max()


def test_nan_and_inf_frames_are_flagged_and_replaced(paper_profile):
    f = grasp(400, seed=2)
    f[100] = np.nan
    f[200, 3] = np.inf
    f[201, 4] = -np.inf
    table = run(paper_profile, f)
    assert (table.flags & FrameFlag.INVALID).sum() >= 2
    assert not (table.state == GraspState.SLIP).any()


def test_negative_and_saturated_readings(paper_profile):
    f = grasp(400, seed=3)
    f[150, 0] = -2.0
    flags = np.zeros(400, np.int64)
    flags[250] = FrameFlag.SATURATED  # from calibration, passed through
    x, y = paper_profile.coordinates_mm
    table = paper_batch(paper_profile.detector, x, y, RATE, np.arange(400) / RATE, f, flags)
    assert (table.flags & FrameFlag.NEGATIVE).any()
    assert (table.flags & FrameFlag.SATURATED).any()
    assert np.isfinite(table.r_coe).all()


def test_window_shorter_than_the_wavelet_filter(paper_profile):
    # 0.4 s at 5 Hz is 4 samples (hops of one sample): db4 needs 8. R_dw cannot be
    # computed, so no update is valid and none reads slip; R_coe still runs.
    cfg = replace(paper_profile.detector, wavelet="db4")
    table = run(paper_profile, grasp(100, seed=4), cfg=cfg, rate=5.0)
    assert len(table) > 0
    assert (table.flags & FrameFlag.SHORT_WINDOW).all()
    assert not table.valid.any()
    assert (table.r_dw == 0).all()


def test_gaps_are_filled_or_reset(paper_profile):
    f = grasp(600, seed=5)
    t = np.arange(600) / RATE
    t[200:] += 0.1  # 10 missing frames: filled
    t[400:] += 5.0  # far longer than max_gap_s: reset and warm up again
    table = run(paper_profile, f, t=t)
    assert (table.flags & FrameFlag.GAP_BEFORE).any()
    assert (table.flags & FrameFlag.RESET).any()
    after_reset = np.flatnonzero(table.flags & FrameFlag.RESET)[0]
    assert not table.valid[after_reset]  # warm-up again
    assert table.valid[-1]


def test_duplicated_and_out_of_order_frames_are_dropped(paper_profile):
    f = grasp(400, seed=6)
    t = np.arange(400) / RATE
    t[101] = t[100]
    t[201] = t[150]
    x, y = paper_profile.coordinates_mm
    det = PaperDetector(paper_profile.detector, x, y, RATE)
    updates = det.feed(t, f)
    assert det.dropped == 2
    assert any(u.flags & FrameFlag.DUPLICATE for u in updates)
    assert all(np.isfinite(u.r_coe) and np.isfinite(u.r_dw) for u in updates)


def test_contact_change_peaks_then_settles(paper_profile):
    # the grab raises both indicators (paper: "a peak occurs at the grab"), then they settle
    f = grasp(800, seed=7)
    f[:300] = 0.0
    table = run(paper_profile, f)
    grab = np.searchsorted(table.t, 3.0)
    assert table.r_coe[grab:grab + 6].max() > 2.5
    assert table.r_coe[-5:].max() < 0.5 and table.state[-1] == GraspState.STABLE


@settings(max_examples=60, deadline=None)
@given(arrays(np.float64, (120, 25), elements=st.floats(allow_nan=True, allow_infinity=True, width=32)),
       st.lists(st.one_of(st.floats(-1.0, 3.0), st.just(float("nan"))), min_size=120, max_size=120))
def test_any_input_gives_defined_output(paper_profile, f, dt):
    t = np.cumsum(np.asarray(dt))  # non-monotonic, NaN, huge gaps: all allowed
    x, y = paper_profile.coordinates_mm
    table = paper_batch(paper_profile.detector, x, y, RATE, t, f)
    for col in ("r_coe", "r_dw", "f_sum", "xc", "yc"):
        assert np.isfinite(getattr(table, col)).all(), col
    assert set(np.unique(table.state)) <= {0, 1, 2, 3}
