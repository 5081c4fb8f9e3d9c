"""Whatever method decides, R_coe and R_dw are the paper's indicators on the same frames;
the method's own scores are score_a and score_b."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from eskin_industrial.detect import METHODS, PaperDetector, get_method, paper_batch
from eskin_industrial.detect.alongside import PaperAlongside
from eskin_industrial.methods import method_of_code
from eskin_industrial.scenes import render
from tests.detect.test_stream_equals_batch import faulty_recording

SCORED = ("cof-track", "force-rate", "hf-energy", "cof-velocity")


@pytest.fixture(params=["scalars", "arrays"])
def hop_path(request, monkeypatch):
    """Each test on both ways of doing a hop's work, whatever the hop's length."""
    monkeypatch.setattr(PaperAlongside, "ARRAYS_FROM", 1 if request.param == "arrays" else 10**9)
    return request.param


def paper_alone(settings, x, y, rate, t, f):
    return PaperDetector(settings, x, y, rate).feed(t, f)


def assert_paper_indicators(settings, x, y, rate, t, f, method: str) -> list:
    """Every update of the paper detector run alone has an update of ``method`` at the
    same time carrying the same R_coe and R_dw; returns the method's updates."""
    alone = paper_alone(settings, x, y, rate, t, f)
    decided = get_method(method).stream(settings, x, y, rate).feed(t, f)
    at = {u.t: u for u in decided}
    assert len(alone) > 20 and all(u.t in at for u in alone)
    np.testing.assert_allclose([at[u.t].r_coe for u in alone], [u.r_coe for u in alone], rtol=1e-8, atol=1e-9)
    np.testing.assert_allclose([at[u.t].r_dw for u in alone], [u.r_dw for u in alone], rtol=1e-8, atol=1e-9)
    assert max(u.r_coe for u in alone) > 2.5  # the recording moves the indicators
    return decided


@pytest.mark.parametrize("method", SCORED)
@pytest.mark.parametrize("seed", [1, 2])
def test_a_faulty_recording_gives_every_method_the_papers_indicators(paper_profile, method, seed, hop_path):
    # NaN, negatives, repeated and backward times, a filled gap and a reset
    x, y = paper_profile.coordinates_mm
    t, f = faulty_recording(seed)
    assert_paper_indicators(paper_profile.detector, x, y, 100.0, t, f, method)


@pytest.mark.parametrize("rate", [100.0, 1000.0])
def test_cof_track_on_a_scene_carries_the_papers_indicators_held_between_its_hops(paper_profile, rate, hop_path):
    x, y = paper_profile.coordinates_mm
    scene = render("case2", rate, 0)
    cfg = replace(paper_profile.detector, method="cof-track")
    decided = assert_paper_indicators(cfg, x, y, rate, scene.t, scene.forces, "cof-track")
    alone = paper_alone(cfg, x, y, rate, scene.t, scene.forces)
    # cof-track decides every 10 ms, the paper every 100 ms: in between, the newest value
    times = np.array([u.t for u in alone])
    for u in decided:
        i = np.searchsorted(times, u.t, side="right") - 1
        want = (alone[i].r_coe, alone[i].r_dw) if i >= 0 else (0.0, 0.0)
        assert u.r_coe == pytest.approx(want[0], rel=1e-8, abs=1e-9) and u.r_dw == pytest.approx(want[1], rel=1e-8, abs=1e-9)
    # and its own scores are not the paper's: they say slip > 1 during the slide
    assert max(u.score_a for u in decided) > 1.0
    assert not np.allclose([u.score_a for u in decided], [u.r_coe for u in decided])


@pytest.mark.parametrize("geometry", [dict(hop_s=0.05, lag_s=0.1), dict(hop_s=0.2, lag_s=0.05),
                                      dict(hop_s=0.02, window_s=0.02), dict(wavelet="db4")])
def test_the_papers_geometry_is_followed(paper_profile, geometry, hop_path):
    # hops shorter and longer than the lag, a window shorter than the wavelet, a longer filter
    x, y = paper_profile.coordinates_mm
    t, f = faulty_recording(3)
    assert_paper_indicators(replace(paper_profile.detector, **geometry), x, y, 100.0, t, f, "cof-track")


def test_the_papers_scores_are_its_indicators(paper_profile):
    x, y = paper_profile.coordinates_mm
    t, f = faulty_recording(1)
    streamed = paper_alone(paper_profile.detector, x, y, 100.0, t, f)
    assert all(u.score_a == u.r_coe and u.score_b == u.r_dw for u in streamed)
    table = paper_batch(paper_profile.detector, x, y, 100.0, t, f)
    assert table.score_a is table.r_coe and table.score_b is table.r_dw  # one computation


def test_the_decision_never_reads_the_papers_indicators(paper_profile):
    # the scores and states with the indicators computed alongside equal those with
    # the indicators' input thrown away
    x, y = paper_profile.coordinates_mm
    scene = render("case2", 100.0, 0)
    a = get_method("cof-track").stream(paper_profile.detector, x, y, 100.0)
    b = get_method("cof-track").stream(paper_profile.detector, x, y, 100.0)
    b.paper.push = lambda *args: None
    ua, ub = a.feed(scene.t, scene.forces), b.feed(scene.t, scene.forces)
    assert [(u.state, u.score_a, u.score_b, u.valid) for u in ua] == [(u.state, u.score_a, u.score_b, u.valid) for u in ub]
    assert any(u.r_coe for u in ua) and not any(u.r_coe for u in ub)


def test_each_method_names_its_scores_and_has_a_code():
    codes = [m.code for m in METHODS.values()]
    assert 0 not in codes and len(set(codes)) == len(codes)
    for m in METHODS.values():
        assert method_of_code(m.code) is m
        columns = getattr(m.stream, "columns", None)
        if columns is not None:  # the scored methods: the detector's own column names
            assert tuple(s.name for s in m.scores) == tuple(columns)
        else:
            assert tuple(s.name for s in m.scores) == ("r_coe", "r_dw")
    assert method_of_code(0) is None


def test_the_hop_path_follows_the_hop_length(paper_profile, hop_path):
    x, y = paper_profile.coordinates_mm
    det = get_method("cof-track").stream(paper_profile.detector, x, y, 100.0)
    assert det.paper._arrays == (hop_path == "arrays")


def test_by_default_short_hops_take_scalars_and_long_ones_arrays(paper_profile):
    x, y = paper_profile.coordinates_mm
    at = {rate: get_method("cof-track").stream(paper_profile.detector, x, y, rate).paper._arrays for rate in (100.0, 1000.0)}
    assert at == {100.0: False, 1000.0: True}  # 10 and 100 frames a hop
