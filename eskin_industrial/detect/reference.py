"""A naive reference of the paper's indicators: every window recomputed from scratch,
with ``np.corrcoef`` and ``pywt.dwt``, the way a first reading of the paper would.

It exists to check the fast code (tests) and to measure it (benchmarks); nothing in
the product runs it.  Input must already be regular (see ``regularize``): one segment,
finite, non-negative forces.
"""

from __future__ import annotations

import numpy as np
import pywt

from .settings import DetectorSettings
from .state import ContactRule


def reference_window_sums(
    settings: DetectorSettings, x_mm: np.ndarray, y_mm: np.ndarray, rate_hz: float, forces: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(end index, Sum_coe, Sum_dw) for every update of one regular segment."""
    geo = settings.geometry(rate_hz)
    k_total = forces.shape[0]
    ends, coe, dw = [], [], []
    rule = ContactRule.from_settings(settings, rate_hz)
    # contact per frame (the rule remembers the frame before), and the centre of force,
    # held at its last in-contact value (array centre before any)
    contact = np.zeros(k_total, bool)
    cof = np.empty((k_total, 2))
    held = (float(np.mean(x_mm)), float(np.mean(y_mm)))
    was = False
    for k in range(k_total):
        s = forces[k].sum()
        contact[k] = was = rule.touching(s, was)
        if was:
            held = (float(forces[k] @ x_mm / s), float(forces[k] @ y_mm / s))
        cof[k] = held
    for end in range(geo.window - 1, k_total, geo.hop):
        start = end - geo.window + 1
        c = 0.0
        for k in range(start, end + 1):
            if k < geo.lag:
                continue
            c += _decorrelation(forces[k], forces[k - geo.lag], contact[k], contact[k - geo.lag])
        xs, ys = cof[start:end + 1, 0], cof[start:end + 1, 1]
        e = 0.0
        if geo.window >= geo.filter_len:
            for seq in (xs, ys):
                e += float(np.sum(valid_detail(seq, settings.wavelet) ** 2))
        ends.append(end)
        coe.append(c)
        dw.append(e)
    return np.asarray(ends), np.asarray(coe), np.asarray(dw)


def valid_detail(x: np.ndarray, wavelet: str) -> np.ndarray:
    """One-level detail coefficients of ``x`` that need no padding.

    ``pywt.dwt(x, w, mode='zero')`` gives ``cD[i] = sum_j h[j] x[2i+1-j]``; the
    coefficients whose taps all fall inside ``x`` are those with ``K-1 <= 2i+1 <= N-1``
    (K the filter length).  Any padding mode gives the same values for these.
    """
    flen = pywt.Wavelet(wavelet).dec_len
    _, detail = pywt.dwt(x, wavelet, mode="zero")
    first = (flen - 1) // 2  # smallest i with 2i+1 >= K-1 (K even)
    last = (len(x) - 2) // 2
    return detail[first:last + 1]


def _decorrelation(a: np.ndarray, b: np.ndarray, ca: bool, cb: bool) -> float:
    if not (ca and cb):
        return 1.0 if (ca or cb) else 0.0
    fa, fb = a / a.sum(), b / b.sum()  # F_dis, as the paper writes it
    flat_a, flat_b = np.ptp(fa) == 0, np.ptp(fb) == 0
    if flat_a or flat_b:
        return 0.0 if (flat_a and flat_b) else 1.0
    return float(np.clip(1.0 - np.corrcoef(fa, fb)[0, 1], 0.0, 2.0))
