"""The vibration rival (hf-energy): per-taxel and total-force energy, on a still grip
and under a vibration the taxels share."""

from __future__ import annotations

from functools import partial

import numpy as np
import pytest

from eskin_industrial import parse_profile
from eskin_industrial.detect import GraspState, get_method
from eskin_industrial.detect.scored import ForceRate, HfEnergy
from eskin_industrial.detect.settings import DetectorSettings
from eskin_industrial.evaluation.suite import run_one
from eskin_industrial.scenes import render
from tests.helpers.paths import PROFILES

X = np.tile(np.arange(5) * 5.0, 5)
Y = np.repeat(np.arange(5) * 5.0, 5)


def peak_ratio(total: bool, shake: float, seed: int = 0) -> tuple[float, float]:
    """Largest score in the 2 s before and the 1 s after a shared ripple starts."""
    rng = np.random.default_rng(seed)
    t = np.arange(600) / 100.0
    factor = 1.0 + np.where(t >= 5.0, shake * np.sign(np.sin(2 * np.pi * 23 * t)), 0.0)
    f = 0.3 * factor[:, None] + rng.normal(0, 0.01, (600, 25))
    det = HfEnergy(DetectorSettings(), X, Y, 100.0, threshold=1e9, total=total)
    before, after = 0.0, 0.0
    for k in range(600):
        for u in det.push(float(t[k]), f[k]):
            if 3.0 <= u.t < 5.0:
                before = max(before, u.score_a)
            elif u.t >= 5.0:
                after = max(after, u.score_a)
    return before, after


def test_a_shared_vibration_stands_out_in_the_total_not_in_the_taxels() -> None:
    """A 4 % ripple shared by 25 taxels of 0.3 N (each with 0.01 N of noise) barely
    moves the per-taxel energy and stands out in the total's, where it adds up
    coherently while the noise adds up only in power."""
    for seed in range(3):
        taxel_before, taxel_after = peak_ratio(False, 0.04, seed)
        total_before, total_after = peak_ratio(True, 0.04, seed)
        assert taxel_after < 2.5 * taxel_before
        assert total_after > 3.0 * total_before
        assert total_after / total_before > 2.0 * taxel_after / taxel_before


def slips(method: str, settings: DetectorSettings, scene: str = "case2") -> int:
    """Updates reading slip on a tuning seed of a scene with one slide."""
    table, _ = run_one(get_method(method).stream, settings, render(scene, 100.0, 0))
    return int((table.state == GraspState.SLIP).sum())


def profile_with(section: str):
    return parse_profile((PROFILES / "paper-5x5.toml").read_text() + "\n" + section, "paper-5x5+.toml")


@pytest.mark.parametrize("method,section", [
    ("force-rate", "[detector.force_rate]\nthreshold_per_s = 1000.0\n"),
    ("cof-velocity", "[detector.cof_velocity]\nthreshold_mm_s = 1000.0\n"),
    ("cof-step", "[detector.cof_step]\nthreshold = 50.0\n"),
])
def test_a_profile_threshold_silences_a_rival_where_it_fires(method, section):
    assert slips(method, DetectorSettings()) > 0
    assert slips(method, profile_with(section).detector) == 0


def test_a_profile_threshold_wakes_the_vibration_rival():
    # hf-energy at its default threshold (6x its baseline) sees nothing of this slide;
    # at 1.2x its baseline it fires
    assert slips("hf-energy", DetectorSettings()) == 0
    prof = profile_with("[detector.hf_energy]\nthreshold = 1.2\nsmooth_s = 0.02\n")
    assert prof.detector.hf_energy.threshold == 1.2 and prof.detector.hf_energy.smooth_s == 0.02
    assert slips("hf-energy", prof.detector) > 0


def test_keyword_overrides_equal_the_profile_settings():
    # the evaluation's sweeps override single fields; a profile section says the same
    via_profile = profile_with("[detector.force_rate]\nthreshold_per_s = 0.5\nlag_s = 0.05\n").detector
    a = run_one(get_method("force-rate").stream, via_profile, render("case1", 100.0, 0))[0]
    b = run_one(partial(ForceRate, threshold_per_s=0.5, lag_s=0.05), DetectorSettings(), render("case1", 100.0, 0))[0]
    np.testing.assert_array_equal(a.state, b.state)
    np.testing.assert_array_equal(a.score_a, b.score_a)
