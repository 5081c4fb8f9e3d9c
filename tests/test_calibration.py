from __future__ import annotations

import numpy as np
import pytest

from eskin_industrial import Calibrator, FrameFlag


def test_paper_figures(paper_profile):
    cal = Calibrator.from_section(paper_profile.calibration, 25)
    raw = np.full(25, 14000.0)  # 1400 ohm in 0.1 ohm units
    raw[3] = 4950.0  # 495 ohm -> 5 N
    forces, flags = cal.to_newtons(raw)
    assert forces[3] == pytest.approx(5.0, abs=1e-9)
    assert forces[0] == 0.0
    assert forces[12] == pytest.approx((1400.0 - 1392.0) / -178.5)  # per-taxel override
    assert flags == 0


def test_vectorized_with_flags(paper_profile):
    cal = Calibrator.from_section(paper_profile.calibration, 25)
    raw = np.full((3, 25), 14000.0)
    raw[1, 0] = 100.0  # 10 ohm: below valid_min, a short
    raw[2, 1] = 1000.0  # 100 ohm -> 7.2 N ... then 60 ohm for saturation
    raw[2, 2] = 600.0  # 60 ohm -> 7.4 N
    raw[0, 4] = np.nan
    forces, flags = cal.to_newtons(raw)
    assert forces.shape == (3, 25)
    assert flags[0] == FrameFlag.INVALID and np.isnan(forces[0, 4])
    assert flags[1] == FrameFlag.INVALID and np.isnan(forces[1, 0])
    assert flags[2] == 0


def test_saturation(hand_profile):
    cal = Calibrator.from_section(hand_profile.calibration, 20)
    raw = np.full(20, 300.0)
    raw[0] = 300 + 250 * 12  # 12 N > full scale 10 N
    forces, flags = cal.to_newtons(raw)
    assert forces[0] == 10.0 and flags == FrameFlag.SATURATED


def test_tare_zeroes_an_unloaded_period(hand_profile):
    cal = Calibrator.from_section(hand_profile.calibration, 20)
    rng = np.random.default_rng(0)
    offset = rng.normal(0, 20, 20)
    unloaded = 300.0 + offset + rng.normal(0, 1, (200, 20))
    unloaded[5, 3] = 0.0  # an invalid reading is ignored by the tare
    tared = cal.tared(unloaded)
    before, _ = cal.to_newtons(300.0 + offset)
    after, _ = tared.to_newtons(300.0 + offset)
    assert np.abs(before).max() > 0.02
    assert np.abs(after).max() < 0.01
    with pytest.raises(ValueError, match="20 taxels"):
        cal.tared(np.zeros((5, 19)))
