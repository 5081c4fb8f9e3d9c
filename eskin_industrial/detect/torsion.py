"""The torsion channel of ``cof-track``: is the pressure distribution turning?

A part that turns in the grip about the sensor's normal (torsional slip) keeps its
centre of force and its total force: every channel that reads those two is blind to
it.  What changes is the distribution's shape.  A small turn ``d theta`` about the
centre of force ``c`` changes the normalised distribution ``p = f / S`` by

    dp = -d theta g,    g = (x - c_x) dp/dy - (y - c_y) dp/dx

(the rotational derivative of ``p``; its gradients from the array's grid), so the
least-squares angle of a change is ``dp . g / (g . g)``: a rotational optical flow.
The second moments would see a long footprint turn but not a square one (they are
isotropic); the flow sees the corners of either.

The channel works on the mean distribution of each of its own hops (``p_h``: the
hop's summed forces over its summed totals, 40 ms by default: a hop's mean is as good
as its frames).  Per frame it keeps the frame and adds ``f . g_hat``, which the caller's
one matrix product per frame (total and centre of force) yields in a fourth column
(:meth:`TurnFlow.project_into`): the hop's angle is their sum over the hop's total, and
the frames are summed only once a block, for the template; so the cost per frame
stays within the budget at 100 Hz, where cof-track's own hop is one frame.  Each hop adds ``d_h = (p_h - p_{h-1}) . g_hat`` (``g_hat = g / g.g``)
to an angle ``theta_h``.  ``g`` comes from the mean distribution of the last
``blocks`` blocks of hops and is renewed once a block; ``d_h`` is taken with one ``g``
for both hops, so between renewals the sum telescopes and ``theta`` carries a hop's
noise once, not a random walk.  The hop at which ``g`` is renewed is left out of it
(its noise would otherwise bias every renewal the same way: a ramp in ``theta`` that
no part makes), and a template over several blocks changes little at each renewal
(the noise of the hop it changes at, times that change, is a step of a random walk).
The angle is in the flow's own units (a 5 mm grid's gradients make it read a 20 mm
square's turn 3.6 times too large): what counts is the ratio to its noise.

The test is the ramp channel's (detect/ramp.py, :class:`RampBank`) on ``theta``, over
horizons counted in hops: a turn that starts is a ramp.  Its noise is each taxel's
(learnt while calm, as half the squared change of its hop mean) weighed by
``g_hat^2`` and over ``S^2``: a taxel with no load reads a clipped, quieter noise, so a
template that moves to loaded taxels (after a slide) is noisier, and a grip that
loosens keeps the right threshold.
"""

from __future__ import annotations

import math

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


class _Grid:
    """What the template needs of the grid, worked out once.

    The central differences along both axes are one gather of each taxel's two
    neighbours (``_ahead``, ``_behind``: indices into the taxels and one zero beyond
    them, for the array's edge), the x differences first: half the numpy calls of
    slicing a padded grid (at 100 Hz the template is renewed every 24 frames), each
    difference the same float."""

    def __init__(self, xs: np.ndarray, ys: np.ndarray) -> None:
        rows, cols = self.shape = (len(ys), len(xs))
        n = rows * cols
        self.x, self.y = np.tile(xs, len(ys)), np.repeat(ys, len(xs))
        px, py = _padded(xs), _padded(ys)
        inv_dx = 1.0 / (px[2:] - px[:-2])
        inv_dy = 1.0 / (py[2:] - py[:-2])
        r, c = np.divmod(np.arange(n), cols)
        edge = n  # the zero beyond the array
        self._ahead = np.concatenate((np.where(c + 1 < cols, r * cols + c + 1, edge),
                                      np.where(r + 1 < rows, (r + 1) * cols + c, edge)))
        self._behind = np.concatenate((np.where(c > 0, r * cols + c - 1, edge),
                                       np.where(r > 0, (r - 1) * cols + c, edge)))
        self._inv = np.concatenate((inv_dx[c], inv_dy[r]))  # each difference's 1 / spacing
        self._buf = np.zeros(n + 1)  # a map's taxels, and the zero beyond the edge
        self._ones = np.ones(n)
        self.inv_dx2 = inv_dx[c] ** 2
        self.inv_dy2 = inv_dy[r] ** 2
        self.pitch2 = float(np.diff(xs).min() * np.diff(ys).min())  # a taxel's cell, mm^2
        self.footprint = 0.0  #: the last template's p: mean squared distance from its centre, in cells

    def template(self, p: np.ndarray, var: np.ndarray | None = None) -> tuple[np.ndarray, float, float] | None:
        """``g_hat``, ``g . g``, and what ``g . g`` would be from the noise of ``p``
        alone if each taxel's variance were ``var`` (1 by default): the central
        differences' noise, weighed by the distance from the centre."""
        n = len(p)
        buf = self._buf
        buf[:n] = p
        d = (buf[self._ahead] - buf[self._behind]) * self._inv  # (dp/dx, dp/dy)
        x, y = self.x - float(p @ self.x), self.y - float(p @ self.y)
        x2, y2 = x * x, y * y
        self.footprint = float(p @ (x2 + y2)) / self.pitch2
        g = x * d[n:] - y * d[:n]
        gg = float(g @ g)
        if not gg > 1e-18:
            return None
        buf[:n] = self._ones if var is None else var
        pair = buf[self._ahead] + buf[self._behind]  # the two neighbours a difference takes
        return g / gg, gg, float((x2 * self.inv_dy2) @ pair[n:] + (y2 * self.inv_dx2) @ pair[:n])


def _summed(frames: list[np.ndarray], zero: np.ndarray) -> np.ndarray:
    """Frames summed in the order they came, from zero (a running sum's floats: a
    sum over the first axis adds the rows in order)."""
    return np.add.reduce(frames) if frames else zero


def turn_template(p: np.ndarray, xs: np.ndarray, ys: np.ndarray) -> np.ndarray | None:
    """``g / (g . g)`` for the distribution ``p`` (row-major, summing to 1) about its
    centre; ``None`` if ``g`` vanishes (a flat distribution shows no turn).

    The gradients are central differences with nothing beyond the array's edge: a
    footprint that ends in an edge taxel's cell has its edge there, and the one-sided
    difference at the edge read a 20 x 12 mm block's turn at a third of the
    correlation (0.34 against 0.58 for the change over 0.1 s)."""
    out = _Grid(xs, ys).template(p)
    return None if out is None else out[0]


def turn_batch(forces: np.ndarray, xs: np.ndarray, ys: np.ndarray, hop: int, block: int,
               blocks: int = 1) -> np.ndarray:
    """The angle ``theta`` after each whole hop (H,) of a series of frames in contact,
    with no streaming state: what :class:`TurnFlow` must reproduce (with no
    ``min_visibility``)."""
    h = len(forces) // hop
    f = forces[:h * hop].reshape(h, hop, -1).sum(axis=1)  # each hop's summed forces
    p = f / f.sum(axis=1, keepdims=True)
    theta = np.zeros(h)
    g: np.ndarray | None = None
    ends: list[int] = []  # the hops at which g was renewed
    for k in range(h):
        if k:
            theta[k] = theta[k - 1] + (float((p[k] - p[k - 1]) @ g) if g is not None else 0.0)
        if (k + 1) % block == 0:  # renew g from the last blocks, less the hops g was renewed at
            ends.append(k)
            use = [j for j in range(max(0, k + 1 - blocks * block), k + 1) if j not in ends]
            g_new = turn_template(f[use].sum(axis=0) / f[use].sum(), xs, ys)
            g = g_new if g_new is not None else g
    return theta


class TurnFlow:
    """Streaming :func:`turn_batch`, and the ramp test on its angle.

    ``push(f, s)`` each frame in contact (``held``: a held copy across a gap, which
    is no sample of its own); :attr:`score` the ramp's score (1 = threshold) against
    the learnt noise, as of the last whole hop; ``learn()`` after a calm frame (it
    counts each hop's change once)."""

    def __init__(self, xs: np.ndarray, ys: np.ndarray, hop: int, block: int, blocks: int,
                 horizons: tuple[int, ...], base: int, z: float, noise_n: int, min_visibility: float = 0.0,
                 min_footprint: float = 0.0, min_rad: float = 0.0) -> None:
        """``block``, ``horizons``, ``base`` and ``noise_n`` count hops of ``hop`` frames;
        ``min_visibility``: the least ``g . g`` over what its template's noise alone
        would give (:attr:`visibility`) at which the channel looks; ``min_footprint``: the
        least mean squared distance of the force from its centre, in taxel cells, at
        which a turn shows (below it the channel looks, but :attr:`blind` says it cannot see);
        ``min_rad``: the least turn, in the flow's units, that the ramp test counts."""
        self.min_visibility = min_visibility
        self.min_rad = min_rad
        self.min_footprint = min_footprint
        self.xs, self.ys = xs, ys
        self._grid = _Grid(xs, ys)
        self.hop, self.block, self.blocks = max(1, hop), max(2, block), max(1, blocks)
        self._ramp = RampBank(horizons, base, z)
        self._a_noise = 1.0 / max(1.0, noise_n / max(2, block))  # (it learns once a block)
        self._proj = np.zeros(len(xs) * len(ys))  # the template, zeros while none (project_into)
        self.reset()

    def reset(self) -> None:
        n = len(self.xs) * len(self.ys)
        # this hop's own frames (one list append a frame: summed only when a change is
        # learnt or a template made) and the sum of their totals; the hop before's
        # frames, total and frame count
        self._fl: list[np.ndarray] = []
        self._fg = 0.0  # the sum of its frames' f . g_hat
        self._zero = np.zeros(n)
        self._last: list[np.ndarray] = []
        # either hop's frames summed, once they were (a renewal sums its hop's, which
        # the next hop's change needs again)
        self._fl_sum: np.ndarray | None = None
        self._last_sum: np.ndarray | None = None
        self._s = self._last_s = 0.0
        self._last_frames = 1
        self._frames = 0
        self._held = 0
        self._hops = 0
        self._block: list[np.ndarray] = []  # this block's frames and summed totals, less the renewal hop's
        self._block_s = 0.0
        self._ring = [(np.zeros(n), 0.0) for _ in range(self.blocks)]  # the last blocks'
        self._ring_i = 0
        self._since = 0  # hops since the template was renewed
        self._proj[:] = 0.0
        self._g: np.ndarray | None = None
        self._g2 = np.zeros(n)  # g_hat^2: each taxel's weight in the angle's noise
        self._unit = 0.0  # g_hat^2 . var: the angle's noise variance times S^2
        self._u = 0.0  # the last hop's p . g_hat
        self.theta = 0.0
        self._change: np.ndarray | None = None  # a hop's mean forces' change from the hop before
        self.learnable = False  #: a change waits to be learnt from
        #: each taxel's noise variance (of a hop's mean force, N^2), learnt while calm
        #: once a block: a taxel with no load reads a clipped, quieter noise, so the
        #: angle's noise depends on which taxels its template weighs
        self._var = np.zeros(n)
        self._learnt = 0
        self.visibility = 0.0
        #: the turn cannot be seen here (TURN_UNSEEN): set until a renewal with learnt
        #: noise first judges the contact (what it shows is not known before): set if
        #: the visibility is below ``min_visibility`` or the footprint below
        #: ``min_footprint``; after that with a hysteresis, cleared only at twice the one
        #: and 1.2 times the other, so that a contact about a limit leaves it set rather
        #: than flapping.  Kept across :meth:`restart` (the same contact); read once a
        #: hop, by the caller
        self.blind = True
        self._judged = False
        self.score = 0.0  #: the ramp test's score as of the last whole hop (1 = threshold)
        self._ramp.reset()

    def project_into(self, column: np.ndarray) -> None:
        """Keep the template in ``column`` (zeros while there is none): a column of the
        caller's per-frame matrix product, which then hands each frame's ``f . g_hat``
        to :meth:`push` at no cost of its own (a hop's angle is their sum over its
        total; the hop's summed forces are needed only once a block)."""
        column[:] = self._proj
        self._proj = column

    def push(self, f: np.ndarray, s: float, held: bool = False, fg: float | None = None) -> None:
        """One frame in contact; ``fg``: ``f . g_hat`` with the column of
        :meth:`project_into` (computed here if not given)."""
        if held:
            self._held += 1
        else:
            self._fl.append(f)  # (the caller's frame, which it keeps unchanged)
            self._s += s
            self._fg += float(f @ self._proj) if fg is None else fg
        frames = self._frames = self._frames + 1
        if frames < self.hop:
            return
        frames -= self._held
        if self._s > 0.0:
            self._hop(frames)
        # the newest is kept as the hop before (its frames: summed only if needed)
        self._last = self._fl
        self._last_sum, self._fl_sum = self._fl_sum, None
        self._last_s, self._s = self._s, 0.0
        self._last_frames = frames
        self._fl = []
        self._fg = 0.0
        self._frames = self._held = 0

    def _hop(self, frames: int) -> None:
        s, fl = self._s, self._fl
        self._hops += 1
        if self._hops % self.block == 1 and self._last_s > 0.0:  # once a block, a change to learn from
            last = self._last_sum if self._last_sum is not None else _summed(self._last, self._zero)
            self._change = _summed(fl, self._zero) / frames - last / self._last_frames
            self.learnable = True
        g = self._g
        if g is not None:
            u = self._fg / s  # (every frame of the hop was taken with this g)
            self.theta += u - self._u
            self._u = u
            mean_s = s / frames
            # (the noise is in the scale pushed with each angle; the test is taken with
            # the push, once a hop, as the caller reads it at every frame)
            self.score = self._ramp.push_score(self.theta, 0.0, self._unit / (mean_s * mean_s), 1.0, 1.0,
                                               self.min_rad)
        self._since += 1
        if self._since < self.block:
            self._block += fl
            self._block_s += s
            return
        # renew the template from the last blocks' hops but this one, and take this
        # hop's projection on it (so that the next change is taken with one template)
        self._since = 0
        self._ring[self._ring_i] = (_summed(self._block, self._zero), self._block_s)
        self._ring_i = (self._ring_i + 1) % self.blocks
        self._block, self._block_s = [], 0.0
        total = sum(b for _, b in self._ring)
        if not total > 0.0:
            return
        made = self._grid.template(_summed([a for a, _ in self._ring], self._zero) / total, self._var)
        if made is None:
            return
        g_new, gg, spread = made
        used = (self.block - 1) * min(self.blocks, self._hops // self.block)  # hops in the template
        mean_s = s / frames
        self.visibility = gg * mean_s * mean_s * used / spread if spread > 0 else math.inf
        if self._learnt:  # (before any learnt noise, the visibility is no judgement)
            size = self._grid.footprint
            if self.visibility < self.min_visibility or size < self.min_footprint:
                self.blind = True
            elif not self._judged or (self.visibility >= 2.0 * self.min_visibility
                                      and size >= 1.2 * self.min_footprint):
                self.blind = False
            self._judged = True
        if self.visibility < self.min_visibility:
            # no turn to see: the template is mostly the noise of its own mean (a
            # contact on one taxel, a light or very noisy grip), and each renewal
            # would turn it at random; silent until one stands out again
            self._set_g(None)
            self.score = 0.0
            self._ramp.reset()
            return
        self._set_g(g_new)
        self._g2 = g_new * g_new
        self._unit = float(self._g2 @ self._var)
        now = self._fl_sum = _summed(fl, self._zero)
        self._u = float(now @ g_new) / s

    def _set_g(self, g: np.ndarray | None) -> None:
        self._g = g
        self._proj[:] = 0.0 if g is None else g

    def restart(self) -> None:
        """Start the template and the ramp again (the learnt noise stays): the
        distribution has moved, and a template over the last blocks smears it."""
        if self._hops == 0 and self._since == 0:
            return  # (nothing since the last restart: called at every frame of a slide)
        self._ring = [(np.zeros_like(a), 0.0) for a, _ in self._ring]
        self._block = []
        self._block_s = 0.0
        self._hops = 0
        self._since = 0
        self._set_g(None)
        self.score = 0.0
        self._ramp.reset()

    def learn(self) -> None:
        """Count the last hop's change as calm noise (the caller knows it was calm)."""
        change = self._change
        if change is None:
            return
        self._learnt += 1
        gain = max(1.0 / self._learnt, self._a_noise)
        self._var += gain * (0.5 * change * change - self._var)
        self._unit = float(self._g2 @ self._var)
        self._change = None
        self.learnable = False
