"""Our method: track the centre of force against its own noise.

Why (see docs/evaluation.md for the measurements): the paper's indicators are
ratios of two overlapping windows, so a slide whose onset is gradual, a slow creep,
or sustained sliding keep the ratio near 1, while at a still grasp the ratio of two
noise numbers jumps.  A slide, however, always *moves* the pressure distribution,
and a varying normal force (a squeeze, a glass being moved) scales it in place.  So:

    m_k  = mean of the last M centres of force                 (M = smooth_s x f_s)
    D_f  = |m_k - m_{k-Lf}|                                   (fast horizon)
    D_s  = |u|, u = m_k - m_{k-Ls}; and onward = (m_k - m_{k-Ls/2}) . u/|u|   (slow, still moving)
    q    = running mean of S_k^2 |c_k - c_{k-1}|^2 / 2, learnt while calm
    s    = sqrt(q) / S_k                      (CoF noise: the force noise spread over S)
    n    = z s sqrt(2/M)                          (the displacement noise, z standard deviations)
    a    = D_f / max(n, min_fast_mm)
    b    = min(D_s / T, onward / max(T/2, 0.75 n)),   T = max(n, min_slow_mm)
    r    = the ramp channel (detect/ramp.py): a least-squares ramp in the raw CoF against
           the mean before it, over a bank of horizons, each axis in units of ramp_z of
           its own noise (q_x, q_y learnt like q); only while the force is steady, and
           taken once a hop (10 ms) at any rate, so that its tests per hour do not grow
           with the rate
    e    = stick-slip evidence (detect/ripple.py): a rise in the energy of the total
           force's 10 ms change, as a log-likelihood ratio added to the ramp's; capped so
           that the ramp still needs ramp_support_z of its own
    p    = the profile channel (detect/profile_shift.py; off unless profile_shift): the
           ramp test on the column and row sums, a change of force projected out; taken
           into r (r = max(r, p)) while the force is steady and not in variable_force
    t    = the torsion channel (detect/torsion.py): the same ramp test on the angle of
           the distribution's rotational flow about the CoF (a turn about the normal
           keeps the CoF and the total); only while the force is steady
    j    = the step channel (detect/step.py): the newest 20 ms of the CoF against its
           mean over the half-second that ended 100 ms earlier, each centre weighed by
           its own total, against the difference's own learnt noise (never below
           q's), with e added as for
           the ramp; taken into r (r = max(r, j)).  Its silence for a varying force is
           the ramp's rule on the force's level (0.1 s and 0.5 s means): a stick-slip
           ripple about a constant level, which the 30 ms means of the ramp's silence
           follow, leaves it open, so a slide in jumps is seen in frames
    g    = the onward gate (onward_open = 0.25; 0: none): while the force is not steady
           and its total onward_fall (5 %) below its last steady level (the level
           onward_fall_s before the last steady frame: a sudden fall reads as steady
           for its first frames), r and j stay open if the centre has moved over the
           fast horizon by onward_open of a's threshold, onward (its newer half
           onward_share of the way), on no held copy nor the frame after one, once the
           total has fallen onward_fall within onward_fall_s (30 ms) since it was last
           steady; once open, open until the force is steady again: a slide whose grip
           gives way at onset, where a squeeze's centre stays and a sway's total falls
           slowly; and shut, until the force is steady again, once the total is back at
           its steady level: a drop stays down, a shake (whose lower halves fall as fast
           as a drop) comes back up
    beta = the total as a covariate (off by default: force_covariate = 0): the coupling
           of the centre's change to the total's over the fast horizon, learnt from calm
           stretches once the force has been steady; a, b, r, j and g then test
           c - beta S (a soft pad's centre that follows its force, a swaying glass, is
           explained away)
    slip when a > 1, b > 1, r > 1 or t > 1 (r and t only while the force is steady);
    in the slip state, also while a, b or r stays above 1 - hysteresis (0.8): a slow
    slide's evidence fades in and out as it stops.  (The CoF's step energy was a vote
    too, until it was found to add only false alarms: docs/evaluation.md.)

The cost per frame is one 4-column matrix product (the total, the centre of force and
the torsion channel's projection), three running sums per ramp horizon, a ring of
squared changes for the evidence, eight running sums for the step channel and a few
scalar operations (the torsion channel's
angle once per 40 ms, its template once per 0.25 s): the
same at 100 Hz and at 1 kHz.  The scores (score_a, score_b) are max(a, r, t) and b (1 = threshold).
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np

from .profile_shift import ProfileShift, profile_groups
from .ramp import RampBank
from .ripple import ForceRipple, ripple_dof, variance_evidence
from .scored import ScoredDetector
from .settings import DetectorSettings
from .state import GraspState
from .step import StepTest
from .torsion import TurnFlow, grid_of

_SLIP = int(GraspState.SLIP)


class CofTrack(ScoredDetector):
    name = "cof-track"
    columns = ("onset_score", "slow_score")  # onset: max(a, r)
    #: no vote until the noise has been learnt for a while after the grab settled
    history_s = 0.35
    settle_s = 0.15

    def __init__(self, settings: DetectorSettings, x_mm: np.ndarray, y_mm: np.ndarray, rate_hz: float,
                 **overrides: Any) -> None:
        """Settings from ``settings.cof_track``; keyword arguments override single
        fields (for parameter sweeps)."""
        c = replace(settings.cof_track, **overrides) if overrides else settings.cof_track
        self.m = max(1, round(c.smooth_s * rate_hz))
        self.lf = max(1, round(c.fast_s * rate_hz))
        self.ls = max(self.lf + 1, round(c.slow_s * rate_hz))
        self._half = self.ls // 2  # (the half-slow lag)
        self._half_fast = max(1, self.lf // 2)  # (the onward gate's half-fast lag)
        self._onward_open, self._onward_share = c.onward_open, c.onward_share
        self._onward_below = 1.0 - c.onward_fall  # (the total's share of its steady level the gate opens under)
        # (the lag the gate's sudden fall is looked for over, 0: any fall opens it; and
        # the fall's least square, times the total's learnt noise)
        self._fall_lag = min(self.ls - 1, max(1, round(c.onward_fall_s * rate_hz))) if c.onward_fall_s > 0 else 0
        self._fall_z2 = c.onward_fall_z * c.onward_fall_z * 2.0 / self.m
        self._covariate = c.force_covariate  # (0: the channels test the raw centre)
        self.z = c.z
        self.min_fast, self.min_slow = c.min_fast_mm, c.min_slow_mm
        self.force_rate = c.force_rate_per_s
        self.fast_s = c.fast_s
        self._a_noise = 1.0 / max(1.0, c.noise_s * rate_hz)
        self._settle = max(1, round(self.settle_s * rate_hz))
        # frames since a reset before the settling time has passed: the first frame
        # that gets this far (with a previous centre and m of them) is max(1, m - 1)
        self._settled = max(1, self.m - 1) + self._settle
        self._steady_n = max(1, round(1.0 * rate_hz))
        self.ramp_min = c.ramp_min_mm
        horizons = tuple(max(2, round(h * rate_hz)) for h in c.ramp_horizons_s)
        base = max(2, round(c.ramp_base_s * rate_hz))
        self._ramp = RampBank(horizons, base, c.ramp_z)
        # force_covariate: the same ramp and step geometry on the total force
        self._ramp_s = RampBank(horizons, base, c.ramp_z) if c.force_covariate > 0.0 else None
        groups = profile_groups(x_mm, y_mm)  # (its test runs on hop means: horizons in hops)
        self._profile = ProfileShift(
            groups, tuple(max(2, round(h / c.hop_s)) for h in c.ramp_horizons_s), max(2, round(c.ramp_base_s / c.hop_s)),
            c.profile_z, every=max(1, round(c.hop_s * rate_hz)), noise_n=round(c.noise_s / c.hop_s),
        ) if c.profile_shift and groups.size else None
        # the ripple's lag and window are times, so that it sees the same band at any rate
        lag = max(1, round(c.ripple_lag_s * rate_hz))
        window = max(1, round(c.ripple_s * rate_hz))
        self._ripple = ForceRipple(lag, window) if c.ripple_s > 0 else None
        self._ripple_dof = ripple_dof(lag, window)
        self._evidence_cap = 0.5 * max(0.0, c.ramp_z ** 2 - c.ramp_support_z ** 2)
        # the step channel (detect/step.py): a jump of the CoF against where it was, beside
        # the ramp bank, its noise its own (learnt like q); the evidence is capped for it
        # as for the ramp: the step must reach ramp_support_z itself
        geometry = (max(1, round(c.step_s * rate_hz)), round(c.step_gap_s * rate_hz),
                    max(1, round(c.step_base_s * rate_hz)))
        self._jumps = StepTest(*geometry) if c.step_s > 0 else None
        # force_covariate: the same step on the total force
        self._jumps_s = StepTest(*geometry) if c.step_s > 0 and c.force_covariate > 0.0 else None
        self._step_z = c.step_z
        self._step_cap = 0.5 * max(0.0, c.step_z ** 2 - c.ramp_support_z ** 2)
        # its learnt noise per axis in force units (N^2 mm^2, like q): d^2 / w, which
        # white noise makes q's own; the learning starts at q, counted as a base's worth
        # of samples, and never goes below it (a few hundred correlated differences
        # alone came out low at times: a grip's first seconds raised false alarms)
        self._step_vx = self._step_vy = 0.0
        self._step_learnt = 0
        jumps = self._jumps
        self._step_prior = jumps.base if jumps is not None else 0
        # the step's silence for a varying force (below), squared: the change that counts
        # as varying per newton of grip, and the level change's noise per unit of the
        # total's learnt noise, in z standard deviations
        self._level_rate = c.force_rate_per_s * c.fast_s
        self._level_noise = c.z * c.z * jumps.level_weight if jumps is not None else 0.0
        # the torsion channel (detect/torsion.py): a turn keeps the CoF and the total
        # (it works on each of its hops' mean: its times count them)
        grid = grid_of(x_mm, y_mm) if c.torsion else None
        hop = max(1, round(c.torsion_hop_s * rate_hz))
        hops = rate_hz / hop  # per second
        self._turn = None if grid is None else TurnFlow(
            *grid, hop, round(c.torsion_ref_s / c.torsion_blocks * hops), c.torsion_blocks,
            tuple(max(2, round(h * hops)) for h in c.ramp_horizons_s), max(2, round(c.ramp_base_s * hops)),
            c.torsion_z, round(c.noise_s * hops), c.torsion_min_visibility, c.torsion_min_footprint,
            math.radians(c.torsion_min_deg))
        self.turn_score = 0.0
        self.fast_score = self.ramp_score = 0.0  # the two parts of the first column
        self._noise: float | None = None  # learnt CoF noise, in force units (N^2 mm^2)
        self._noise_x = 0.0  # the part of it along x (sigma_x^2 S^2)
        self._fnoise = 0.0  # learnt noise of the total force (N^2)
        self._rnoise = 0.0  # learnt calm level of the ripple's squared change (N^2)
        self._keep = 1.0 - settings.hysteresis  # the scores' level that keeps a slip
        super().__init__(settings, x_mm, y_mm, rate_hz, hop_s=c.hop_s, confirm=1)

    def reset_scores(self) -> None:
        self._win: list[tuple[float, float, float]] = [(0.0, 0.0, 0.0)] * self.m  # the last m (x, y, S)
        self._sx = self._sy = self._ss = 0.0
        self._cnt = 0
        # one ring of the smoothed (x, y, S), read at the fast, half-slow and slow lags
        self._hist: list[tuple[float, float, float]] = [(0.0, 0.0, 0.0)] * self.ls
        self._hn = 0
        self._prev: tuple[float, float, float] | None = None
        self._calm_force = 0
        # the total as a covariate (force_covariate): the learnt moments (dx dS, dy dS,
        # dS^2 over the fast horizon; the frame-to-frame noise's own dx dS / 2, dy dS / 2)
        # and the coupling beta they give, learnt from blocks that were calm and followed
        # by one
        self._cov = [0.0] * 5
        self._cov_count = 0  # frames committed
        self._block = [0.0] * 5  # the current block's sums, its frames learnt, its length so far
        self._block_learnt = self._block_len = 0
        self._block_moved = False
        self._candidate: tuple[list[float], int] | None = None  # the last calm block, not yet committed: (sums, frames learnt)
        self._beta_x = self._beta_y = 0.0
        self._held = False  # the force has been steady once since the grab (not the grab's own change)
        self._steady_level: float | None = None  # the smoothed total at the last steady frame (the gate's)
        self._was_filled = False  # the last frame was a held copy
        self._latched = False  # the gate has opened since the force was last steady
        self._armed = False  # the total fell fast since the force was last steady (onward_fall_s)
        self._spent = False  # the total has been back at its steady level since (the gate stays shut)
        self._ramp_on = False  # the ramp's verdict at the last hop's end
        self._ramp.reset()
        self._level_calm = 0  # frames since the force's level last moved (the step's silence)
        if self._jumps is not None:
            self._jumps.reset()
        if self._ramp_s is not None:
            self._ramp_s.reset()
        if self._jumps_s is not None:
            self._jumps_s.reset()
        if self._profile is not None:
            self._profile.reset()
        if self._turn is not None:
            self._turn.reset()
        if self._ripple is not None:
            self._ripple.reset()

    #: whether :meth:`_stepped` is wanted (a subclass's; no call a frame for nothing)
    _keeps_steps = False

    def _stepped(self, step2: float) -> None:
        """Each scored frame's CoF step energy (S^2 |c_k - c_{k-1}|^2 / 2; a held copy's:
        the learnt noise), for a subclass that sets :attr:`_keeps_steps`: the learned
        method's feature (cof-track itself no longer votes on it: docs/evaluation.md)."""

    def _evidence(self) -> float:
        """The stick-slip ripple's evidence now (nats, not capped; 0 without it)."""
        ripple = self._ripple
        energy = ripple.energy if ripple is not None else None
        rnoise = self._rnoise
        if energy is None or not rnoise > 0.0:
            return 0.0
        return variance_evidence(energy / rnoise, self._ripple_dof)

    def _covariate_block(self, moving: bool) -> None:
        """The coupling's learning (force_covariate), a block at a time: a block's
        moments are committed only once it and the block after it went by with no slip
        evidence, so that the first frames of a slide whose force drops, before it is
        found, are not learnt as a centre that follows its total.  Then the coupling
        of the centre's change to the total's over the fast horizon: their moments
        less the noise's own (a taxel's noise moves the total and pulls the centre
        towards it: the frame-to-frame differences' moments, like the total's noise,
        over m per mean and times 2 per difference), over the total's change's
        variance plus force_covariate - 1 of its noise's (2 sigma_S^2 / m), from the
        moments' mean, 0 unless the total's change's variance is more than twice its
        noise's: until the total has varied with no slide."""
        if moving:
            self._block_moved = True
        self._block_len += 1
        if self._block_len < self._steady_n // 4:  # (blocks of 0.25 s)
            return
        block, learnt = self._block, self._block_learnt
        if self._block_moved:
            self._candidate = None
        else:
            candidate = self._candidate
            if candidate is not None and candidate[1]:
                sums, n = candidate
                total = self._cov_count = self._cov_count + n
                gain = n / total
                if gain < n * self._a_noise:
                    gain = n * self._a_noise
                if gain > 1.0:
                    gain = 1.0
                cov = self._cov
                for i in range(5):
                    cov[i] += gain * (sums[i] / n - cov[i])
                var = 2.0 * self._fnoise / self.m  # (the total's change's noise variance)
                if cov[2] > 2.0 * var:  # the total has varied by more than its noise
                    den = cov[2] + (self._covariate - 1.0) * var
                    k = 2.0 / self.m
                    self._beta_x = (cov[0] - k * cov[3]) / den
                    self._beta_y = (cov[1] - k * cov[4]) / den
                else:  # (a still grip's noise alone gave couplings of +-0.06 mm/N, which
                    # a drop of 1.6 N made a ramp of 0.1 mm: no coupling learnt)
                    self._beta_x = self._beta_y = 0.0
            self._candidate = (block, learnt)
        self._block = [0.0] * 5
        self._block_learnt = self._block_len = 0
        self._block_moved = False

    def score(self, t: float, f: np.ndarray, s: float, xc: float, yc: float) -> tuple[float, float, bool, bool]:
        # (hot path: one call per frame at any rate, ten per paper hop at 100 Hz; so
        # attributes are read once into locals, and each (x, y, S) is one tuple)
        # running means of the last m centres and totals (the total is smoothed too,
        # so that sensor noise does not read as a varying force)
        hn = self._hn  # frames so far (the rings below are indexed by it)
        m = self.m
        win = self._win
        slot = hn % m
        old = win[slot]
        now = (xc, yc, s)
        win[slot] = now
        if hn < m:
            cnt = self._cnt = self._cnt + 1
            sx = self._sx = self._sx + xc
            sy = self._sy = self._sy + yc
            ss = self._ss = self._ss + s
        else:
            cnt = self._cnt
            sx = self._sx = self._sx + (xc - old[0])
            sy = self._sy = self._sy + (yc - old[1])
            ss = self._ss = self._ss + (s - old[2])
        mx, my, ms = sx / cnt, sy / cnt, ss / cnt
        prev = self._prev
        self._prev = now
        hist, ls, lf, lh = self._hist, self.ls, self.lf, self._half
        at = hn % ls
        fast = hist[at - lf] if hn >= lf else None  # (a negative index counts from the end)
        half = hist[at - lh] if hn >= lh else None
        lhf = self._half_fast
        half_fast = hist[at - lhf] if hn >= lhf else None
        slow = hist[at] if hn >= ls else None
        hist[at] = (mx, my, ms)
        self._hn = hn + 1
        filled = self.filled
        # (a real frame after a held copy moves the centre by the gap's motion at once)
        after_copy, self._was_filled = self._was_filled, filled
        # the total's change over the ripple's lag (a held copy counts as calm)
        ripple = self._ripple
        rip_d2 = ripple.push(s, self._rnoise if filled else None) if ripple is not None else None
        # a varying force: the smoothed total changes faster than force_rate, and by
        # more than its own noise (z sigma), which matters when the grip is light
        z = self.z
        if fast is None:
            varying = False
        else:
            rate_d = self.force_rate * ms * self.fast_s
            noise_s = z * math.sqrt(2.0 * self._fnoise / m)
            change = ms - fast[2]
            varying = (change if change >= 0.0 else -change) > (rate_d if rate_d > noise_s else noise_s)
        if prev is None or cnt < m:
            return 0.0, 0.0, False, varying
        # CoF noise scales as 1 / S (sigma_F * spread / S): learn it in force units so
        # that a grip that loosens (or tightens) keeps the right threshold
        dx = xc - prev[0]
        noise = self._noise
        step2 = (dx * dx + (yc - prev[1]) ** 2) * 0.5 * s * s
        if filled:  # a held copy has no step of its own: neither noise nor vibration
            step2 = noise if noise is not None else 0.0
        if noise is None or noise <= 0.0:
            # nothing learnt yet: the first frames after a grab still settle, so
            # vote nothing until a running mean over the settling time exists
            if hn < self._settled:
                return 0.0, 0.0, False, varying
            if filled or step2 <= 0.0:
                return 0.0, 0.0, False, varying
            noise = self._noise = step2
            self._learnt = 1
            self._noise_x = 0.5 * step2
        # (not while the force changes, nor for a second after: a squeeze or a swaying
        # load moves a soft contact's CoF in steps too)
        self._calm_force = calm = 0 if varying else self._calm_force + 1
        steady = calm > self._steady_n
        if steady:
            self._held = True
            # (the level from before the last onward_fall_s: the force reads as steady
            # for a few frames into a sudden fall, until the change passes its noise)
            lag = self._fall_lag
            self._steady_level = hist[at - lag][2] if lag and hn >= lag else ms
            self._armed = False
            self._latched = False
            self._spent = False
        elif self._steady_level is not None and ms >= self._steady_level:
            # the total back at its steady level: whatever moved it was no grip giving
            # way (a drop stays down; a sway, a shake and a squeeze come back up), so the
            # gate shuts and stays shut until the force is steady again; a sway of 2 Hz
            # falls as fast as a drop in each lower half, and a gate left open through
            # every one of them read the sway as slip (docs/evaluation.md)
            self._spent = True
            self._armed = False
            self._latched = False
        elif self._fall_lag and not self._armed and not self._spent and not filled and not after_copy \
                and hn >= self._fall_lag:
            # the gate waits for a sudden fall of the total (onward_fall_s): a grip that
            # gives way at a slide's onset loses 10-30 % in tens of milliseconds, a
            # swaying glass's total falls over hundreds and a light hold settles slower
            # still; the fall must also pass onward_fall_z sigma of its own noise (two
            # means of m frames), which a light grip's noise would reach alone
            back = hist[at - self._fall_lag][2]
            fall = back - ms
            if fall >= (1.0 - self._onward_below) * back and fall * fall > self._fall_z2 * self._fnoise:
                self._armed = True
        noise_d = z * math.sqrt(2.0 * noise / m) / s
        # the onward gate: while the force is not steady, the ramp and the step stay
        # open if the centre moves on, steadily, over the fast horizon: a slide whose
        # grip gives way at onset is still a slide, where a squeeze scales the
        # distribution in place (its centre stays) and a sway turns back.  Only while
        # the total is down from its last steady level (a drop is a step down; a sway,
        # a vibration and a held copy's step go both ways) and never on a held copy or
        # the frame after one
        moving_on = False
        gate = self._onward_open
        bx, by = self._beta_x, self._beta_y  # (0 unless force_covariate)
        level = self._steady_level
        if (not steady and gate > 0.0 and fast is not None and half_fast is not None and not filled
                and not after_copy and level is not None and ms <= level * self._onward_below
                and (self._armed or not self._fall_lag)):
            if self._latched:
                # once open, open until the force is steady again: a light grip's centre
                # is noisy, and its onward test flickered shut while the slide went on
                moving_on = True
            else:
                # (the centre less the part of its motion the total's change explains)
                ds = ms - fast[2]
                ux, uy = mx - fast[0] - bx * ds, my - fast[1] - by * ds
                d2 = ux * ux + uy * uy
                lim = self.min_fast
                thr = gate * (noise_d if noise_d > lim else lim)
                if d2 > thr * thr:
                    ds = ms - half_fast[2]
                    on = (mx - half_fast[0] - bx * ds) * ux + (my - half_fast[1] - by * ds) * uy
                    moving_on = self._latched = on >= self._onward_share * d2
        open_ = steady or moving_on
        # the ramp's base must not hold the grab: its centres start once it has settled;
        # a held copy is no sample (repeats would count one noise draw twice)
        ramp, profile, step = self._ramp, self._profile, self._jumps
        r = 0.0
        # the ramp's test is taken once a hop, on the frame the decision reads the hop
        # at: its statistic moves little from one frame to the next, and tested at every
        # frame of a 1 kHz node its noise crossed the threshold twice as often per hour
        # as at 100 Hz (docs/evaluation.md); its verdict stands for the hop's other frames
        hop_end = (self._k + 1) % self.hop == 0
        raw = -1.0  # the ripple's evidence, once it is worked out (the ramp's and the step's)
        # the total as a covariate (force_covariate): banks of the same geometry fed the
        # total, so that the ramp and the step test the centre less beta times it
        ramp_s, step_s = self._ramp_s, self._jumps_s
        if ramp_s is not None and not filled:
            ramp_s.push(s, 0.0, 1.0)
            if step_s is not None:
                step_s.push(s, 0.0, s)
        if open_ and hop_end:
            # the ramp weighs raw centres, each axis against its own noise (in force
            # units, like q; the floor keeps a constant axis, a strip's y, harmless);
            # silent while the force changes and for a second after, like the
            # stick-slip channel: a soft pad's CoF follows its force, and a swaying
            # glass is no slip.  Stick-slip shakes the total force: that evidence adds
            # to the ramp's
            qx = self._noise_x
            qy = noise - qx
            floor = 0.0025 * noise
            if not qx > floor:
                qx = floor
            if not qy > floor:
                qy = floor
            energy = ripple.energy if ripple is not None else None
            rnoise = self._rnoise
            raw = 0.0
            if energy is not None and rnoise > 0.0:
                raw = variance_evidence(energy / rnoise, self._ripple_dof)
            evidence = raw if raw < self._evidence_cap else self._evidence_cap
            if filled:
                r = ramp.score_less(ramp_s, bx, by, qx, qy, self.ramp_min, evidence)  # (None: score)
            else:  # (the push and the test in one pass: at 100 Hz every frame has both)
                if ramp_s is None:
                    r = ramp.push_score(xc, yc, 1.0 / (s * s), qx, qy, self.ramp_min, evidence)
                else:
                    ramp.push(xc, yc, 1.0 / (s * s))
                    r = ramp.score_less(ramp_s, bx, by, qx, qy, self.ramp_min, evidence)
                if step is not None:
                    step.push(xc, yc, s)
                if profile is not None:
                    profile.push(f)
            if profile is not None and not self.decision.latch.on:  # the sums' own test, OR'd
                # (silent in the variable_force state: a soft pad's outline changes
                # with its force, which no scaling of the sums describes)
                rp = profile.score()
                if rp > r:
                    r = rp
            self._ramp_on = r > 1.0
        else:
            if not filled:
                ramp.push(xc, yc, 1.0 / (s * s))
                if step is not None:
                    step.push(xc, yc, s)
                if profile is not None:
                    profile.push(f)
            if not open_:
                self._ramp_on = False
        level_open = False
        if step is not None:
            # the step channel has its own silence for a varying force: the ramp's rule
            # (a change of the total of more than force_rate_per_s x fast_s, 3 % of the
            # grip, and for a second after), on the force's level over the span the
            # step looks across (its means over the newest 0.1 s and over the base),
            # which a stick-slip ripple about a constant level does not move; the
            # ramp's 30 ms means 0.1 s apart follow a ripple of 6-18 Hz
            # (squares: no root a frame)
            change = step.level
            limit = self._level_rate * s
            limit *= limit
            noise2 = self._level_noise * self._fnoise
            if noise2 > limit:
                limit = noise2
            self._level_calm = calm_level = self._level_calm + 1 if change * change <= limit else 0
            level_open = calm_level > self._steady_n
            if hop_end and (level_open or moving_on) and self._step_learnt and step.ready:
                # (the step's score, written out: a call a frame at 100 Hz) against its learnt
                # noise per axis, never below q's, times the centres' weight; the evidence
                # added (capped: the step must reach ramp_support_z itself); the
                # displacement floor
                if raw < 0.0:
                    raw = self._evidence()
                vx, vy = self._step_vx, self._step_vy
                qx = self._noise_x
                if qx > vx:
                    vx = qx
                if noise - qx > vy:
                    vy = noise - qx
                floor = 0.0025 * (vx + vy)  # (a constant axis, a strip's y, stays harmless)
                if not vx > floor:
                    vx = floor
                if not vy > floor:
                    vy = floor
                if vx > 0.0:
                    jx, jy = step.dx, step.dy
                    if step_s is not None and step_s.ready:  # (less the part the total explains)
                        ju = step_s.dx
                        jx -= bx * ju
                        jy -= by * ju
                    if raw > self._step_cap:
                        raw = self._step_cap
                    rs = math.sqrt((jx * jx / vx + jy * jy / vy) / step.weight + 2.0 * raw) / self._step_z
                    if rs > r:  # (else min(rs, mm) cannot raise r: mm is not needed)
                        lim = self.ramp_min
                        if lim > 0.0:
                            mm = math.sqrt(jx * jx + jy * jy) / lim
                            if mm < rs:
                                rs = mm
                        if rs > r:
                            r = rs
                self._ramp_on = r > 1.0
        turn = self._turn
        if turn is not None:
            turn.push(f, s, filled, self.projected)
        # (force_covariate: the displacements less the part the total's change over the
        # same horizon explains, as the ramp, the step and the gate test them; a soft
        # pad's sway at 1 mm/N otherwise moves its centre past min_slow_mm)
        coupled = bx != 0.0 or by != 0.0
        if fast is not None:
            lim = self.min_fast
            if coupled:
                ds = ms - fast[2]
                a = math.hypot(mx - fast[0] - bx * ds, my - fast[1] - by * ds)
            else:
                a = math.hypot(mx - fast[0], my - fast[1])
            a /= noise_d if noise_d > lim else lim
        else:
            a = 0.0
        b = 0.0
        if slow is not None and half is not None:  # (a slow lag implies the half one)
            # only while the motion goes on: the newer half of the horizon moved on in
            # the same direction (noise alone points anywhere)
            if coupled:
                ds, dh = ms - slow[2], ms - half[2]
                ux, uy = mx - slow[0] - bx * ds, my - slow[1] - by * ds
                hx, hy = mx - half[0] - bx * dh, my - half[1] - by * dh
            else:
                ux, uy = mx - slow[0], my - slow[1]
                hx, hy = mx - half[0], my - half[1]
            total = math.hypot(ux, uy)
            onward = (hx * ux + hy * uy) / total if total > 0 else 0.0
            lim = self.min_slow
            thr = noise_d if noise_d > lim else lim
            # the onward half gets a noise margin of its own (4.5 sigma): half the
            # threshold alone would be only 3 sigma, met by noise every few seconds
            # (min and max written out: two builtin calls a frame)
            margin = 0.75 * noise_d
            if not margin > 0.5 * thr:
                margin = 0.5 * thr
            b = total / thr
            if onward / margin < b:
                b = onward / margin
        if self._keeps_steps:
            self._stepped(step2)
        slip = a > 1.0 or b > 1.0 or r > 1.0
        moving = slip or self._ramp_on  # (what the noise must not be learnt from)
        tr = 0.0
        if turn is not None:
            if moving:  # a slide: the turn's template would smear it
                turn.restart()
            if steady:
                tr = turn.score
        self.fast_score, self.ramp_score, self.turn_score = a, r, tr
        if tr > 1.0:
            slip = moving = True
        if turn is not None and turn.learnable and not moving and tr < 0.5 and not filled:
            turn.learn()
        if not moving and a < 0.5 and not filled:  # learn the noise only while calm
            learnt = self._learnt = self._learnt + 1
            gain = 1.0 / learnt
            if gain < self._a_noise:
                gain = self._a_noise
            self._noise = noise + gain * (step2 - noise)
            self._noise_x += gain * (dx * dx * 0.5 * s * s - self._noise_x)
            self._fnoise += gain * ((s - prev[2]) ** 2 * 0.5 - self._fnoise)
            if rip_d2 is not None:
                self._rnoise += gain * (rip_d2 - self._rnoise)
            if self._covariate > 0.0 and self._held and fast is not None:
                # the moments of the coupling (force_covariate), into the current block
                ds = ms - fast[2]
                d1 = s - prev[2]
                block = self._block
                block[0] += (mx - fast[0]) * ds
                block[1] += (my - fast[1]) * ds
                block[2] += ds * ds
                block[3] += dx * d1 * 0.5
                block[4] += (yc - prev[1]) * d1 * 0.5
                self._block_learnt += 1
            if level_open and step is not None and step.ready:  # the step's own noise (force units)
                if not self._step_learnt:  # (white noise's, q, to start from)
                    self._step_vx = self._noise_x
                    self._step_vy = self._noise - self._noise_x
                    self._step_learnt = self._step_prior
                learnt = self._step_learnt = self._step_learnt + 1
                g = 1.0 / learnt
                if g < self._a_noise:
                    g = self._a_noise
                inv = 1.0 / step.weight
                jx, jy = step.dx, step.dy
                self._step_vx += g * (jx * jx * inv - self._step_vx)
                self._step_vy += g * (jy * jy * inv - self._step_vy)
            if profile is not None:
                profile.calm()
        if self._covariate > 0.0:
            self._covariate_block(moving)
        if tr > r:
            r = tr
        if not slip and self.decision.state == _SLIP:
            # a slip is kept while its evidence stays above (1 - hysteresis) of the
            # thresholds: a slow slide's evidence fades in and out as it stops
            slip = a > self._keep or b > self._keep or r > self._keep
        return (a if a > r else r), b, slip, varying
