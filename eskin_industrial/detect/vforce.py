"""Varying-force evidence: is the grip force changing, beyond its noise and faster
than creep?  One statistic for every method (the state it feeds is ``state.py``'s).

A varying normal force (a squeeze, water poured into a held glass, a load swung back
and forth) changes the total force S; a still grip leaves S at a constant plus
noise, and a piezoresistive film's creep moves it by a few percent over many
seconds.  The test is the ramp test of the centre of force (``ramp.py``) applied to
S: for a change that began ``L`` samples ago, the least-squares ramp of the newest
``L`` totals against the mean of the ``B`` before them,

    num_L  = sum_{j=1..L} j (S_{k-L+j} - mean(S_{k-L-B+1} .. S_{k-L}))
    T_L    = |num_L| / (sigma sd_L),     sd_L = sqrt(sum j^2 + (sum j)^2 / B)
    rate_L = |sum_{j=1..L} (j - (L+1)/2) S_{k-L+j}| / C_L x f_s / S_k,   C_L = L (L^2 - 1) / 12
    sd_L   = sigma / sqrt(C_L) x f_s / S_k            (the slope's own noise)
    score  = max over L of min(T_L / z, rate_L / min(min_rate + rate_z sd_L, max_rate))

so the score is 1 at the entry threshold: the change is z standard deviations of
its own noise, and the force's least-squares slope over the horizon is faster than
``min_rate_per_s`` of the grip per second (creep is slower) by ``rate_z`` standard
deviations of the slope's own noise, or faster than ``max_rate_per_s`` whatever
that noise.  The margin matters where the change is significant but slow: a film's
creep after a grab rises 1-2 % of the grip a second, under the 3 % floor, while the
slope of the newest 0.1 s scatters by 2 % a second (10 ms means at 1 kHz) to 7 %
(frames at 100 Hz) and carried the creep over it.  The ceiling matters where the
slope's noise is large (a machine's vibration is learnt as noise): the margin alone
then asked a swinging load for a slope it has only between its turning points, and
let it out at each (docs/evaluation.md, *Film creep after a grab*).  The slope is taken
within the horizon, not against the base: a creep that has gone on for a while
raises the newest samples above the base's mean as a change that began L samples
ago would, but not their slope.  The horizons are times (0.1, 0.2, 0.4 s): the shortest answers a sharp
change first, the longest sees a slow pour that the shorter ones cannot separate
from noise.

``sigma`` is the noise of S learnt while in contact from its second difference,
sigma^2 = mean of (S_k - 2 S_{k-1} + S_{k-2})^2 / 6: a ramp or a slow swing has
almost none, so the noise can be learnt while the force changes, and a varying
force does not teach the test to ignore itself.  (A machine's vibration is learnt
as noise: the test then needs a larger change.)

**The samples are 10 ms means** (``hop_s``): one frame at 100 Hz, ten at 1 kHz, the
horizons, base and noise counted in them.  Frame by frame at 1 kHz, a machine's
50 Hz vibration is smooth: its second difference is (2 pi 50 / 1000)^2, a tenth of
its amplitude, so almost none of it was learnt as noise, while the ramps over 0.1-0.4 s
still saw its residue: the vibration scene's 8 N hold changed state 20 times before its slide
(cof-track; 7 times for the paper's method), none at 100 Hz, where 50 Hz is the
Nyquist frequency and the second difference sees all of it.  On the 10 ms means the
test sees the band it sees at 100 Hz, whatever the rate.  A hop is held if any of
its frames was a held copy; a hop's score stands for its frames until the next
hop's last frame.

A held copy across a gap is no
sample of the noise; it repeats one, which the ramp's sums then count twice, so the
noise used is sigma^2 (1 + 2 f), f the share of held copies among the last max L + B
frames (with a fifth of the frames lost, a still hold otherwise entered the state
about once a minute).

Contact lost: everything is forgotten; the score is 0 until ``max L + B`` frames of
contact (of hops, above 100 Hz) have come.  :class:`ForceVariation` is the streaming form (bounded state:
the last ``max L + B`` totals, three running sums per horizon);
:func:`force_variation_batch` the same over a recording, with no streaming state.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .ramp import ramp_weights
from .settings import VaryingForceSettings


def _centred_j2(length: int) -> float:
    """sum over j = 1..L of (j - (L+1)/2)^2: the least-squares slope's denominator."""
    return length * (length * length - 1) / 12.0


def _rate_test(c: VaryingForceSettings) -> bool:
    """Whether the slope is tested at all (a floor, a margin over its noise, or both)."""
    return c.min_rate_per_s > 0 or c.rate_z > 0


def _rate_scales(c: VaryingForceSettings, horizons: tuple[int, ...],
                 rate_hz: float) -> tuple[list[float], list[float], list[float]]:
    """Per horizon, the rate test's threshold on the centred slope sum
    ``sum (j - (L+1)/2) S_j`` as ``min(a S + b sigma, m S)``: the slope (in samples) is
    that sum over ``C_L = L (L^2 - 1) / 12``, its noise sigma / sqrt(C_L), so
    ``slope x f_s / S > min(min_rate + rate_z sd, max_rate)`` reads ``|sum| >
    min((min_rate C_L / f_s) S + (rate_z sqrt(C_L)) sigma, (max_rate C_L / f_s) S)``."""
    cj2 = [_centred_j2(length) for length in horizons]
    return ([c.min_rate_per_s * v / rate_hz for v in cj2], [c.rate_z * math.sqrt(v) for v in cj2],
            [c.max_rate_per_s * v / rate_hz for v in cj2])


def _hop_of(c: VaryingForceSettings, rate_hz: float) -> int:
    """Frames per sample of the test (one at 100 Hz)."""
    return max(1, round(c.hop_s * rate_hz))


def _geometry(c: VaryingForceSettings, rate_hz: float) -> tuple[tuple[int, ...], int]:
    horizons = tuple(max(2, round(h * rate_hz)) for h in c.horizons_s)
    return horizons, max(2, round(c.base_s * rate_hz))


class ForceVariation:
    """Streaming varying-force score: :meth:`push` each frame's total force, whether it
    is in contact and whether it is a held copy; it returns the frame's score (1 = the
    entry threshold, 0 out of contact and until the test has its history)."""

    def __init__(self, settings: VaryingForceSettings, rate_hz: float) -> None:
        self.hop = _hop_of(settings, rate_hz)
        rate_hz /= self.hop  # the test's own rate: one sample (a hop's mean) per hop
        horizons, base = _geometry(settings, rate_hz)
        _, sd, _ = ramp_weights(horizons, base)
        self.horizons, self.base = horizons, base
        self.n = max(horizons) + base
        self._kb = [length * (length + 1) / 2.0 / base for length in horizons]
        # |num| x this / sigma = T / z
        self._to_z = [1.0 / (float(v) * settings.z) for v in sd]
        self._mid = [(length + 1) / 2.0 for length in horizons]
        # |slope sum| / min(this x S + that x sigma, ceiling x S)
        #   = rate / min(min_rate + rate_z sd_rate, max_rate)
        self._rate_on = _rate_test(settings)
        self._rate_s, self._rate_sigma, self._rate_max = _rate_scales(settings, horizons, rate_hz)
        self._a_noise = 1.0 / max(1.0, settings.noise_s * rate_hz)
        self._resync_every = self.n * max(1, round(500 / self.n))
        self.reset()

    def reset(self) -> None:
        self._ring = [0.0] * self.n  # the last n totals (zeros before the first)
        self._held = [False] * self.n  # which of them are held copies
        self._held_count = 0
        h = len(self.horizons)
        self._w, self._p, self._b = [0.0] * h, [0.0] * h, [0.0] * h
        self._i = 0
        self.count = 0
        self.noise = 0.0  #: learnt variance of S per frame (N^2)
        self._learnt = 0
        self._s1: float | None = None  # the last two totals (None: a held copy, or none)
        self._s2: float | None = None
        # the hop so far: its totals' sum, frames, and whether any was a held copy; the
        # last hop's score, which stands for its frames until the next hop's
        self._acc = 0.0
        self._in = 0
        self._held_in = False
        self._last = 0.0

    def push(self, s: float, contact: bool, filled: bool = False) -> float:
        if not contact:
            if self.count or self._in:
                self.reset()
            return 0.0
        # (hot path: once per frame)
        if self.hop > 1:  # a hop's mean is the test's sample (a hop with a held copy is held)
            self._acc += s
            self._held_in |= filled
            self._in += 1
            if self._in < self.hop:
                return self._last
            s, filled = self._acc / self.hop, self._held_in
            self._acc, self._in, self._held_in = 0.0, 0, False
        s1, s2 = self._s1, self._s2
        if not filled and s1 is not None and s2 is not None:
            d = s - 2.0 * s1 + s2
            self._learnt = learnt = self._learnt + 1
            gain = 1.0 / learnt
            if gain < self._a_noise:
                gain = self._a_noise
            self.noise += gain * (d * d / 6.0 - self.noise)
        self._s2, self._s1 = s1, (None if filled else s)
        i, ring, base = self._i, self._ring, self.base
        w, p, b = self._w, self._p, self._b
        for h, length in enumerate(self.horizons):
            leave = ring[i - length]  # leaves the newest L (joins the base)
            w[h] += length * s - p[h]
            p[h] += s - leave
            b[h] += leave - ring[i - length - base]
        ring[i] = s
        held = self._held
        if held[i] != filled:
            self._held_count += 1 if filled else -1
            held[i] = filled
        self._i = i + 1 if i + 1 < self.n else 0
        self.count = count = self.count + 1
        if count % self._resync_every == 0:
            self._resync()
        noise = self.noise
        if count < self.n or noise <= 0.0:
            self._last = 0.0
            return 0.0
        if self._held_count:
            noise *= 1.0 + 2.0 * self._held_count / self.n
        sigma = math.sqrt(noise)
        inv_sigma = 1.0 / sigma
        rate_on = self._rate_on
        best = 0.0
        for wh, ph, bh, kb, mid, to_z, rs, rsig, rmax in zip(w, p, b, self._kb, self._mid, self._to_z, self._rate_s,
                                                            self._rate_sigma, self._rate_max):
            r = abs(wh - kb * bh) * to_z * inv_sigma
            if rate_on:
                floor = rs * s + rsig * sigma
                if rmax:
                    cap = rmax * s
                    if floor > cap:
                        floor = cap
                rate = abs(wh - mid * ph) / floor
                if rate < r:
                    r = rate
            if r > best:
                best = r
        self._last = best
        return best

    def _resync(self) -> None:
        """Recompute the running sums from the ring, against rounding drift (a whole
        number of rounds has passed: the ring is oldest first)."""
        c = np.asarray(self._ring)
        for h, length in enumerate(self.horizons):
            newest = c[self.n - length:]
            self._w[h] = float(np.arange(1.0, length + 1.0) @ newest)
            self._p[h] = float(newest.sum())
            self._b[h] = float(c[self.n - length - self.base:self.n - length].sum())


def force_variation_batch(s: np.ndarray, contact: np.ndarray, filled: np.ndarray,
                          settings: VaryingForceSettings, rate_hz: float) -> np.ndarray:
    """The score of every frame, with no streaming state: what :class:`ForceVariation`
    must reproduce, frame for frame."""
    s = np.asarray(s, dtype=np.float64)
    contact = np.asarray(contact, dtype=bool)
    filled = np.asarray(filled, dtype=bool)
    hop = _hop_of(settings, rate_hz)
    weights = _Weights.of(settings, rate_hz / hop)  # (at the test's own rate)
    out = np.zeros(len(s))
    m = np.concatenate(([False], contact, [False]))
    edges = np.flatnonzero(m[1:] != m[:-1])
    for a, b in zip(edges[::2], edges[1::2]):  # each run of contact starts afresh
        run, held = s[a:b], filled[a:b]
        if hop == 1:
            out[a:b] = _sample_scores(run, held, settings, weights)
            continue
        # each whole hop's mean, its frames added in the order they came (as the
        # stream adds them); a hop with a held copy is held
        k = len(run) // hop
        if not k:
            continue
        means = run[0:k * hop:hop].copy()
        for j in range(1, hop):
            means += run[j:k * hop:hop]
        means /= hop
        held_hops: np.ndarray = held[:k * hop].reshape(k, hop).max(axis=1)
        scores = _sample_scores(means, held_hops, settings, weights)
        # a hop's score stands from its last frame until the next hop's
        which = (np.arange(len(run)) + 1) // hop - 1
        out[a:b] = np.where(which >= 0, scores[np.maximum(which, 0)], 0.0)
    return out


class _Weights(NamedTuple):
    """What the batch test needs of its geometry, worked out once per recording."""

    g: np.ndarray  #: the ramps' weights, per horizon (oldest first)
    sd: np.ndarray  #: their noise per unit sample noise
    slope: np.ndarray  #: the least-squares slope sum of the newest L, per horizon (rows like g's)
    rate_s: np.ndarray  #: the rate test's threshold per unit S, per horizon ...
    rate_sigma: np.ndarray  #: ... and per unit noise sigma ...
    rate_max: np.ndarray  #: ... at most this per unit S (0: no ceiling)
    a_noise: float  #: the noise learner's least gain

    @classmethod
    def of(cls, settings: VaryingForceSettings, rate_hz: float) -> _Weights:
        horizons, base = _geometry(settings, rate_hz)
        g, sd, _ = ramp_weights(horizons, base)
        n = g.shape[1]
        slope = np.zeros_like(g)
        for h, length in enumerate(horizons):
            slope[h, n - length:] = np.arange(1.0, length + 1.0) - (length + 1) / 2.0
        rate_s, rate_sigma, rate_max = _rate_scales(settings, horizons, rate_hz)
        return cls(g, sd, slope, np.array(rate_s), np.array(rate_sigma), np.array(rate_max),
                   1.0 / max(1.0, settings.noise_s * rate_hz))


def _sample_scores(run: np.ndarray, held: np.ndarray, settings: VaryingForceSettings, w: _Weights) -> np.ndarray:
    """The score of each sample of one run of contact (totals, or hop means at the
    test's own rate)."""
    g, sd = w.g, w.sd
    n = g.shape[1]
    out = np.zeros(len(run))
    # the noise: a running mean of the squared second difference over 6, from samples
    # whose two predecessors (and themselves) are no held copies
    usable = np.zeros(len(run), bool)
    usable[2:] = ~held[2:] & ~held[1:-1] & ~held[:-2]
    d2 = (run[2:] - 2.0 * run[1:-1] + run[:-2]) ** 2 / 6.0
    learnt = running_mean(d2[usable[2:]], w.a_noise)
    last = np.cumsum(usable) - 1  # how many usable samples so far, less one
    noise = np.where(last >= 0, learnt[np.maximum(last, 0)] if learnt.size else 0.0, 0.0)
    if len(run) < n:
        return out
    num = np.abs(_against_rows(run, g))
    held_n = np.convolve(held.astype(float), np.ones(n), mode="valid")  # held copies among the last n
    sigma = np.sqrt(noise[n - 1:] * (1.0 + 2.0 * held_n / n))
    with np.errstate(divide="ignore", invalid="ignore"):
        score = num / (sd * settings.z) / sigma[:, None]
        if _rate_test(settings):
            rate = np.abs(_against_rows(run, w.slope))
            floor = w.rate_s * run[n - 1:, None] + w.rate_sigma * sigma[:, None]
            if settings.max_rate_per_s > 0:
                floor = np.minimum(floor, w.rate_max * run[n - 1:, None])
            score = np.minimum(score, rate / floor)
    out[n - 1:] = np.where(noise[n - 1:] > 0, score.max(axis=1), 0.0)
    return out


def _against_rows(x: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """(frames from n - 1 on, rows): each row (oldest first, n long) against the newest n
    values, correlated over the row's nonzero tail only."""
    n = rows.shape[1]
    out = np.empty((len(x) - n + 1, len(rows)))
    for h, row in enumerate(rows):
        start = int(np.flatnonzero(row)[0]) if row.any() else n - 1
        out[:, h] = np.correlate(x[start:], row[start:], mode="valid")
    return out


def running_mean(x: np.ndarray, a: float) -> np.ndarray:
    """The stream's learner after each value of ``x``: q += max(1 / m, a) (x_m - q), from
    q = 0: the plain mean while 1 / m >= a, then an exponential mean of gain ``a``.
    Vectorized in blocks short enough that the powers of (1 - a) stay well scaled."""
    x = np.asarray(x, dtype=np.float64)
    out = np.empty(len(x))
    if not len(x):
        return out
    head = min(len(x), int(math.floor(1.0 / a)) if a > 0 else len(x))  # 1 / m >= a up to here
    out[:head] = np.cumsum(x[:head]) / np.arange(1, head + 1)
    r = 1.0 - a
    if head == len(x):
        return out
    if r <= 0.0:
        out[head:] = x[head:]
        return out
    block = int(min(4096, max(1, 20.0 / -math.log(r))))  # r^-block <= e^20
    q = out[head - 1] if head else 0.0
    for i in range(head, len(x), block):
        chunk = x[i:i + block]
        k = np.arange(1, len(chunk) + 1)
        rk = r ** k
        # q_k = r^k q + a sum_{j<=k} r^(k-j) x_j
        out[i:i + len(chunk)] = rk * (q + a * np.cumsum(chunk / rk))
        q = out[i + len(chunk) - 1]
    return out
