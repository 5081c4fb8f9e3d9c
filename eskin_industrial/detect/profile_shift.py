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

The cost per frame is one matrix product (the profile of the frame) and a store in a
ring; the test itself runs once per ``every`` frames (the detector's hop) as one
product over the ring, and the noise is learnt once per calm hop, so its cost per frame
is the same at 100 Hz and at 1 kHz.  :func:`profile_batch` is the same test over a
whole series, with a given noise, for the tests.
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


def whitening(cov: np.ndarray) -> tuple[np.ndarray, int]:
    """The pseudo-inverse of a noise covariance and its rank (eigenvalues below 1e-9 of
    the largest count as none: the total is shared by both axes' sums)."""
    vals, vecs = np.linalg.eigh(0.5 * (cov + cov.T))
    top = float(vals[-1]) if len(vals) else 0.0
    if not top > 0.0:
        return np.zeros_like(cov), 0
    keep = vals > 1e-9 * top
    v = vecs[:, keep]
    return (v / vals[keep]) @ v.T, int(keep.sum())


def _scores(num: np.ndarray, ref: np.ndarray, cinv: np.ndarray, sd2: np.ndarray) -> np.ndarray:
    """T_L^2 for each row of num (H, m) against its reference row."""
    a = num @ cinv
    b = ref @ cinv
    rr = np.einsum("hm,hm->h", ref, b)
    rn = np.einsum("hm,hm->h", ref, num)
    nn = np.einsum("hm,hm->h", num, a)
    with np.errstate(invalid="ignore", divide="ignore"):
        t2 = nn - np.where(rr > 0.0, rn * rn / rr, 0.0)
    return np.maximum(t2, 0.0) / sd2


def _weights(horizons: tuple[int, ...], base: int) -> tuple[np.ndarray, np.ndarray]:
    """Rows: each horizon's ramp weights, then each horizon's base mean (oldest first);
    and sd_L^2."""
    g, sd, _ = ramp_weights(horizons, base)
    n = g.shape[1]
    means = np.zeros_like(g)
    for h, length in enumerate(horizons):
        means[h, n - length - base:n - length] = 1.0 / base
    return np.vstack([g, means]), sd * sd


def profile_batch(p: np.ndarray, cov: np.ndarray, horizons: tuple[int, ...], base: int, z: float) -> np.ndarray:
    """The score (1 = threshold) at every sample of a (K, m) profile series under a
    fixed noise covariance, with no streaming state: what :class:`ProfileShift` must
    reproduce (NaN until N = max L + B profiles)."""
    w, sd2 = _weights(horizons, base)
    nh, n = len(horizons), w.shape[1]
    cinv, rank = whitening(cov)
    thr = chi2_threshold(z, max(1, rank - 1))
    out = np.full(len(p), np.nan)
    for k in range(n - 1, len(p)):
        both = w @ p[k - n + 1:k + 1]
        out[k] = math.sqrt(float(np.max(_scores(both[:nh], both[nh:], cinv, sd2))) / thr)
    return out


class ProfileShift:
    """Streaming :func:`profile_batch`, with the noise learnt as it goes.

    ``push(frame)`` once a frame (not for held copies); ``calm()`` after a frame the
    detector judged calm (runs of calm changes teach the noise); ``score()`` returns
    the test's score, computed on every ``every``-th push (0 until the ring is full
    and a ring's worth of changes has been learnt).

    The ring holds the raw frames: a push is one store, and an evaluation is two
    products over the ring's two halves (no copy), then one with the groups and the
    whitening folded into one matrix, and the 2H x 2H Gram matrix of the result, whose
    diagonals hold every inner product the test needs."""

    def __init__(self, groups: np.ndarray, horizons: tuple[int, ...], base: int, z: float,
                 every: int, noise_n: int) -> None:
        self.groups = groups
        self.m = groups.shape[1]
        self._w, sd2 = _weights(horizons, base)
        self._sd2 = sd2.tolist()
        self.nh = len(horizons)
        self.n = self._w.shape[1]
        self.z = z
        self.every = max(1, every)
        self.learn_every = max(self.every, self.n // 4)  # changes per learning step
        self._a_noise = 1.0 / max(1.0, noise_n)  # the learning's smallest gain per change
        self.min_learnt = self.n
        self.reset()

    def reset(self) -> None:
        self._ring = np.zeros((self.n, self.groups.shape[0]))
        self._i = 0
        self.count = 0
        self._calm_from = -1  # push count at which the current run of calm frames began
        self._calm_last = -1  # push count at the last calm frame
        self._var = np.zeros(self.groups.shape[0])  # each taxel's noise variance
        self._learnt = 0
        self._white: np.ndarray | None = None  # groups times the whitening (taxels x rank)
        self._thr = 0.0
        self._stale = 0  # learning steps since the whitening was computed
        self._last = 0.0
        self._last_at = -1

    def push(self, frame: np.ndarray) -> None:
        i = self._i
        self._ring[i] = frame
        self._i = i + 1 if i + 1 < self.n else 0
        self.count += 1

    def _ordered(self, k: int) -> np.ndarray:
        """The newest ``k`` frames (k <= n), oldest first."""
        i, ring = self._i, self._ring
        if k <= i:
            return ring[i - k:i]
        return np.concatenate((ring[self.n - (k - i):], ring[:i]))

    def calm(self) -> None:
        """The frame just pushed was calm: once ``learn_every`` changes in a row are (a
        frame not followed by ``calm()`` breaks the run), learn the noise from them."""
        count = self.count
        if self._calm_last != count - 1 or self._calm_from < 0:
            self._calm_from = count
        self._calm_last = count
        run = count - self._calm_from
        if run < self.learn_every:
            return
        d = np.diff(self._ordered(run + 1), axis=0)
        self._calm_from = count
        self._learnt += run
        gain = max(run / self._learnt, run * self._a_noise)
        self._var += min(1.0, gain) * ((d * d).sum(axis=0) / (2.0 * run) - self._var)
        self._stale += 1
        if self._white is None or self._stale >= 10:  # the noise moves slowly
            self._whiten()

    def _whiten(self) -> None:
        # taxels' noise independent: the sums' covariance follows from the taxels'
        # variances, far steadier than a covariance learnt entry by entry (with a few
        # hundred changes that one's small eigenvalues came out low, and the
        # test's tail fired on a still grip)
        cov = self.groups.T @ (self._var[:, None] * self.groups)
        vals, vecs = np.linalg.eigh(cov)
        top = float(vals[-1]) if len(vals) else 0.0
        keep = vals > 1e-9 * top if top > 0.0 else np.zeros(len(vals), dtype=bool)
        rank = int(keep.sum())
        # C+ = L L' with L = V / sqrt(lambda): whitened profiles are frames @ (groups L)
        self._white = self.groups @ (vecs[:, keep] / np.sqrt(vals[keep])) if rank else None
        self._thr = chi2_threshold(self.z, max(1, rank - 1))
        self._stale = 0

    def set_noise(self, var: np.ndarray) -> None:
        """Use these taxel noise variances (as if learnt) from now on."""
        self._var = np.array(var, dtype=float)
        self._learnt = max(self._learnt, self.min_learnt)
        self._whiten()

    def score(self) -> float:
        count = self.count
        if count == self._last_at:
            return self._last
        if count % self.every:  # between evaluations: the last one, if it is this hop's
            return self._last if count - self._last_at < self.every else 0.0
        self._last_at = count
        white = self._white
        if count < self.n or white is None or self._learnt < self.min_learnt:
            self._last = 0.0
            return 0.0
        i, w, ring = self._i, self._w, self._ring
        # the ring's oldest frame sits at i: weights' first n - i columns go with ring[i:]
        y = (w[:, :self.n - i] @ ring[i:] + w[:, self.n - i:] @ ring[:i]) @ white
        gram = (y @ y.T).tolist()
        nh, thr = self.nh, self._thr
        best = 0.0
        for h in range(nh):
            row, ref = gram[h], gram[nh + h]
            rr = ref[nh + h]
            t2 = row[h] - (row[nh + h] ** 2 / rr if rr > 0.0 else 0.0)
            t2 /= self._sd2[h] * thr
            if t2 > best:
                best = t2
        self._last = math.sqrt(best)
        return self._last
