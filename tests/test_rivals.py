"""The vibration rival (hf-energy): per-taxel and total-force energy, on a still grip
and under a vibration the taxels share."""

from __future__ import annotations

import numpy as np

from eskin_industrial.detect.scored import HfEnergy
from eskin_industrial.detect.settings import DetectorSettings

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
                before = max(before, u.r_coe)
            elif u.t >= 5.0:
                after = max(after, u.r_coe)
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
