"""Rival ``cof-step``: the plain displacement test, a yardstick for delay claims.

The newest ``step_s`` of the centre of force (two frames at 100 Hz) against its mean
and standard deviation over the ``base_s`` (0.5 s) that ended ``gap_s`` (0.1 s)
before the newest frame:

    m     = mean of the centres of the newest step_s
    mu, sd = mean and standard deviation of the centres over the base, per axis
    score = |((m_x - mu_x) / sd_x, (m_y - mu_y) / sd_y)| / threshold      (slip above 1)

No model of the motion (a ramp, a step), no learnt noise beyond the base's own
spread, no silence while the force changes: whatever moved the CoF further than its
recent scatter is slip.  Its threshold is chosen for the same false-alarm rate over
the tuning holds as ``cof-track`` (docs/evaluation.md), so that the two can be
compared at equal false alarms: an honest check on any claim that a delay is the
physics' and not the method's.

The test is taken once per 10 ms (every frame at 100 Hz), so that its tests per hour
do not grow with the rate; its centres start once the grab has settled
(``settle_s``), and a held copy across a gap is no sample.  Running sums per axis
(about a reference, renewed with the sums from the ring every few hundred pushes, so
that the variance keeps its digits).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from .scored import ScoredDetector
from .settings import DetectorSettings

#: the smallest standard deviation an axis is divided by (mm): a strip's CoF across
#: its one row does not move at all
SD_FLOOR_MM = 1e-3


class CofStep(ScoredDetector):
    name = "cof-step"
    columns = ("step_score", "unused")
    settle_s = 0.15  #: the grab settles this long before centres count (cof-track's)

    def __init__(self, settings: DetectorSettings, x_mm: np.ndarray, y_mm: np.ndarray, rate_hz: float,
                 **overrides: float) -> None:
        c = replace(settings.cof_step, **overrides) if overrides else settings.cof_step
        self.threshold = c.threshold
        self.newest = max(1, round(c.step_s * rate_hz))
        self.gap = max(self.newest, round(c.gap_s * rate_hz))
        self.base = max(2, round(c.base_s * rate_hz))
        self._len = self.gap + self.base  # the ring: the base, then the gap up to the newest
        self._settle = max(0, round(self.settle_s * rate_hz))
        self._resync_every = self._len * max(1, round(500 / self._len))
        super().__init__(settings, x_mm, y_mm, rate_hz, hop_s=c.hop_s, confirm=1)

    def reset_scores(self) -> None:
        self._x = [0.0] * self._len
        self._y = [0.0] * self._len
        self._i = 0  # the oldest slot, about to be overwritten
        self._count = 0
        self._seen = 0  # frames in contact since the reset
        self._ref = (0.0, 0.0)
        # sums over the base (about the reference) and over the newest ``newest``
        self._bx = self._by = self._bxx = self._byy = 0.0
        self._nx = self._ny = 0.0

    def _resync(self) -> None:
        """The sums again from the ring, about the base's current mean."""
        order = [(self._i + j) % self._len for j in range(self._len)]  # oldest first
        xs = [self._x[j] for j in order]
        ys = [self._y[j] for j in order]
        bx, by = xs[:self.base], ys[:self.base]
        rx, ry = math.fsum(bx) / self.base, math.fsum(by) / self.base
        self._ref = (rx, ry)
        self._bx = math.fsum(v - rx for v in bx)
        self._by = math.fsum(v - ry for v in by)
        self._bxx = math.fsum((v - rx) ** 2 for v in bx)
        self._byy = math.fsum((v - ry) ** 2 for v in by)
        self._nx = math.fsum(v - rx for v in xs[self._len - self.newest:])
        self._ny = math.fsum(v - ry for v in ys[self._len - self.newest:])

    def _push(self, xc: float, yc: float) -> None:
        n, i = self._len, self._i
        rx, ry = self._ref
        x, y = xc - rx, yc - ry
        ring_x, ring_y = self._x, self._y
        # the sample that leaves the ring leaves the base; the one ``gap`` pushes old
        # enters it; the one ``newest`` pushes old leaves the newest
        ox, oy = ring_x[i] - rx, ring_y[i] - ry
        j = (i + self.base) % n  # (the ring holds the base's samples first, oldest first)
        ex, ey = ring_x[j] - rx, ring_y[j] - ry
        k = (i + n - self.newest) % n
        lx, ly = ring_x[k] - rx, ring_y[k] - ry
        if not self._count:  # the sums are kept about the first centre until the first renewal
            self._ref = (xc, yc)
            rx, ry = xc, yc
            x = y = 0.0
        if self._count >= n:
            self._bx += ex - ox
            self._by += ey - oy
            self._bxx += ex * ex - ox * ox
            self._byy += ey * ey - oy * oy
        elif self._count >= self.gap:  # the base fills up
            self._bx += ex
            self._by += ey
            self._bxx += ex * ex
            self._byy += ey * ey
        self._nx += x - (lx if self._count >= self.newest else 0.0)
        self._ny += y - (ly if self._count >= self.newest else 0.0)
        ring_x[i], ring_y[i] = xc, yc
        self._i = (i + 1) % n
        self._count += 1
        if self._count % self._resync_every == 0:
            self._resync()

    def statistic(self) -> float:
        """The step's distance from the base's mean in its standard deviations (0 until
        the ring is full)."""
        if self._count < self._len:
            return 0.0
        b = self.base
        mx, my = self._bx / b, self._by / b
        vx = max(self._bxx / b - mx * mx, 0.0) * b / (b - 1)
        vy = max(self._byy / b - my * my, 0.0) * b / (b - 1)
        fl = SD_FLOOR_MM * SD_FLOOR_MM
        dx = self._nx / self.newest - mx
        dy = self._ny / self.newest - my
        return math.sqrt(dx * dx / max(vx, fl) + dy * dy / max(vy, fl))

    def score(self, t: float, f: np.ndarray, s: float, xc: float, yc: float) -> tuple[float, float, bool, bool]:
        seen = self._seen = self._seen + 1
        if seen > self._settle and not self.filled:  # (a held copy is no sample)
            self._push(xc, yc)
        if (self._k + 1) % self.hop:  # tested once a hop, on the frame the decision reads
            return 0.0, 0.0, False, False
        z = self.statistic() / self.threshold
        return z, 0.0, z > 1.0, False
