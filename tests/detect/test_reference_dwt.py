"""The fast window sums equal a from-scratch computation with np.corrcoef and pywt.dwt."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import pywt

from eskin_industrial.detect.indicators import segment_indicators
from eskin_industrial.detect.reference import reference_window_sums, valid_detail
from tests.helpers.scenes import grasp


def test_valid_detail_is_the_unpadded_part_of_every_pywt_mode():
    x = np.random.default_rng(0).normal(size=40)
    ref = valid_detail(x, "db2")
    assert len(ref) == (40 - 4) // 2 + 1
    for mode in ("symmetric", "periodic", "reflect", "smooth"):
        _, d = pywt.dwt(x, "db2", mode=mode)
        np.testing.assert_allclose(d[1:1 + len(ref)], ref, rtol=1e-12)
    # and it is the high-pass FIR filter at stride 2 ending on odd samples
    h = pywt.Wavelet("db2").dec_hi
    fir = np.convolve(x, h, mode="valid")  # ends at samples 3, 4, ...
    np.testing.assert_allclose(fir[::2], ref, rtol=1e-12)


@pytest.mark.parametrize("wavelet,hop", [("db2", 0.1), ("db4", 0.07), ("db1", 0.03), ("db3", 0.05)])
def test_window_sums_match_reference(paper_profile, wavelet, hop):
    cfg = replace(paper_profile.detector, wavelet=wavelet, hop_s=hop, window_s=4 * hop)
    x, y = paper_profile.coordinates_mm
    f = grasp(700, seed=5, noise=0.05)
    f[:60] = 0.0
    f[300:380] = np.roll(f[300:380], 2, axis=1)
    geo = cfg.geometry(100.0)
    mat = np.column_stack([np.ones(25), x, y])
    cols, _, _ = segment_indicators(f, np.zeros(len(f), np.int64), mat, cfg, geo)
    end, coe, dw = reference_window_sums(cfg, x, y, 100.0, f)
    np.testing.assert_array_equal(cols.end, end)
    np.testing.assert_allclose(cols.coe_sum, coe, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(cols.dw_sum, dw, rtol=1e-9, atol=1e-12)
    assert dw.max() > 0 and coe.max() > 0
