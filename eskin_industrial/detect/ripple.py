"""Stick-slip evidence in the total force, for ``cof-track``'s ramp channel.

An object that starts to slide does not glide: it sticks and slips, and each slip
shakes the normal force a little (the vibration the paper's wavelet detail looks for
in the centre of force).  In the *total* force those shakes add up coherently over
the taxels while the taxels' noise adds up only in power, so the total is where they
stand out most.

The statistic is the energy of the total force's change over a fixed lag (``lag``
samples: a band in time, so that it means the same at 100 Hz and at 1 kHz), averaged
over the last ``window`` samples, against its learnt calm level ``q``:

    d_k   = S_k - S_{k-lag}
    ratio = mean(d^2 over the window) / q
    e     = (dof / 2) (ratio - 1 - ln ratio)   if ratio > 1, else 0        (nats)

``e`` is the generalized likelihood ratio of "the variance rose by ``ratio``" against
"it did not", for ``dof`` independent samples (the window over the lag).  It is
evidence, not a decision: the ramp channel adds it to its own log-likelihood ratio,
so stick-slip lets a slide through with less displacement, and nothing else does.
A steady vibration of the machine raises ``q`` with it (it is learnt while the grip is
calm), and the ramp channel is silent while the force itself changes.

Used alone, a variance test on a handful of samples has a heavy tail (first
differences of white noise are correlated): docs/evaluation.md shows why the evidence
only ever adds to the displacement's.
"""

from __future__ import annotations

import math


def variance_evidence(ratio: float, dof: float) -> float:
    """Nats for a variance ``ratio`` times its calm level over ``dof`` samples (0 below 1)."""
    if not ratio > 1.0:
        return 0.0
    return 0.5 * dof * (ratio - 1.0 - math.log(ratio))


def ripple_dof(lag: int, window: int) -> float:
    """Independent samples in the mean of ``window`` squared changes over ``lag`` of
    white noise: two changes ``lag`` apart share a sample (their squares correlate by
    1/4), so ``2 W^2 / (2 W + max(0, W - lag))``; 4.2, not 6, for six changes at lag 1.
    Counting 6 made every burst of noise strong evidence: on the light hand grip it
    raised a false alarm every hour and a half (docs/evaluation.md)."""
    return 2.0 * window * window / (2.0 * window + max(0, window - lag))


class ForceRipple:
    """Streaming energy of ``S_k - S_{k-lag}`` over the last ``window`` samples.

    ``push(s)`` returns the change's square (for learning its calm level) and keeps the
    window's mean in :attr:`energy` (``None`` until the window is full)."""

    def __init__(self, lag: int, window: int) -> None:
        self.lag = max(1, lag)
        self.window = max(1, window)
        self.reset()

    def reset(self) -> None:
        self._s = [0.0] * self.lag  # the last ``lag`` totals, a ring (index: pushes mod lag)
        self._pushed = 0
        self._d2: list[float] = [0.0] * self.window
        self._i = 0
        self._sum = 0.0
        self._n = 0
        self.energy: float | None = None

    def push(self, s: float, held: float | None = None) -> float | None:
        """Add a total.  ``held``: the value to count instead of the change (a held copy
        across a gap carries none of its own); ``None`` until ``lag`` totals are in."""
        pushed = self._pushed
        self._pushed = pushed + 1
        totals = self._s
        slot = pushed % self.lag
        old = totals[slot]
        totals[slot] = s
        if pushed < self.lag:
            return None
        d2 = (s - old) ** 2 if held is None else held
        i, ring = self._i, self._d2
        self._sum += d2 - ring[i]
        ring[i] = d2
        i += 1
        window = self.window
        if i == window:  # once a round, against the running sum's rounding drift
            i = 0
            self._sum = math.fsum(ring)
        self._i = i
        n = self._n = self._n + 1
        self.energy = self._sum / window if n >= window else None
        return d2
