"""Every detection method, stream and batch, driven with any finite force up to 1e300
and any time (NaN, infinite, huge, repeated, backwards): no exception, and every
update a finite verdict or a flagged invalid one."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from eskin_industrial.detect.hygiene import FORCE_LIMIT_N, TIME_FAULTS, time_verdicts
from eskin_industrial.detect.methods import METHODS
from eskin_industrial.detect.state import GraspState
from eskin_industrial.detect.updates import UpdateTable
from eskin_industrial.frames import FrameFlag
from tests.helpers.scenes import grasp

RATE = 100.0
N = 25
K = 160  # frames: past the warm-up of every method at 100 Hz

finite = st.floats(min_value=-1e300, max_value=1e300, allow_nan=False, allow_infinity=False)
any_time = st.floats(allow_nan=True, allow_infinity=True)


@st.composite
def recordings(draw):
    """A grasp scaled by 10**e (e up to +-300), with single taxels, whole frames and
    times overwritten by arbitrary values, and the time axis scaled and shifted."""
    seed = draw(st.integers(0, 2**16))
    f = grasp(K, N, seed=seed, noise=0.02)
    f[: draw(st.integers(0, K // 4))] = 0.0
    f *= 10.0 ** draw(st.integers(-300, 299))
    for i, j, v in draw(st.lists(st.tuples(st.integers(0, K - 1), st.integers(0, N - 1), finite), max_size=8)):
        f[i, j] = v
    for i, row in draw(st.lists(st.tuples(st.integers(0, K - 1), st.lists(finite, min_size=N, max_size=N)), max_size=2)):
        f[i] = row
    scale = draw(st.sampled_from([1.0, 1.0, 1e-6, 1e6, 0.0, -1.0]))
    t = np.arange(K) / RATE * scale + draw(st.sampled_from([0.0, 1.7e9, -5e9, 9.99e9]))
    for i, v in draw(st.lists(st.tuples(st.integers(0, K - 1), any_time), max_size=6)):
        t[i] = v
    return t, f


def assert_sound(table: UpdateTable) -> None:
    for col in ("t", "r_coe", "r_dw", "f_sum", "xc", "yc"):
        assert np.isfinite(getattr(table, col)).all(), col
    assert set(table.state.tolist()) <= {int(s) for s in GraspState}
    assert table.valid.dtype == bool
    assert (table.f_sum <= N * FORCE_LIMIT_N).all() and (table.f_sum >= 0).all()


def run_both(method, profile, t, f) -> UpdateTable:
    x, y = profile.coordinates_mm
    streamed = UpdateTable.from_updates(method.stream(profile.detector, x, y, RATE).feed(t, f))
    batch = method.batch(profile.detector, x, y, RATE, t, f)
    assert len(streamed) == len(batch)
    np.testing.assert_array_equal(streamed.state, batch.state)
    np.testing.assert_array_equal(streamed.flags, batch.flags)
    assert_sound(streamed)
    assert_sound(batch)
    return streamed


FAST = sorted(name for name, m in METHODS.items() if not m.needs_model)


@pytest.mark.parametrize("name", FAST)
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                                  HealthCheck.too_slow])
@given(rec=recordings())
def test_any_finite_force_and_any_time(paper_profile, name, rec):
    t, f = rec
    run_both(METHODS[name], paper_profile, t, f)


@pytest.mark.slow
@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                                  HealthCheck.too_slow])
@given(rec=recordings())
def test_the_learned_method_too(paper_profile, rec):
    from eskin_industrial.methods import bind

    t, f = rec
    run_both(bind(METHODS["learned"]), paper_profile, t, f)


@pytest.mark.parametrize("name", FAST)
def test_the_reported_cases(paper_profile, name):
    """One taxel at 1e160 N, a time of inf: each was a traceback (ripple.py, hygiene.py)."""
    t = np.arange(600) / RATE
    f = grasp(600, N, seed=3)
    f[300, 3] = 1e160
    table = run_both(METHODS[name], paper_profile, t, f)
    assert any(fl & FrameFlag.SATURATED for fl in table.flags.tolist())
    t2 = t.copy()
    t2[300] = math.inf
    run_both(METHODS[name], paper_profile, t2, grasp(600, N, seed=3))


def test_a_first_frame_with_no_time_refuses_only_itself(paper_profile):
    """A first time of 1e10 s (no time: past the limit) and, later, one that falls back
    to 0: the batch rule once took the NaN it kept for "no newest time yet" as the
    newest, refused the second frame too, and its updates fell one frame off the
    stream's (found by the test above)."""
    t = np.arange(K) / RATE
    t[0], t[60] = 1e10, 0.0
    verdicts = time_verdicts(t)
    assert verdicts[0] == TIME_FAULTS_CODE["not_a_time"] and verdicts[60] == TIME_FAULTS_CODE["backward_time"]
    assert (np.delete(verdicts, [0, 60]) == 0).all()
    f = grasp(K, N, seed=5, noise=0.02)
    for name in FAST:
        assert len(run_both(METHODS[name], paper_profile, t, f))  # (stream and batch the same updates)


TIME_FAULTS_CODE = {name: code for code, name in TIME_FAULTS.items()}


def test_time_refusals_are_counted_by_kind_the_same_in_stream_and_batch(paper_profile):
    t = np.arange(1000) / RATE
    t[100] = math.nan
    t[101] = math.inf
    t[102] = 1e300  # absurd: must not hold back the frames after it
    t[200] = t[199]  # repeated
    t[500:] -= 3.005  # a backward jump of 3 s: 300 frames come before the newest kept one
    verdicts = time_verdicts(t)
    counts = {name: int(np.sum(verdicts == code)) for code, name in TIME_FAULTS.items()}
    assert counts == {"not_a_time": 3, "repeated_time": 1, "backward_time": 300}
    x, y = paper_profile.coordinates_mm
    det = METHODS["cof-track"].stream(paper_profile.detector, x, y, RATE)
    det.feed(t, grasp(1000, N, seed=1))
    assert det.time_faults == counts
    assert det.dropped == sum(counts.values())


@pytest.mark.parametrize("name", ["paper", "cof-track"])
def test_the_pipeline_counts_them_by_kind_too(paper_profile, name):
    from eskin_industrial.calibration import Calibrator
    from eskin_industrial.frames import RawScan
    from eskin_industrial.pipeline import Pipeline

    raw = Calibrator.from_section(paper_profile.calibration, N).to_raw(grasp(300, N, seed=2))
    t = np.arange(300) / RATE
    t[10], t[20], t[200:] = math.nan, t[19], t[200:] - 1.005
    pipe = Pipeline(paper_profile, method=name)
    for k in range(300):
        pipe.push(RawScan(k, float(t[k]), raw[k]))
    assert pipe.time_faults() == {"not_a_time": 1, "repeated_time": 1, "backward_time": 100}
    assert pipe.counters.dropped_by_detector == 102
