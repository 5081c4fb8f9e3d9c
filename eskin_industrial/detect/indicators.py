"""The paper's two indicators over a whole (regularized) recording, vectorized.

Notation as in ``docs/method.md``: frame k has forces F_k (n taxels), total S_k,
centre of force (X_k, Y_k).  With lag L samples, window W = B blocks of H samples
(hop H), and the wavelet's high-pass decomposition filter h of length K:

    d_k    = 1 - corr(F_k, F_{k-L})                  decorrelation (Pearson, F_dis-invariant)
    D_k    = (h * X)_k^2 + (h * Y)_k^2               one-level detail energy ending at k
    C(s)   = sum_{k=s}^{s+W-1} d_k                    Sum_coe of the window starting at s
    E(s)   = sum_{o odd, K-1 <= o <= W-1} D_{s+o}      Sum_dw: only coefficients needing no padding
    ratio  = (C(s) + c0 W) / (C(s-H) + c0 W)          c0, e0: noise floors
    R      = max(ratio, 1/ratio) - 1                  (symmetric; "rise": max(ratio - 1, 0))

Window sums are formed from per-block sums added oldest to newest, the same order the
streaming code uses, so the two agree to rounding of the per-frame terms.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..frames import FrameFlag
from .regularize import forward_fill_rows
from .settings import DetectorSettings, Geometry
from .state import ContactRule

_EPS = 1e-12  # keeps 0/0 ratios at 1 when a floor is set to 0
_ZERO_VAR = 1e-12  # relative variance below which a distribution counts as uniform
_WARMUP = int(FrameFlag.WARMUP)
_SHORT = int(FrameFlag.SHORT_WINDOW)


@dataclass(frozen=True)
class IndicatorColumns:
    """Per-update indicator values of one segment, before the state machine."""

    end: np.ndarray  #: index of the newest frame of each update's window
    r_coe: np.ndarray
    r_dw: np.ndarray
    valid: np.ndarray
    flags: np.ndarray
    coe_sum: np.ndarray  #: Sum_coe of each window, before the floor
    dw_sum: np.ndarray  #: Sum_dw of each window, before the floor
    contact: np.ndarray  #: the newest frame of each update in contact (:class:`ContactRule`)


def decorrelation_pair(
    n: int, s_a: np.ndarray, ss_a: np.ndarray, s_b: np.ndarray, ss_b: np.ndarray, sab: np.ndarray,
    contact_a: np.ndarray, contact_b: np.ndarray,
) -> np.ndarray:
    """1 - Pearson correlation of two distributions from their sums, with the edge rules:
    both out of contact -> 0; one only -> 1; both uniform -> 0; one uniform -> 1."""
    var_a = n * ss_a - s_a * s_a
    var_b = n * ss_b - s_b * s_b
    flat_a = var_a <= _ZERO_VAR * s_a * s_a
    flat_b = var_b <= _ZERO_VAR * s_b * s_b
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = (n * sab - s_a * s_b) / np.sqrt(var_a * var_b)
    d = np.clip(1.0 - corr, 0.0, 2.0)
    d = np.where(flat_a | flat_b, np.where(flat_a & flat_b, 0.0, 1.0), d)
    return np.where(contact_a & contact_b, d, np.where(contact_a | contact_b, 1.0, 0.0))


def ratio_to_r(now: np.ndarray, before: np.ndarray, mode: str) -> np.ndarray:
    ratio = (now + _EPS) / (before + _EPS)
    if mode == "rise":
        return np.maximum(ratio - 1.0, 0.0)
    return np.maximum(ratio, 1.0 / ratio) - 1.0


def odd_offsets(window: int, filter_len: int) -> int:
    """Number of detail coefficients of a window that need no padding."""
    if window < filter_len:
        return 0
    first = filter_len - 1 if (filter_len - 1) % 2 == 1 else filter_len
    return 0 if first > window - 1 else (window - 1 - first) // 2 + 1


def segment_indicators(
    forces: np.ndarray, flags: np.ndarray, mat: np.ndarray, cfg: DetectorSettings, geo: Geometry
) -> tuple[IndicatorColumns, np.ndarray, np.ndarray]:
    """Indicators of one segment; also returns per-frame (S, Sx, Sy) and the held CoF.

    ``mat`` is the (n, 3) matrix of columns [1, x_mm, y_mm].
    """
    k_total, n = forces.shape
    sums = forces @ mat  # S, S*X, S*Y
    s = sums[:, 0]
    ss = np.einsum("ij,ij->i", forces, forces)
    contact = ContactRule.from_settings(cfg, geo.rate_hz).mask(s)
    with np.errstate(invalid="ignore", divide="ignore"):
        cof = sums[:, 1:] / s[:, None]
    centre = mat[:, 1:].mean(axis=0)
    cof = forward_fill_rows(cof, np.repeat(contact[:, None], 2, axis=1), centre)

    lag, hop, blocks, window = geo.lag, geo.hop, geo.blocks, geo.window
    d = np.zeros(k_total)
    if k_total > lag:
        sab = np.einsum("ij,ij->i", forces[lag:], forces[:-lag])
        d[lag:] = decorrelation_pair(n, s[lag:], ss[lag:], s[:-lag], ss[:-lag], sab, contact[lag:], contact[:-lag])

    h = geo.dec_hi
    flen = h.size
    energy = np.zeros(k_total)
    if k_total >= flen:
        # valid convolution: out[m] = sum_j h[j] x[m + flen - 1 - j], i.e. ending at m + flen - 1
        dx = np.convolve(cof[:, 0], h, mode="valid")
        dy = np.convolve(cof[:, 1], h, mode="valid")
        energy[flen - 1:] = dx * dx + dy * dy

    n_blocks = k_total // hop
    empty = IndicatorColumns(np.zeros(0, np.int64), np.zeros(0), np.zeros(0), np.zeros(0, bool), np.zeros(0, np.int64),
                             np.zeros(0), np.zeros(0), np.zeros(0, bool))
    if n_blocks < blocks:
        return empty, sums, cof
    used = n_blocks * hop
    parity = (np.arange(used) & 1).astype(bool)

    def block_sums(values: np.ndarray) -> np.ndarray:
        # cumsum adds left to right, as the stream does
        return np.cumsum(values[:used].reshape(n_blocks, hop), axis=1)[:, -1]

    c_blk = block_sums(d)
    e_blk = (block_sums(np.where(parity, 0.0, energy[:used])), block_sums(np.where(parity, energy[:used], 0.0)))
    f_blk = np.bitwise_or.reduce(flags[:used].reshape(n_blocks, hop), axis=1)

    n_up = n_blocks - blocks + 1
    c_win = np.zeros(n_up)
    e_win = (np.zeros(n_up), np.zeros(n_up))
    for j in range(blocks):
        c_win += c_blk[j:j + n_up]
        e_win[0][:] += e_blk[0][j:j + n_up]
        e_win[1][:] += e_blk[1][j:j + n_up]
    start = np.arange(n_up) * hop
    p = (start + 1) & 1  # parity of the coefficients that belong to each window
    dw = np.where(p == 1, e_win[1], e_win[0])
    if window >= flen:
        # drop the coefficients that reach back before the window (they need padding)
        partial = np.zeros(n_up)
        for o in range(flen - 1):
            e_idx = start + o
            partial += np.where((e_idx & 1) == p, energy[e_idx], 0.0)
        dw = np.maximum(dw - partial, 0.0)
    else:
        dw = np.zeros(n_up)

    c_floor = cfg.coe_floor * window
    e_floor = cfg.dw_floor_mm2 * odd_offsets(window, flen)
    r_coe = np.zeros(n_up)
    r_dw = np.zeros(n_up)
    r_coe[1:] = ratio_to_r(c_win[1:] + c_floor, c_win[:-1] + c_floor, cfg.ratio_mode)
    r_dw[1:] = ratio_to_r(dw[1:] + e_floor, dw[:-1] + e_floor, cfg.ratio_mode)
    warm = start - hop < lag  # the previous window must have full lag history too
    short = window < flen
    valid = ~warm & (not short)
    up_flags = f_blk[blocks - 1:] | np.where(warm, _WARMUP, 0) | (_SHORT if short else 0)
    # the first update also reports what happened while the first window filled (RESET)
    up_flags[0] |= np.bitwise_or.reduce(f_blk[:blocks])
    r_dw = np.where(short, 0.0, r_dw)
    end = start + window - 1
    return IndicatorColumns(end, r_coe, r_dw, valid, up_flags.astype(np.int64), c_win, dw, contact[end]), sums, cof
