"""The ramp channel of ``cof-track``: has the centre of force started to move?

A slide that starts turns the CoF from a constant into a ramp.  For a ramp that began
``L`` samples ago, the best linear statistic (least squares, white noise) weights the
newest samples ``1 .. L`` against the mean of the ``B`` samples before them:

    num_L = sum_{j=1..L} j (c_{k-L+j} - mean(c_{k-L-B+1} .. c_{k-L}))        (2-vector)
    sd_L  = sqrt(sum j^2 + (sum j)^2 / B)         (its noise, per unit sample noise)
    T_L   = |(num_x / sigma_x, num_y / sigma_y)| / sd_L      (Rayleigh: P(T > z) = e^(-z^2/2))
    d_L   = |num_L| L / sum j^2                  (the displacement the ramp implies, mm)

and a slide is a ramp when ``T_L > z`` and ``d_L > min_mm`` for any horizon of a small
bank (the onset time is unknown).  Each axis is divided by its own noise: an array
with rows 20 mm apart has a CoF four times noisier across the rows, and a magnitude
over the pooled noise then has a one-dimensional tail, far heavier than Rayleigh's
(the light hand grip's false alarms before the axes were whitened).  Its delay grows
as (sigma / speed)^(2/3), against (sigma / speed) for a two-window difference:
docs/evaluation.md.

**Other evidence adds to it.**  ``T^2 / 2`` is the ramp's log-likelihood ratio (nats).
Evidence the caller has from an independent source (``cof-track``: the stick-slip
ripple of the total force, detect/ripple.py) comes in the same unit and is added
before the threshold, ``sqrt(T^2 + 2 e) > z``; the displacement floor still holds.
With ``e = 0`` it is the ramp test alone.

A centre's noise is the force noise spread over the total force, so it scales as
1 / S: with each centre the caller pushes that scale (1 / S^2), and the noise used is
q times its mean over the window (under a machine's vibration S swings by a factor
of five within the window, and the current frame's S alone misjudged it).

The batch form is one (H x N) matrix product over the last N = max L + B centres;
the streaming form keeps running sums per horizon instead (:class:`RampBank`).
"""

from __future__ import annotations

import math

import numpy as np


def ramp_weights(horizons: tuple[int, ...], base: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Weights ``G`` (H x N, oldest sample first), the noise ``sd`` of each row for unit
    sample noise, and ``disp``: mm of displacement per unit of ``|G c|``."""
    n = max(horizons) + base
    g = np.zeros((len(horizons), n))
    sd = np.zeros(len(horizons))
    disp = np.zeros(len(horizons))
    for h, length in enumerate(horizons):
        w = np.arange(1.0, length + 1.0)
        g[h, n - length:] = w
        g[h, n - length - base:n - length] = -w.sum() / base
        sd[h] = math.sqrt(float(g[h] @ g[h]))
        disp[h] = length / float(w @ w)
    return g, sd, disp


def ramp_batch(c: np.ndarray, q: np.ndarray, horizons: tuple[int, ...], base: int, z: float,
               min_mm: float | np.ndarray, scale: np.ndarray | None = None,
               evidence: np.ndarray | None = None) -> np.ndarray:
    """The score (1 = threshold) at every sample of a (K, 2) CoF series, with no
    streaming state: what :class:`RampBank` must reproduce (NaN until N samples).
    ``q`` (K, 2): each axis' noise variance per unit ``scale``; ``scale`` (K,), each
    centre's noise scale (1 by default); ``min_mm`` may change per sample (K,);
    ``evidence`` (K,): nats to add to the ramp's (none by default)."""
    floors = np.broadcast_to(np.asarray(min_mm, dtype=float), (len(c),))
    scale = np.ones(len(c)) if scale is None else scale
    evidence = np.zeros(len(c)) if evidence is None else evidence
    g, sd, disp = ramp_weights(horizons, base)
    n = g.shape[1]
    out = np.full(len(c), np.nan)
    for k in range(n - 1, len(c)):
        num = g @ c[k - n + 1:k + 1]
        sigma = np.sqrt(q[k] * scale[k - n + 1:k + 1].mean())
        t = np.sqrt((np.linalg.norm(num / sigma, axis=1) / sd) ** 2 + 2.0 * evidence[k])
        mm = np.linalg.norm(num, axis=1) * disp
        floor = floors[k]
        out[k] = float(np.max(np.minimum(t / z, mm / floor if floor > 0 else np.inf)))
    return out


class RampBank:
    """Streaming :func:`ramp_batch`: ``push`` a centre and its noise scale, ``score``
    with the current noise variance per unit scale (and any evidence).

    Each horizon keeps three running sums of the centre, each axis on its own: ``w``,
    the ramp-weighted sum of its newest ``L``; ``p``, their plain sum; ``b``, the sum
    of the ``B`` before them.  A push moves each by the samples that enter and leave,
    so the cost per frame is the same at 100 Hz and at 1 kHz (the horizons are times;
    a matrix product over them grew with the rate).  Every few rounds the sums are
    recomputed from the ring, against rounding drift.

    (The axes are Python floats, not one complex number ``x + iy``: a float's
    arithmetic is the interpreter's specialised fast path, a complex's the generic
    one, at twice the cost a push.  Each part of a complex sum is the same float;
    the recomputation still takes the centres as complex numbers, whose sums numpy
    adds in its own order.)"""

    def __init__(self, horizons: tuple[int, ...], base: int, z: float) -> None:
        _, sd, disp = ramp_weights(horizons, base)  # (the weights are the batch form's)
        self.n = max(horizons) + base
        self.horizons, self.base = tuple(horizons), base
        self._sd2 = (sd * sd).tolist()  # |whitened num|^2 / this: T^2
        self._z = z
        self._disp = disp.tolist()  # |num| x this: the displacement in mm
        # num = w - (sum of the weights 1..L) / B x b
        self._kb = [length * (length + 1) / 2.0 / base for length in self.horizons]
        # recompute the sums every whole number of rounds, about every 500 pushes
        self._resync_every = self.n * max(1, round(500 / self.n))
        # (the hot path's loops read one tuple per horizon: each horizon's index, its
        # length (as the float it multiplies) and reach into the ring; its sums'
        # factor, T^2 scale and displacement scale)
        self._pushes = tuple((h, float(length), length, length + base) for h, length in enumerate(self.horizons))
        self._scores = tuple(zip(range(len(self.horizons)), self._kb, self._sd2, self._disp))
        self._both = tuple(push + score[1:] for push, score in zip(self._pushes, self._scores))
        self.reset()

    def reset(self) -> None:
        self._x = [0.0] * self.n  # the last n centres (zeros before the first)
        self._y = [0.0] * self.n
        #: each horizon's sums (w_x, w_y, p_x, p_y, b_x, b_y)
        self._sums = [(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)] * len(self.horizons)
        self._scale = [0.0] * self.n
        self._scale_sum = 0.0
        self._i = 0
        self.count = 0

    def push(self, x: float, y: float, scale: float = 1.0) -> None:
        i, ring_x, ring_y, sums = self._i, self._x, self._y, self._sums
        for h, weight, length, reach in self._pushes:
            # the centre that leaves the newest L (it joins the base), and the one that
            # leaves the base; ``i`` holds the oldest of all n, about to be overwritten
            wx, wy, px, py, bx, by = sums[h]
            lx, ly = ring_x[i - length], ring_y[i - length]
            sums[h] = (wx + (weight * x - px), wy + (weight * y - py), px + (x - lx), py + (y - ly),
                       bx + (lx - ring_x[i - reach]), by + (ly - ring_y[i - reach]))
        ring_x[i], ring_y[i] = x, y
        scales = self._scale
        self._scale_sum += scale - scales[i]  # the sample n pushes ago leaves
        scales[i] = scale
        i += 1
        self._i = i if i < self.n else 0
        count = self.count = self.count + 1
        if count % self._resync_every == 0:  # against the running sums' rounding drift
            self._resync()

    def _resync(self) -> None:
        self._scale_sum = math.fsum(self._scale)
        c = np.empty(self.n, complex)  # oldest first: a whole number of rounds has passed
        c.real, c.imag = self._x, self._y
        for h, length in enumerate(self.horizons):
            newest = c[self.n - length:]
            w = complex(np.arange(1.0, length + 1.0) @ newest)
            p = complex(newest.sum())
            b = complex(c[self.n - length - self.base:self.n - length].sum())
            self._sums[h] = (w.real, w.imag, p.real, p.imag, b.real, b.imag)

    def score(self, q_x: float, q_y: float, min_mm: float, evidence: float = 0.0) -> float:
        """Largest over the horizons of min(sqrt(T^2 + 2 evidence) / z, d / min_mm); 0
        until N centres."""
        return self.score_less(None, 0.0, 0.0, q_x, q_y, min_mm, evidence)

    def score_less(self, cov: RampBank | None, beta_x: float, beta_y: float, q_x: float, q_y: float, min_mm: float,
                   evidence: float = 0.0) -> float:
        """:meth:`score` of the centre less ``beta`` times a covariate, ``c - beta u``:
        ``cov`` is a bank of the same horizons and base fed ``u`` as its x (the total
        force, for ``cof-track``'s ``force_covariate``; None: none, :meth:`score`).  The
        statistic is linear in the samples, so this is the test of the corrected series
        at the current ``beta`` (a beta that is learnt as it goes puts no step into the
        ring)."""
        mean_scale = self._scale_sum / self.n
        if self.count < self.n or not (q_x > 0.0 and q_y > 0.0 and mean_scale > 0.0):
            return 0.0
        inv_x, inv_y = 1.0 / (q_x * mean_scale), 1.0 / (q_y * mean_scale)
        extra = 2.0 * evidence
        z, sqrt = self._z, math.sqrt
        sums, other = self._sums, None if cov is None else cov._sums
        best = 0.0
        for h, kb, sd2, disp in self._scores:
            wx, wy, _, _, bx, by = sums[h]
            nx, ny = wx - kb * bx, wy - kb * by
            if other is not None:
                wu, _, _, _, bu, _ = other[h]
                nu = wu - kb * bu
                nx, ny = nx - beta_x * nu, ny - beta_y * nu
            nx2, ny2 = nx * nx, ny * ny
            r = sqrt((nx2 * inv_x + ny2 * inv_y) / sd2 + extra) / z
            if r > best:  # (else min(r, d) cannot be the largest: d is not needed)
                if min_mm > 0.0:
                    d = sqrt(nx2 + ny2) * disp / min_mm
                    if d < r:
                        r = d
                if r > best:
                    best = r
        return best

    def push_score(self, x: float, y: float, scale: float, q_x: float, q_y: float, min_mm: float,
                   evidence: float = 0.0) -> float:
        """:meth:`push`, then :meth:`score`: the same floats, in one pass over the
        horizons (the caller's hot path at 100 Hz, where it tests every frame)."""
        i, scales = self._i, self._scale
        count = self.count + 1
        scale_sum = self._scale_sum + (scale - scales[i])
        mean_scale = scale_sum / self.n
        if count < self.n or count % self._resync_every == 0 or not (q_x > 0.0 and q_y > 0.0 and mean_scale > 0.0):
            self.push(x, y, scale)  # (no score yet, or the sums renewed first)
            return self.score(q_x, q_y, min_mm, evidence)
        self._scale_sum = scale_sum
        scales[i] = scale
        inv_x, inv_y = 1.0 / (q_x * mean_scale), 1.0 / (q_y * mean_scale)
        extra = 2.0 * evidence
        z, sqrt = self._z, math.sqrt
        ring_x, ring_y, sums = self._x, self._y, self._sums
        best = 0.0
        for h, weight, length, reach, kb, sd2, disp in self._both:
            wx, wy, px, py, bx, by = sums[h]
            j = i - length
            lx, ly = ring_x[j], ring_y[j]
            j = i - reach
            wx += weight * x - px
            wy += weight * y - py
            bx += lx - ring_x[j]
            by += ly - ring_y[j]
            sums[h] = (wx, wy, px + (x - lx), py + (y - ly), bx, by)
            nx, ny = wx - kb * bx, wy - kb * by
            nx2, ny2 = nx * nx, ny * ny
            r = sqrt((nx2 * inv_x + ny2 * inv_y) / sd2 + extra) / z
            if r > best:
                if min_mm > 0.0:
                    d = sqrt(nx2 + ny2) * disp / min_mm
                    if d < r:
                        r = d
                if r > best:
                    best = r
        ring_x[i], ring_y[i] = x, y
        i += 1
        self._i = i if i < self.n else 0
        self.count = count
        return best
