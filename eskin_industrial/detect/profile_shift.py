"""The profile channel of ``cof-track``: has the pressure map's outline started to move?

A slide that starts translates the contact.  The centre of force sees that as one
number per axis, and it weighs every column by its distance from the centre, so the
unloaded far columns' noise counts most while the change sits at the footprint's
edges.  When the contact hangs off the array's edge, a translation even changes the
centre by less than the slide (case6's slides back onto the array: 0.45 of it).  The
profile of the map (its column sums and its row sums, ``p``, ``m`` numbers) carries the
change where it happens.  For each horizon ``L`` of a bank, the least-squares ramp of
the profile against the mean of the ``B`` profiles before it (the ramp channel's
weights, detect/ramp.py) is

    num_L = sum_{j=1..L} j (p_{k-L+j} - ref_L),   ref_L = mean(p_{k-L-B+1} .. p_{k-L})

and the test is the generalised likelihood ratio of "the profile ramps in any way
that is not a change of the total force" (a change of force scales the profile: its
direction ``ref_L`` is a nuisance, projected out):

    T_L^2 = (num' C+ num - (ref' C+ num)^2 / ref' C+ ref) / sd_L^2

with ``C`` the profile's noise covariance (from each taxel's noise variance, learnt
from its frame-to-frame changes while the grip is calm: column and row sums share
taxels, so it is not diagonal) and
``C+`` its pseudo-inverse (the column sums and the row sums both add up to the total:
``C`` has rank m - 1).  Under noise ``T_L^2`` is chi-square with ``dof = rank - 1``
degrees of freedom (8 on a 5 x 5 array: four per axis); the threshold is the chi-square
quantile with the tail of the ramp channel's Rayleigh test at ``z``, exp(-z^2/2), so
both channels raise about as many false alarms per test.  The score is
``sqrt(T_L^2 / threshold)`` (1 = threshold), the largest over the bank.

The test runs on the means of blocks of frames (the detector's hop, 10 ms), so that
its cost per frame falls with the rate (:class:`ProfileShift`); :func:`profile_batch`
is the same test over a whole series, with a given noise, for the tests.
"""

from __future__ import annotations

import math

import numpy as np

from .ramp import ramp_weights


def profile_groups(x_mm: np.ndarray, y_mm: np.ndarray) -> np.ndarray:
    """The (n, m) matrix whose product with a frame is its column sums then its row
    sums (taxels grouped by their x, then by their y); an axis with one position only
    (a strip's) adds nothing but the total and is left out."""
    cols = []
    for pos in (np.asarray(x_mm, dtype=float), np.asarray(y_mm, dtype=float)):
        keys = np.round(pos, 6)
        values = np.unique(keys)
        if len(values) > 1:
            cols.append(keys[:, None] == values[None, :])
    if not cols:
        return np.zeros((len(x_mm), 0))
    return np.concatenate(cols, axis=1).astype(np.float64)


def chi2_tail(x: float, dof: int) -> float:
    """P(chi-square with ``dof`` degrees of freedom > x), closed form (dof >= 1)."""
    if x <= 0.0:
        return 1.0
    h = 0.5 * x
    if dof % 2 == 0:
        term = total = math.exp(-h)
        for j in range(1, dof // 2):
            term *= h / j
            total += term
        return total
    total = math.erfc(math.sqrt(h))
    term = math.exp(-h) * math.sqrt(h) / math.gamma(1.5)  # (h^(j+1/2) / Gamma(j+3/2)) e^-h
    for j in range(0, (dof - 1) // 2):
        total += term
        term *= h / (j + 1.5)
    return total


def chi2_threshold(z: float, dof: int) -> float:
    """The chi-square value with the tail of Rayleigh's at ``z`` (exp(-z^2 / 2))."""
    target = math.exp(-0.5 * z * z)
    lo, hi = 0.0, z * z + 20.0 * dof + 50.0
    for _ in range(200):  # bisection: the tail falls monotonically
        mid = 0.5 * (lo + hi)
        if chi2_tail(mid, dof) > target:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def sum_whitening(groups: np.ndarray, var: np.ndarray) -> tuple[np.ndarray | None, int]:
    """``groups`` times a whitening of the sums' noise (C+ = L L'), and the rank of that
    noise, from each taxel's noise variance ``var`` (taxels independent: far steadier
    than a covariance learnt entry by entry, whose small eigenvalues came out low
    after a few hundred changes and made the test fire on a still grip)."""
    top = float(var.max()) if len(var) else 0.0
    if not top > 0.0:
        return None, 0
    # a taxel that hardly changes (quantized, stuck) gets a floor: with none, its sums'
    # noise learnt as zero would weigh any change of it without bound
    cov = groups.T @ (np.maximum(var, 0.0025 * top)[:, None] * groups)
    vals, vecs = np.linalg.eigh(cov)
    keep = vals > 1e-9 * float(vals[-1])  # the total is in both axes' sums: rank m - 1
    rank = int(keep.sum())
    return groups @ (vecs[:, keep] / np.sqrt(vals[keep])), rank


def _weights(horizons: tuple[int, ...], base: int) -> tuple[np.ndarray, np.ndarray]:
    """Rows: each horizon's ramp weights, then each horizon's base mean (oldest first);
    and sd_L^2."""
    g, sd, _ = ramp_weights(horizons, base)
    n = g.shape[1]
    means = np.zeros_like(g)
    for h, length in enumerate(horizons):
        means[h, n - length - base:n - length] = 1.0 / base
    return np.vstack([g, means]), sd * sd


def _score(gram: list[list[float]], nh: int, sd2: list[float], thr: float) -> float:
    """The largest T_L^2 / threshold's root, from the Gram matrix of the whitened
    ramps (rows 0..H-1) and references (rows H..2H-1)."""
    best = 0.0
    for h in range(nh):
        row, rr = gram[h], gram[nh + h][nh + h]
        t2 = (row[h] - (row[nh + h] ** 2 / rr if rr > 0.0 else 0.0)) / (sd2[h] * thr)
        if t2 > best:
            best = t2
    return math.sqrt(best)


def profile_batch(frames: np.ndarray, groups: np.ndarray, var: np.ndarray, horizons: tuple[int, ...],
                  base: int, z: float, every: int = 1) -> np.ndarray:
    """The score (1 = threshold) after every block of ``every`` frames of a (K, n)
    series, under a fixed taxel noise variance ``var`` (of the frames), with no
    streaming state: what :class:`ProfileShift` must reproduce (NaN until N = max L + B
    blocks).  The test runs on the blocks' means, horizons and base in blocks."""
    blocks = frames[:len(frames) // every * every].reshape(-1, every, frames.shape[1]).mean(axis=1)
    w, sd2 = _weights(horizons, base)
    nh, n = len(horizons), w.shape[1]
    white, rank = sum_whitening(groups, np.asarray(var, dtype=float) / every)
    thr = chi2_threshold(z, max(1, rank - 1))
    out = np.full(len(blocks), np.nan)
    if white is None:
        return out
    for k in range(n - 1, len(blocks)):
        y = (w @ blocks[k - n + 1:k + 1]) @ white
        out[k] = _score((y @ y.T).tolist(), nh, sd2.tolist(), thr)
    return out


class ProfileShift:
    """Streaming :func:`profile_batch`, with the noise learnt as it goes.

    ``push(frame)`` once a frame (not for held copies); ``calm()`` after a frame the
    detector judged calm; ``score()`` the test's score, computed once a block of
    ``every`` frames (the detector's hop) is complete: 0 until the ring is full and a
    ring's worth of block changes has been learnt.

    The test runs on the means of the blocks, so its cost per frame falls with the
    rate: at 1 kHz a frame is one store, and a block one mean; an evaluation is one
    product over the ring of block means (stored twice, so that the newest N are one
    contiguous view), one with the groups and the whitening folded into one matrix,
    and the 2H x 2H Gram matrix of the result, which holds every inner product the
    test needs.  The noise is each taxel's variance over the changes of its block
    means, learnt from runs of blocks whose every frame was calm."""

    def __init__(self, groups: np.ndarray, horizons: tuple[int, ...], base: int, z: float,
                 every: int, noise_n: int) -> None:
        self.groups = groups
        self._w, sd2 = _weights(horizons, base)
        self._sd2 = sd2.tolist()
        self.nh = len(horizons)
        self.n = self._w.shape[1]
        self.z = z
        self.every = max(1, every)
        self.learn_every = max(1, self.n // 4)  # block changes per learning step
        self._a_noise = 1.0 / max(1.0, noise_n)  # the learning's smallest gain per change
        self.min_learnt = self.n
        self.reset()

    def reset(self) -> None:
        taxels = self.groups.shape[0]
        self._buf = np.zeros((self.every, taxels))  # the current block's frames
        self._j = 0
        self._ring = np.zeros((2 * self.n, taxels))  # block means, at i and at i + n
        self._i = 0
        self.blocks = 0
        self._calm_frames = 0  # calm frames in the current block
        self._calm_from = -1  # block count at which the current run of calm blocks began
        self._calm_last = -1  # block count at the last calm block
        self._var = np.zeros(taxels)  # each taxel's noise variance (of a block mean)
        self._learnt = 0
        self._white: np.ndarray | None = None  # groups times the whitening (taxels x rank)
        self._thr = 0.0
        self._stale = 0  # learning steps since the whitening was computed
        self._last = 0.0
        self._last_at = -1

    def push(self, frame: np.ndarray) -> None:
        j = self._j
        if j == 0:
            self._calm_frames = 0
        if self.every == 1:
            block = frame
        else:
            self._buf[j] = frame
            j += 1
            if j < self.every:
                self._j = j
                return
            block = self._buf.mean(axis=0)
        self._j = 0
        i, n, ring = self._i, self.n, self._ring
        ring[i] = ring[i + n] = block
        self._i = i + 1 if i + 1 < n else 0
        self.blocks += 1

    def calm(self) -> None:
        """The frame just pushed was calm.  Once ``learn_every`` block changes in a row
        are (a block with a frame that was not breaks the run), learn from them."""
        self._calm_frames += 1
        if self._j or self._calm_frames < self.every:
            return
        count = self.blocks
        if self._calm_last != count - 1 or self._calm_from < 0:
            self._calm_from = count
        self._calm_last = count
        run = count - self._calm_from
        if run < self.learn_every:
            return
        i = self._i + self.n
        d = np.diff(self._ring[i - run - 1:i], axis=0)
        self._calm_from = count
        self._learnt += run
        gain = max(run / self._learnt, run * self._a_noise)
        self._var += min(1.0, gain) * ((d * d).sum(axis=0) / (2.0 * run) - self._var)
        self._stale += 1
        if self._white is None or self._stale >= 10:  # the noise moves slowly
            self._whiten()

    def _whiten(self) -> None:
        self._white, rank = sum_whitening(self.groups, self._var)
        self._thr = chi2_threshold(self.z, max(1, rank - 1))
        self._stale = 0

    def set_noise(self, var: np.ndarray) -> None:
        """Use these taxel noise variances (of single frames, as if learnt) from now on."""
        self._var = np.array(var, dtype=float) / self.every
        self._learnt = max(self._learnt, self.min_learnt)
        self._whiten()

    def score(self) -> float:
        count = self.blocks
        if self._j or count == self._last_at:  # mid-block: the last block's, if recent
            return self._last if count - self._last_at <= 1 else 0.0
        self._last_at = count
        white = self._white
        if count < self.n or white is None or self._learnt < self.min_learnt:
            self._last = 0.0
            return 0.0
        i = self._i
        y = (self._w @ self._ring[i:i + self.n]) @ white
        self._last = _score((y @ y.T).tolist(), self.nh, self._sd2, self._thr)
        return self._last
