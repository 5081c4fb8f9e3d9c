"""The paper's indicators, one frame at a time, with explicit bounded state.

Cost per frame does not depend on the window length: three dot products of n
taxels, a K-tap FIR step (the one-level DWT detail is the high-pass filter at stride
2, so each coefficient is known as soon as its last sample arrives), and running
block sums; a window sum is B block sums added when a hop completes.  Memory: ``lag``
frames, ``W`` energies, ``B`` block sums.

Frame handling (duplicates, NaN, negative values, gaps) comes from
:class:`~eskin_industrial.detect.hygiene.FrameHygiene`; a test proves the stream
agrees with the batch code.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable, Sequence

import numpy as np

from ..frames import FrameFlag
from .hygiene import FrameHygiene
from .indicators import _EPS, _ZERO_VAR, odd_offsets
from .settings import DetectorSettings, Geometry
from .state import ContactRule
from .vforce import ForceVariation

_WARMUP = int(FrameFlag.WARMUP)
_SHORT = int(FrameFlag.SHORT_WINDOW)
_FILLED = int(FrameFlag.FILLED)

#: What :meth:`IndicatorStream.push` returns for each completed hop.
#: (end_time, r_coe, r_dw, valid, flags, f_sum, xc, yc, contact, vf): vf is the hop's
#: largest varying-force score (``vforce.py``; 0 when the profile takes the paper's own)
RawUpdate = tuple[float, float, float, bool, int, float, float, float, bool, float]


class IndicatorStream(FrameHygiene):
    """Streaming R_coe / R_dw for one sensor array at a fixed sample rate.

    ``push(t, forces, flags)`` (from :class:`FrameHygiene`) returns the
    :data:`RawUpdate` tuples the frame completes."""

    def __init__(self, settings: DetectorSettings, x_mm: np.ndarray, y_mm: np.ndarray, rate_hz: float) -> None:
        self.cfg = settings
        self.geo: Geometry = settings.geometry(rate_hz)
        super().__init__(int(len(x_mm)), rate_hz, self.geo.max_fill)
        self._mat = np.column_stack([np.ones(self.n), x_mm, y_mm]).astype(np.float64)
        self._centre = (float(np.mean(x_mm)), float(np.mean(y_mm)))
        self._h = [float(v) for v in self.geo.dec_hi]
        self._c_floor = settings.coe_floor * self.geo.window
        self._e_floor = settings.dw_floor_mm2 * odd_offsets(self.geo.window, len(self._h))
        self._symmetric = settings.ratio_mode == "symmetric"
        self._rule = ContactRule.from_settings(settings, rate_hz)
        self._touching = self._rule.touching
        own = settings.varying_force.evidence == "method"
        self._vf = None if own else ForceVariation(settings.varying_force, rate_hz)
        self._reset(0)

    def _reset(self, flags: int) -> None:
        geo = self.geo
        self._k = 0
        self._contact = False  # the previous frame's, for the contact rule's hysteresis
        self._rule.reset()  # (a restart learns the baseline anew, as the batch form's segments do)
        self._ring_f = np.zeros((geo.lag, self.n))
        self._ring_s = [0.0] * geo.lag
        self._ring_ss = [0.0] * geo.lag
        self._ring_c = [False] * geo.lag
        self._xs: list[float] = []
        self._ys: list[float] = []
        self._cof = self._centre
        self._energy = [0.0] * max(geo.window, 1)
        self._cur_c = 0.0
        self._cur_e = [0.0, 0.0]
        self._cur_flags = flags
        self._carry_flags = 0
        self._blocks: deque[tuple[float, float, float]] = deque(maxlen=geo.blocks)
        self._prev_sums: tuple[float, float] | None = None
        self._hop_vf = 0.0
        if self._vf is not None:
            self._vf.reset()

    # -- the per-frame core --------------------------------------------------------
    def _step(self, t: float, f: np.ndarray, flags: int, out: list[RawUpdate]) -> None:
        geo = self.geo
        k = self._k
        s, sx, sy = (f @ self._mat).tolist()
        ss = float(f @ f)
        contact = self._contact = self._touching(s, self._contact)
        if contact:
            self._cof = (sx / s, sy / s)
        xc, yc = self._cof
        if self._vf is not None:
            vf = self._vf.push(s, contact, bool(flags & _FILLED))
            if vf > self._hop_vf:
                self._hop_vf = vf

        lag = geo.lag
        slot = k % lag
        d = 0.0
        if k >= lag:
            d = self._decorrelation(s, ss, contact, float(f @ self._ring_f[slot]), slot)
        self._ring_f[slot] = f
        self._ring_s[slot] = s
        self._ring_ss[slot] = ss
        self._ring_c[slot] = contact

        h = self._h
        flen = len(h)
        xs, ys = self._xs, self._ys
        xs.append(xc)
        ys.append(yc)
        energy = 0.0
        if len(xs) > flen:
            del xs[0], ys[0]
        if len(xs) == flen:
            # ending at k: sum_j h[j] x[k - j]
            dx = dy = 0.0
            for j in range(flen):
                dx += h[j] * xs[flen - 1 - j]
                dy += h[j] * ys[flen - 1 - j]
            energy = dx * dx + dy * dy
        self._energy[k % len(self._energy)] = energy

        self._cur_c += d
        self._cur_e[k & 1] += energy
        self._cur_flags |= flags
        self._k = k = k + 1
        if k % geo.hop:
            return
        self._blocks.append((self._cur_c, self._cur_e[0], self._cur_e[1]))
        block_flags = self._cur_flags
        hop_vf, self._hop_vf = self._hop_vf, 0.0
        self._cur_c = 0.0
        self._cur_e = [0.0, 0.0]
        self._cur_flags = 0
        if len(self._blocks) < geo.blocks:
            self._carry_flags |= block_flags  # reported with the first update (RESET)
            return
        block_flags |= self._carry_flags
        self._carry_flags = 0
        out.append(self._update(t, block_flags, s, xc, yc, contact, hop_vf))

    def _decorrelation(self, s: float, ss: float, contact: bool, sab: float, slot: int) -> float:
        c_b = self._ring_c[slot]
        if not (contact and c_b):
            return 1.0 if (contact or c_b) else 0.0
        n = self.n
        s_b, ss_b = self._ring_s[slot], self._ring_ss[slot]
        var_a = n * ss - s * s
        var_b = n * ss_b - s_b * s_b
        flat_a = var_a <= _ZERO_VAR * s * s
        flat_b = var_b <= _ZERO_VAR * s_b * s_b
        if flat_a or flat_b:
            return 0.0 if (flat_a and flat_b) else 1.0
        d = 1.0 - (n * sab - s * s_b) / math.sqrt(var_a * var_b)
        return 0.0 if d < 0.0 else 2.0 if d > 2.0 else d

    def _update(self, t: float, block_flags: int, s: float, xc: float, yc: float, contact: bool,
                vf: float) -> RawUpdate:
        geo = self.geo
        start = self._k - geo.window
        short = geo.window < len(self._h)
        c_win, dw = window_sums(self._blocks, self._energy, self._k, geo.window, len(self._h), self._c_floor,
                                self._e_floor)
        r_coe = r_dw = 0.0
        if self._prev_sums is not None:
            r_coe = r_of(c_win, self._prev_sums[0], self._symmetric)
            r_dw = 0.0 if short else r_of(dw, self._prev_sums[1], self._symmetric)
        self._prev_sums = (c_win, dw)
        warm = start - geo.hop < geo.lag
        flags = block_flags | (_WARMUP if warm else 0) | (_SHORT if short else 0)
        return (t, r_coe, r_dw, not warm and not short, flags, s, xc, yc, contact, vf)


def window_sums(blocks: Iterable[tuple[float, float, float]], energy: Sequence[float] | np.ndarray, k: int,
                window: int, flen: int, c_floor: float, e_floor: float) -> tuple[float, float]:
    """A window's decorrelation sum and wavelet detail energy, floors added, from its
    hops' sums ``(decorrelation, even frames' energy, odd frames' energy)`` and the ring
    of per-frame energies (``energy[i % len]``), for the window of ``window`` frames
    ending before frame ``k``.  The detail coefficients are those of one parity, and the first
    ``flen - 1`` frames' of them need padding: they come off.  Every hop of the paper's
    streaming indicators ends here (:class:`IndicatorStream` and
    :class:`~.alongside.PaperAlongside`), so their values agree to the last bit."""
    c_win = e0 = e1 = 0.0
    for c, a, b in blocks:
        c_win += c
        e0 += a
        e1 += b
    start = k - window
    p = (start + 1) & 1
    dw = e1 if p else e0
    if window < flen:  # a window shorter than the filter: no coefficient
        dw = 0.0
    else:
        partial = 0.0
        for o in range(flen - 1):
            e = start + o
            partial += float(energy[e % len(energy)]) if (e & 1) == p else 0.0
        dw = max(dw - partial, 0.0)
    return c_win + c_floor, dw + e_floor


def r_of(now: float, before: float, symmetric: bool) -> float:
    """One indicator from a window's sum and the previous window's: the ratio's rise
    (``rise``), or its departure from 1 either way (``symmetric``)."""
    ratio = (now + _EPS) / (before + _EPS)
    if symmetric:
        return (ratio if ratio >= 1.0 else 1.0 / ratio) - 1.0
    return ratio - 1.0 if ratio > 1.0 else 0.0
