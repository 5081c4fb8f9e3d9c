"""The paper's two indicators beside another method's decision: what R_coe and R_dw
carry in every update, register and log line whatever method decides.

:class:`PaperAlongside` is fed the frames the deciding method has already made fit
(its :class:`~eskin_industrial.detect.hygiene.FrameHygiene`: the same drops, fills and
resets as the paper detector's own), with the total force, centre of force and
contact the decider computed for them (the same rule, the same floats).  Per frame it
only keeps them: two list appends.  The work comes once
per paper hop, over the hop's frames at once: the squared norms and lagged products of
the frames, the decorrelations, the wavelet detail of the centre of force, and the
window sums of :mod:`.stream`, in the same order.  So the values agree with
:class:`~eskin_industrial.detect.paper.PaperDetector` run alone on the same frames (to
the rounding of a dot product: tests/detect/test_alongside.py), at the paper's own hop.
"""

from __future__ import annotations

import math
from collections import deque
from itertools import chain
from operator import mul

import numpy as np

from .indicators import _ZERO_VAR, decorrelation_pair, odd_offsets
from .settings import DetectorSettings
from .stream import r_of, window_sums


class PaperAlongside:
    """R_coe and R_dw with the paper's settings; :attr:`r_coe` and :attr:`r_dw` hold
    the newest hop's values (0 until the second window, as the paper detector's).

    A hop's work is a few numpy calls over its frames (the squared norms and lagged
    products), then either more numpy calls (:meth:`_hop_arrays`: a fixed cost that
    pays off over many frames, 100 at 1 kHz) or the stream's scalar arithmetic frame
    by frame (:meth:`_hop_scalars`: cheaper over the 10 frames of a hop at 100 Hz);
    :data:`ARRAYS_FROM` frames a hop decides which."""

    #: Hops of at least this many frames take the numpy path.
    ARRAYS_FROM = 25

    def __init__(self, settings: DetectorSettings, n: int, rate_hz: float) -> None:
        geo = settings.geometry(rate_hz)
        self.n = n
        self.hop, self.lag, self.blocks, self.window = geo.hop, geo.lag, geo.blocks, geo.window
        self._h = [float(v) for v in geo.dec_hi]
        self._flen = len(self._h)
        self._c_floor = settings.coe_floor * geo.window
        self._e_floor = settings.dw_floor_mm2 * odd_offsets(geo.window, self._flen)
        self._symmetric = settings.ratio_mode == "symmetric"
        self._arrays = self.hop >= self.ARRAYS_FROM
        self._hop = self._hop_arrays if self._arrays else self._hop_scalars
        self.reset()

    def reset(self) -> None:
        """Start over (the decider's reset: start, long gap)."""
        lag, hop = self.lag, self.hop
        self.r_coe = self.r_dw = 0.0
        self._k = 0  #: frames since the reset, to the current hop's first
        # the current hop's (frame, total, contact, centre of force): the frames are the
        # hygiene's own, which it keeps unchanged too (to fill a gap)
        self._rows: list[tuple[np.ndarray, float, bool, tuple[float, float]]] = []
        # the lag frames before the hop, their squared norms, totals and contact (as
        # arrays for the numpy path, lists for the scalar one)
        self._lag_f = np.zeros((lag, self.n))
        self._lag_ss = np.zeros(lag)
        self._lag_s = np.zeros(lag)
        self._lag_c = np.zeros(lag, bool)
        self._prev: tuple[list[float], list[float], list[bool]] = ([0.0] * lag, [0.0] * lag, [False] * lag)
        # the last flen - 1 centres before the hop (fewer just after a reset), (m, 2)
        self._cof_tail = np.zeros((0, 2))
        # the last flen centres as complex numbers x + iy: one filter pass for both axes
        # (a real tap times x + iy is (h x) + i (h y) exactly, and complex sums add each
        # part on its own)
        self._zs: deque[complex] = deque(maxlen=self._flen)
        # each frame's detail energy, a ring of the window (a list: the window's sums
        # read its first frames one by one, and a list's floats are read cheaply)
        self._energy = [0.0] * max(self.window, 1)
        self._blocks: deque[tuple[float, float, float]] = deque(maxlen=self.blocks)
        self._prev_sums: tuple[float, float] | None = None
        # which of a hop's frames are even (row 1) and odd (row 2), by the parity of its
        # first frame; row 0 takes the decorrelations
        ks = np.arange(hop)
        self._parity = tuple(np.array([np.ones(hop, bool), (ks + p) & 1 == 0, (ks + p) & 1 == 1]) for p in (0, 1))

    def push(self, f: np.ndarray, s: float, contact: bool, cof: tuple[float, float]) -> None:
        """One clean frame (the hot path: two appends; the hop's work at its last frame)."""
        rows = self._rows
        rows.append((f, s, contact, cof))
        if len(rows) == self.hop:
            self._hop()

    def _hop_scalars(self) -> None:
        """The hop as :class:`~.stream.IndicatorStream` steps its frames, in Python
        floats, from the hop's squared norms and lagged products (two numpy calls)."""
        lag, hop = self.lag, self.hop
        n = float(self.n)  # (a float times a float is the interpreter's fast path; the same product)
        zero_var, sqrt = _ZERO_VAR, math.sqrt
        k0 = self._k
        frames, s_t, c_t, cof_t = zip(*self._rows)
        cur = np.array(frames)
        if hop == lag:
            f_b = self._lag_f
            self._lag_f = cur
        else:
            f_all = np.concatenate((self._lag_f, cur))
            f_b, self._lag_f = f_all[:hop], f_all[hop:]
        ss_t = np.einsum("ij,ij->i", cur, cur).tolist()
        sab_t = np.einsum("ij,ij->i", cur, f_b).tolist()
        ps, pss, pc = self._prev
        ps, pss, pc = ps + list(s_t), pss + ss_t, pc + list(c_t)
        h, flen = self._h, self._flen
        zs = self._zs
        energies: list[float] = []
        c_blk = e0 = e1 = 0.0
        full = len(zs) == flen  # (flen centres since the reset: from then on, every frame)
        # each frame with its lagged one's total, squared norm and contact (pss[lag + i]
        # is its own squared norm), in one pass
        k = k0
        for s, contact, (xc, yc), ss, s_b, ss_b, c_b, sab in zip(
                s_t, c_t, cof_t, pss[lag:], ps, pss, pc, sab_t):
            d = 0.0
            if k >= lag:  # (as IndicatorStream._decorrelation)
                if not (contact and c_b):
                    d = 1.0 if (contact or c_b) else 0.0
                else:
                    var_a = n * ss - s * s
                    var_b = n * ss_b - s_b * s_b
                    flat_a = var_a <= zero_var * s * s
                    flat_b = var_b <= zero_var * s_b * s_b
                    if flat_a or flat_b:
                        d = 0.0 if (flat_a and flat_b) else 1.0
                    else:
                        d = 1.0 - (n * sab - s * s_b) / sqrt(var_a * var_b)
                        d = 0.0 if d < 0.0 else 2.0 if d > 2.0 else d
            zs.append(complex(xc, yc))
            energy = 0.0
            if full or len(zs) == flen:
                full = True
                # sum_j h[j] x[k - j], added from j = 0 as the stream adds it
                dz = sum(map(mul, h, reversed(zs)))
                dx, dy = dz.real, dz.imag
                energy = dx * dx + dy * dy
            energies.append(energy)
            c_blk += d
            if k & 1:
                e1 += energy
            else:
                e0 += energy
            k += 1
        at = (k0 // hop) % self.blocks * hop
        self._energy[at: at + hop] = energies
        self._prev = (ps[hop:], pss[hop:], pc[hop:])
        self._rows = []
        self._k = k0 + hop
        self._blocks.append((c_blk, e0, e1))
        if len(self._blocks) == self.blocks:
            self._update()

    def _hop_arrays(self) -> None:
        lag, hop = self.lag, self.hop
        k0 = self._k
        frames, s_t, c_t, cof_t = zip(*self._rows)
        cur = np.array(frames)
        s = np.array(s_t)
        c = np.array(c_t, bool)
        xy_hop = np.fromiter(chain.from_iterable(cof_t), float, 2 * hop).reshape(hop, 2)
        ss = np.einsum("ij,ij->i", cur, cur)
        if hop == lag:  # (the paper's 100 ms and 100 ms)
            f_b, ss_b, s_b, c_b = self._lag_f, self._lag_ss, self._lag_s, self._lag_c
            self._lag_f, self._lag_ss, self._lag_s, self._lag_c = cur, ss, s, c
        else:
            f_all = np.concatenate((self._lag_f, cur))
            ss_all = np.concatenate((self._lag_ss, ss))
            s_all = np.concatenate((self._lag_s, s))
            c_all = np.concatenate((self._lag_c, c))
            f_b, ss_b, s_b, c_b = f_all[:hop], ss_all[:hop], s_all[:hop], c_all[:hop]
            self._lag_f, self._lag_ss, self._lag_s, self._lag_c = f_all[hop:], ss_all[hop:], s_all[hop:], c_all[hop:]
        sab = np.einsum("ij,ij->i", cur, f_b)
        d = _decorrelation(self.n, s, ss, s_b, ss_b, sab, c, c_b)
        if k0 < lag:
            d[: lag - k0] = 0.0  # no frame a lag before yet
        # the one-level detail energy of the CoF ending at each frame, from the frame
        # with flen centres since the reset on; the taps added in the stream's order
        h, flen = self._h, self._flen
        xy = np.concatenate((self._cof_tail, xy_hop))
        end = len(xy)
        energy = np.zeros(hop)
        j0 = max(0, flen - 1 - k0)
        if j0 < hop:
            lo = end - hop + j0
            dxy = h[0] * xy[lo:]
            for j in range(1, flen):
                dxy += h[j] * xy[lo - j: end - j]
            dxy *= dxy
            energy[j0:] = dxy[:, 0] + dxy[:, 1]
        # the ring holds a window of whole hops: this hop's slot is one slice
        at = (k0 // hop) % self.blocks * hop
        self._energy[at: at + hop] = energy.tolist()
        self._cof_tail = xy[max(0, end - (flen - 1)):]
        # cumulative sums add left to right, as the stream's running sums do:
        # the decorrelations, the even frames' energies and the odd ones'
        sums = np.cumsum(np.where(self._parity[k0 & 1], (d, energy, energy), 0.0), axis=1)[:, -1].tolist()
        self._rows = []
        self._k = k0 + hop
        self._blocks.append((sums[0], sums[1], sums[2]))
        if len(self._blocks) == self.blocks:
            self._update()

    def _update(self) -> None:
        """R from the window sums, as :class:`~.stream.IndicatorStream` forms them."""
        short = self.window < self._flen
        c_win, dw = window_sums(self._blocks, self._energy, self._k, self.window, self._flen, self._c_floor,
                                self._e_floor)
        if self._prev_sums is not None:
            self.r_coe = r_of(c_win, self._prev_sums[0], self._symmetric)
            self.r_dw = 0.0 if short else r_of(dw, self._prev_sums[1], self._symmetric)
        self._prev_sums = (c_win, dw)


def _decorrelation(n: int, s_a: np.ndarray, ss_a: np.ndarray, s_b: np.ndarray, ss_b: np.ndarray, sab: np.ndarray,
                   contact_a: np.ndarray, contact_b: np.ndarray) -> np.ndarray:
    """:func:`~.indicators.decorrelation_pair` with its common case first (every frame
    and its lagged one in contact, neither uniform): the same values in a third of the
    numpy calls, which at 100 Hz are the cost of a hop."""
    var_a = n * ss_a - s_a * s_a
    var_b = n * ss_b - s_b * s_b
    flat = (var_a <= _ZERO_VAR * s_a * s_a) | (var_b <= _ZERO_VAR * s_b * s_b)
    if flat.any() or not (contact_a.all() and contact_b.all()):
        return decorrelation_pair(n, s_a, ss_a, s_b, ss_b, sab, contact_a, contact_b)
    d = 1.0 - (n * sab - s_a * s_b) / np.sqrt(var_a * var_b)
    return np.clip(d, 0.0, 2.0, out=d)
