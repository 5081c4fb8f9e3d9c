"""The step channel of ``cof-track``: has the centre of force jumped?

Stick-slip often moves a contact in jumps with rests between them: a few tenths of a
millimetre in one or two frames, then nothing for most of the period.  The ramp
channel (detect/ramp.py) waits for a slope; a jump is visible at once against where
the contact was.  So, beside the ramp bank, the mean of the newest ``J`` centres
against the mean of the ``B`` that ended ``G`` samples before the newest (the plain
displacement test's geometry: two frames against the half-second that ended 100 ms
earlier, at 100 Hz):

    d     = mean(c_{k-J+1} .. c_k) - mean(c_{k-G-B+1} .. c_{k-G})         (2-vector, mm)
    w     = sum(1 / S_i^2 over the newest) / J^2 + sum(1 / S_i^2 over the base) / B^2
    v     = running mean of d^2 / w per axis, learnt while calm            (its own noise)
    T^2   = d_x^2 / (w v_x) + d_y^2 / (w v_y)                              (Rayleigh under noise)
    score = min(sqrt(T^2 + 2 e) / z, |d| / min_mm)

A centre's noise scales as 1 / S, so ``d``'s variance is ``w`` times the noise in
force units, each centre weighed with its own total as the ramp weighs its samples:
under a machine's vibration the total swings between 1 and 5 N within two frames, and
a centre taken at the light end, scaled by the newest total as if it were as sure as
that one, read as a jump of 6 to 7 standard deviations (20 false slips on a light
hold shaken at 37 Hz; 2 with the weights, as many as without the channel).  The noise is the statistic's own, not one
derived from the frame-to-frame noise under a white-noise model: the base spans
0.6 s, and whatever wanders the CoF over that time (a light grip's sway, a slow
drift) widens ``d`` but not the frame-to-frame steps.  ``e`` is the same evidence the
ramp adds (the stick-slip ripple of the total force, in nats): the channel is one
more hypothesis beside the ramp bank's horizons, its log-likelihood ratio ``T^2 / 2``
with the same evidence added.

The streaming form keeps the last ``G + B`` centres, totals and weights and running
sums of each (the newest ``J``, the base), renewed from the ring every few hundred
pushes against rounding drift; :func:`step_batch` is the same statistic with no
streaming state.
"""

from __future__ import annotations

import math

import numpy as np


def step_batch(c: np.ndarray, newest: int, gap: int, base: int) -> np.ndarray:
    """``d`` (K, 2) at every sample of a (K, 2) CoF series, NaN until ``gap + base``
    samples: what :class:`StepTest` must reproduce.  (A (K, 3) series whose third
    column is the total force gives (K, 4): ``d``, the level change of
    :meth:`StepTest.level_change` and the weight ``w`` of :attr:`StepTest.weight`.)"""
    n = gap + base
    out = np.full((len(c), 2 if c.shape[1] == 2 else 4), np.nan)
    for k in range(n - 1, len(c)):
        out[k, :2] = c[k - newest + 1:k + 1, :2].mean(axis=0) - c[k - n + 1:k - gap + 1, :2].mean(axis=0)
        if c.shape[1] > 2:
            out[k, 2] = c[k - gap + 1:k + 1, 2].mean() - c[k - n + 1:k - gap + 1, 2].mean()
            out[k, 3] = ((1.0 / c[k - newest + 1:k + 1, 2] ** 2).sum() / newest ** 2
                         + (1.0 / c[k - n + 1:k - gap + 1, 2] ** 2).sum() / base ** 2)
    return out


class StepTest:
    """Streaming :func:`step_batch`: ``push`` a centre and the total force, read
    :meth:`difference`, :attr:`weight` and :meth:`level_change`."""

    def __init__(self, newest: int, gap: int, base: int) -> None:
        self.newest = max(1, newest)
        self.gap = max(self.newest, gap)
        self.base = max(1, base)
        self.n = self.gap + self.base
        self._resync_every = self.n * max(1, round(500 / self.n))
        #: the level change's variance per unit variance of one total (white noise)
        self.level_weight = 1.0 / self.gap + 1.0 / self.base
        self._geometry = (self.newest, self.gap, self.n)
        self.reset()

    def reset(self) -> None:
        self._x = [0.0] * self.n  # the last n centres and totals, a ring; ``_i`` the oldest
        self._y = [0.0] * self.n
        self._s = [0.0] * self.n
        self._w = [0.0] * self.n  # 1 / S^2
        self._i = 0
        self.count = 0
        #: sums of the newest ``newest`` (x, y, 1 / S^2), of the total over the gap, of
        #: the base (x, y, total, 1 / S^2)
        self._sums = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        #: ``d`` (mm), its variance per unit of noise in force units (N^-2) and the level
        #: change after the latest push (0 until ``ready``)
        self.dx = self.dy = self.weight = self.level = 0.0
        self.ready = False

    def push(self, x: float, y: float, s: float) -> bool:
        """Add a centre and its total (> 0); whether ``gap + base`` are in (then
        :attr:`dx`, :attr:`dy`, :attr:`weight` and :attr:`level` hold the test's values)."""
        newest, gap, n = self._geometry
        i = self._i
        ring_x, ring_y, ring_s, ring_w = self._x, self._y, self._s, self._w
        count = self.count
        w = 1.0 / (s * s)
        # the newest ``newest`` lose the one that many pushes ago; the base gains the one
        # ``gap`` pushes ago and loses the oldest (the ring holds the base first)
        nx, ny, nw, gs, bx, by, bs, bw = self._sums
        nx += x
        ny += y
        nw += w
        gs += s
        if count >= newest:
            j = i - newest  # (a negative index counts from the end)
            nx -= ring_x[j]
            ny -= ring_y[j]
            nw -= ring_w[j]
        if count >= gap:
            j = i - gap
            bx += ring_x[j]
            by += ring_y[j]
            bw += ring_w[j]
            old = ring_s[j]
            gs -= old
            bs += old
            if count >= n:
                bx -= ring_x[i]
                by -= ring_y[i]
                bs -= ring_s[i]
                bw -= ring_w[i]
        ring_x[i] = x
        ring_y[i] = y
        ring_s[i] = s
        ring_w[i] = w
        i += 1
        self._i = i if i < n else 0
        count = self.count = count + 1
        self._sums = (nx, ny, nw, gs, bx, by, bs, bw)
        if count % self._resync_every == 0:  # against the running sums' rounding drift
            self._resync()
            nx, ny, nw, gs, bx, by, bs, bw = self._sums
        if count < n:
            return False
        self.ready = True
        base = self.base
        self.dx = nx / newest - bx / base
        self.dy = ny / newest - by / base
        self.weight = nw / (newest * newest) + bw / (base * base)
        self.level = gs / gap - bs / base
        return True

    def _resync(self) -> None:
        """The sums again from the ring (a whole number of rounds: oldest first)."""
        base, cut = self.base, self.n - self.newest
        x, y, s, w = self._x, self._y, self._s, self._w
        self._sums = (math.fsum(x[cut:]), math.fsum(y[cut:]), math.fsum(w[cut:]), math.fsum(s[base:]),
                      math.fsum(x[:base]), math.fsum(y[:base]), math.fsum(s[:base]), math.fsum(w[:base]))

    def difference(self) -> tuple[float, float] | None:
        """``d`` (mm), or None until ``gap + base`` centres are in."""
        return (self.dx, self.dy) if self.ready else None

    def level_change(self) -> float:
        """The total force's mean over the gap (the newest ``gap`` samples) less its mean
        over the base (0 until ``gap + base`` are in): whether the force's level moved
        over the span the step looks across.  A stick-slip ripple, fast and about a
        constant level, averages out of both means; a squeeze or a swinging load does
        not."""
        return self.level
