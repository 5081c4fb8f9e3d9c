"""The torsion channel of ``cof-track``: is the pressure distribution turning?

A part that turns in the grip about the sensor's normal (torsional slip) keeps its
centre of force and its total force: every channel that reads those two is blind to
it.  What changes is the distribution's shape.  A small turn ``d theta`` about the
centre of force ``c`` changes the normalised distribution ``p = f / S`` by

    dp = -d theta g,    g = (x - c_x) dp/dy - (y - c_y) dp/dx

(the rotational derivative of ``p``; its gradients from the array's grid), so the
least-squares angle of a frame's change is ``dp . g / (g . g)``: a rotational optical
flow.  The second moments would see a long footprint turn but not a square one (they
are isotropic); the flow sees the corners of either.

Per frame the channel adds ``d_k = (p_k - p_{k-1}) . g_hat`` (``g_hat = g / g.g``) to
an angle ``theta_k``.  ``g`` comes from the mean distribution of the last block of
``ref_s`` and is renewed once a block; ``d_k`` is taken with one ``g`` for both frames,
so within a block the sum telescopes and ``theta`` carries the frame's noise once, not
a random walk.  The frame at which ``g`` is renewed is left out of it (its noise would
otherwise bias every renewal the same way: a ramp in ``theta`` that no part makes).  The angle is in the flow's own units (a coarse grid's gradients make
it read a square's turn several times too large, a long block's too small): what
counts is the ratio to its noise.

The test is the ramp channel's (detect/ramp.py, :class:`RampBank`) on ``theta``: a
turn that starts is a ramp; its noise is learnt while calm as ``S^2 d^2 / 2`` (the
distribution's noise is the taxels' over ``S``), so a grip that loosens keeps the
right threshold.  Per frame: one dot product and one vector sum; per block one
gradient of the grid.
"""

from __future__ import annotations

import numpy as np

from .ramp import RampBank


def grid_of(x_mm: np.ndarray, y_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The columns' x and the rows' y of a row-major rectangular array, or ``None`` if
    the taxels are no such grid (or a single row or column: no turn to see)."""
    x, y = np.asarray(x_mm, float), np.asarray(y_mm, float)
    xs, ys = np.unique(x), np.unique(y)
    if len(xs) < 2 or len(ys) < 2 or len(xs) * len(ys) != len(x):
        return None
    if not (np.array_equal(x, np.tile(xs, len(ys))) and np.array_equal(y, np.repeat(ys, len(xs)))):
        return None
    return xs, ys


def _padded(c: np.ndarray) -> np.ndarray:
    """Coordinates with one more taxel's pitch beyond each end."""
    return np.concatenate(([2.0 * c[0] - c[1]], c, [2.0 * c[-1] - c[-2]]))


def turn_template(p: np.ndarray, xs: np.ndarray, ys: np.ndarray) -> np.ndarray | None:
    """``g / (g . g)`` for the distribution ``p`` (row-major, summing to 1) about its
    centre; ``None`` if ``g`` vanishes (a flat distribution shows no turn).

    The gradients are central differences with nothing beyond the array's edge: a
    footprint that ends in an edge taxel's cell has its edge there, and the one-sided
    difference at the edge read a 20 x 12 mm block's turn at a third of the
    correlation (0.34 against 0.58 for the change over 0.1 s)."""
    grid = np.pad(p.reshape(len(ys), len(xs)), 1)
    px, py = _padded(xs), _padded(ys)
    dx = (grid[1:-1, 2:] - grid[1:-1, :-2]) / (px[2:] - px[:-2])[None, :]
    dy = (grid[2:, 1:-1] - grid[:-2, 1:-1]) / (py[2:] - py[:-2])[:, None]
    x = np.tile(xs, len(ys))
    y = np.repeat(ys, len(xs))
    cx, cy = float(p @ x), float(p @ y)
    g = (x - cx) * dy.ravel() - (y - cy) * dx.ravel()
    gg = float(g @ g)
    if not gg > 1e-18:
        return None
    return g / gg


def turn_batch(forces: np.ndarray, xs: np.ndarray, ys: np.ndarray, block: int, blocks: int = 1) -> np.ndarray:
    """The angle ``theta`` (K,) of a series of frames in contact, with no streaming
    state: what :class:`TurnFlow` must reproduce."""
    s = forces.sum(axis=1)
    p = forces / s[:, None]
    theta = np.zeros(len(forces))
    g: np.ndarray | None = None
    ends: list[int] = []  # the frames at which g was renewed
    for k in range(len(forces)):
        if k:
            theta[k] = theta[k - 1] + (float((p[k] - p[k - 1]) @ g) if g is not None else 0.0)
        if (k + 1) % block == 0:  # renew g from the last blocks, less the frames g was renewed at
            ends.append(k)
            first = max(0, k + 1 - blocks * block)
            use = [j for j in range(first, k + 1) if j not in ends]
            g_new = turn_template(forces[use].sum(axis=0) / s[use].sum(), xs, ys)
            g = g_new if g_new is not None else g
    return theta


class TurnFlow:
    """Streaming :func:`turn_batch`, and the ramp test on its angle.

    ``push(f, s)`` each frame in contact (``held``: a held copy across a gap, which
    adds no change); ``score(min_rad)`` the ramp's score (1 = threshold) against the
    learnt noise; ``learn()`` after a calm frame."""

    def __init__(self, xs: np.ndarray, ys: np.ndarray, block: int, blocks: int, horizons: tuple[int, ...],
                 base: int, z: float, noise_n: int) -> None:
        self.xs, self.ys = xs, ys
        self.block, self.blocks = max(1, block), max(1, blocks)
        self._ramp = RampBank(horizons, base, z)
        self._a_noise = 1.0 / max(1.0, noise_n)
        self.reset()

    def reset(self) -> None:
        n = len(self.xs) * len(self.ys)
        self._acc = np.zeros(n)  # this block's sum of forces (and of totals)
        self._acc_s = 0.0
        # the last ``blocks`` block sums, and their sum: the template's distribution
        self._ring = [(np.zeros(n), 0.0) for _ in range(self.blocks)]
        self._ring_i = 0
        self._sum = np.zeros(n)
        self._sum_s = 0.0
        self._n = 0
        self._g: np.ndarray | None = None
        self._u = 0.0  # the last frame's p . g_hat
        self.theta = 0.0
        self._d2 = 0.0  # the last change, squared, in force units (S^2 d^2 / 2)
        self._noise = 0.0  # its learnt calm level
        self._learnt = 0
        self._ramp.reset()

    def push(self, f: np.ndarray, s: float, held: bool = False) -> None:
        g = self._g
        if g is not None:
            u = float(f @ g) / s
            d = 0.0 if held else u - self._u
            self.theta += d
            self._d2 = 0.5 * s * s * d * d
            self._u = u
            if not held:
                self._ramp.push(self.theta, 0.0, 1.0 / (s * s))
        self._n += 1
        if self._n < self.block:
            self._acc += f
            self._acc_s += s
            return
        # a new template from the last blocks' frames but this one, and this frame's
        # projection on it (had the frame's own noise entered its template, the two
        # would correlate, and every renewal would add the same bias: a drift in theta).
        # A template over several blocks changes little at each renewal: the noise of
        # the frame it changes at, times that change, is a random walk in theta
        old, old_s = self._ring[self._ring_i]
        self._sum += self._acc - old
        self._sum_s += self._acc_s - old_s
        self._ring[self._ring_i] = (self._acc, self._acc_s)
        self._ring_i = (self._ring_i + 1) % self.blocks
        if self._ring_i == 0:  # once a round, against the running sum's rounding drift
            self._sum = np.sum([a for a, _ in self._ring], axis=0)
            self._sum_s = sum(b for _, b in self._ring)
        g_new = turn_template(self._sum / self._sum_s, self.xs, self.ys) if self._sum_s > 0.0 else None
        if g_new is not None:
            self._g = g_new
            self._u = float(f @ g_new) / s
        self._acc = old  # (recycled: it left the ring)
        self._acc[:] = 0.0
        self._acc_s = 0.0
        self._n = 0

    def score(self, min_rad: float) -> float:
        q = self._noise
        return self._ramp.score(q, q, min_rad) if q > 0.0 else 0.0

    def learn(self) -> None:
        """Count the last change as calm noise (the caller knows the frame was calm)."""
        if self._g is None:
            return
        self._learnt += 1
        gain = max(1.0 / self._learnt, self._a_noise)
        self._noise += gain * (self._d2 - self._noise)
