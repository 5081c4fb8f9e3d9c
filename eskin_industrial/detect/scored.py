"""Detectors built from one per-frame score: the rivals a reviewer asks for, and the
skeleton of our own method.  Each shares the frame hygiene, contact rule, decision
and :class:`Update` output of the paper detector (:mod:`.state`), so the evaluation
and the bridge run them all the same way.

Per frame k in contact the subclass returns ``(score_a, score_b, slip, varying)``;
every hop the hop's votes go to the :class:`~.state.Decision`: slip evidence if any
frame of the hop voted slip (for ``confirm`` consecutive frames); varying-force
evidence the hop's largest score of the total force's own test (``vforce.py``), or,
with ``[detector.varying_force] evidence = "method"``, whether any frame voted
varying.  The update carries the hop's largest scores in ``score_a`` and ``score_b``
(what each means: the class's ``columns``), and in ``r_coe`` and ``r_dw`` the paper's
indicators on the same frames (:mod:`.alongside`, fed the frames, totals, centres and
contact computed here: the decision never reads them).

The rivals' thresholds are profile settings (``[detector.force_rate]``,
``[detector.cof_velocity]``, ``[detector.hf_energy]``); keyword arguments override
single fields, for parameter sweeps.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np

from ..frames import FrameFlag
from .alongside import PaperAlongside
from .hygiene import FrameHygiene, feed
from .settings import DetectorSettings
from .state import ContactRule, Decision
from .torsion import TurnFlow
from .updates import Update
from .vforce import ForceVariation

_WARMUP = int(FrameFlag.WARMUP)
_FILLED = int(FrameFlag.FILLED)
_TURN_UNSEEN = int(FrameFlag.TURN_UNSEEN)
#: an :class:`Update` from all its fields in order, without the named tuple's own
#: ``__new__`` (a Python function: half an update's cost, and a method that decides
#: every 10 ms builds one a frame at 100 Hz)
_new_update = tuple.__new__


class ScoredDetector(FrameHygiene):
    name = "scored"
    filled = False  #: the current frame is a held copy (set before ``score`` is called)
    projected = 0.0  #: the current frame times the projection column (set likewise)
    columns = ("score", "unused")
    #: frames of contact needed before the score is trusted
    history_s = 0.1
    #: a torsion channel (cof-track's): while in contact and it is ``blind``, the
    #: updates carry TURN_UNSEEN; none in the others, which see no turn at all
    _turn: TurnFlow | None = None

    def __init__(self, settings: DetectorSettings, x_mm: np.ndarray, y_mm: np.ndarray, rate_hz: float,
                 hop_s: float | None = None, confirm: int = 1) -> None:
        geo = settings.geometry(rate_hz)
        super().__init__(int(len(x_mm)), rate_hz, geo.max_fill)
        self.settings = settings
        self.rate_hz = rate_hz
        self.hop = max(1, round((hop_s if hop_s is not None else settings.hop_s) * rate_hz))
        self.history = max(1, round(self.history_s * rate_hz))
        self.confirm = confirm
        # each frame's (S, Sx, Sy) and one projection, in one product: column 3 is the
        # torsion channel's template (its hop's angle is a sum of these), zeros without one
        self._mat = np.column_stack([np.ones(self.n), x_mm, y_mm, np.zeros(self.n)]).astype(np.float64)
        if self._turn is not None:
            self._turn.project_into(self._mat[:, 3])
        self._rule = ContactRule.from_settings(settings, rate_hz)
        self._touching = self._rule.touching
        # (confirmation is per frame, above: the decision reports a hop's slip vote at once)
        self.decision = Decision.from_settings(settings, confirm=1)
        own = settings.varying_force.evidence == "method"
        self._vf = None if own else ForceVariation(settings.varying_force, rate_hz)
        self.paper = PaperAlongside(settings, self.n, rate_hz)
        self._reset(0)

    @property
    def state(self) -> int:
        return self.decision.state

    def _reset(self, flags: int) -> None:
        self._k = 0
        self._contact_run = 0
        self._rule.reset()  # (a restart learns the baseline anew, as the batch form's segments do)
        self._hop_a = self._hop_b = 0.0
        self._hop_slip = self._hop_var = False
        self._hop_vf = 0.0
        self._slip_run = 0
        self._hop_flags = flags
        if self._vf is not None:
            self._vf.reset()
        self._warm = True
        self._cof = (float(self._mat[:, 1].mean()), float(self._mat[:, 2].mean()))
        self.paper.reset()
        self.reset_scores()

    # -- for subclasses ---------------------------------------------------------
    def reset_scores(self) -> None:
        """Forget the score's history (start, reset, loss of contact)."""

    def score(self, t: float, f: np.ndarray, s: float, xc: float, yc: float) -> tuple[float, float, bool, bool]:
        raise NotImplementedError

    # -- the per-frame loop -----------------------------------------------------
    def _step(self, t: float, f: np.ndarray, flags: int, out: list[Update]) -> None:
        s, sx, sy, self.projected = (f @ self._mat).tolist()
        contact = self._touching(s, self._contact_run > 0)
        filled = bool(flags & _FILLED)  # a held copy across a gap: no new information
        vf = self._vf.push(s, contact, filled) if self._vf is not None else 0.0
        a = b = 0.0
        slip = varying = False
        if contact:
            xc, yc = sx / s, sy / s
            self._cof = (xc, yc)
            self._contact_run += 1
            self.filled = filled
            a, b, slip, varying = self.score(t, f, s, xc, yc)
            trusted = self._contact_run > self.history
            if not trusted:
                slip = varying = False
            self._slip_run = self._slip_run + 1 if slip else 0
            slip = self._slip_run >= self.confirm
            warm = not trusted
        else:
            if self._contact_run:
                self.reset_scores()
            self._contact_run = 0
            self._slip_run = 0
            warm = False
        self.paper.push(f, s, contact, self._cof)
        self._k += 1
        if self.hop == 1:
            # a hop of one frame (cof-track at 100 Hz): its votes are the frame's own,
            # with no hop to gather them in (the largest of 0 and each score, as there)
            carried = self._hop_flags  # (what a reset left for the first update)
            if carried:
                flags |= carried
                self._hop_flags = 0
            out.append(self._decide(t, s, contact, not warm, slip, varying, vf if vf > 0.0 else 0.0,
                                    a if a > 0.0 else 0.0, b if b > 0.0 else 0.0, flags))
            return
        if vf > self._hop_vf:
            self._hop_vf = vf
        if contact:
            self._hop_slip |= slip
            self._hop_var |= varying
            if a > self._hop_a:
                self._hop_a = a
            if b > self._hop_b:
                self._hop_b = b
        self._warm = warm
        self._hop_flags |= flags
        if self._k % self.hop:
            return
        out.append(self._decide(t, s, contact, not self._warm, self._hop_slip, self._hop_var, self._hop_vf,
                                self._hop_a, self._hop_b, self._hop_flags))
        self._hop_a = self._hop_b = self._hop_vf = 0.0
        self._hop_slip = self._hop_var = False
        self._hop_flags = 0

    def _decide(self, t: float, s: float, contact: bool, valid: bool, slip: bool, var: bool, vf: float,
                a: float, b: float, flags: int) -> Update:
        """The update for a hop from its votes: any slip, any varying force, the largest
        varying-force score, the largest scores, its frames' flags."""
        state = self.decision.decide(t, contact, valid, slip, vf if self._vf is not None else float(var))
        if not valid:
            flags |= _WARMUP
        turn = self._turn
        if contact and turn is not None and turn.blind:
            flags |= _TURN_UNSEEN
        paper = self.paper
        xc, yc = self._cof
        return _new_update(Update, (t, paper.r_coe, paper.r_dw, state, valid, s, xc, yc, flags, a, b))

    def feed(self, t: np.ndarray, forces: np.ndarray, flags: np.ndarray | None = None) -> list[Update]:
        return feed(self.push, t, forces, flags)


class NoSlip(ScoredDetector):
    """No slip sensing at all: contact, the varying-force state and DATA_VALID as every
    method reports them, and never a slip.  A PLC program fed by it grips as if the
    skin were absent while still trusting the data (the fixed grip of the closed loop,
    ``sim/cell``)."""

    name = "none"
    columns = ("unused", "unused")

    def score(self, t: float, f: np.ndarray, s: float, xc: float, yc: float) -> tuple[float, float, bool, bool]:
        return 0.0, 0.0, False, False


class _Lagged:
    """A ring of the last ``lag`` values: ``swap(v)`` returns the value ``lag`` pushes ago."""

    __slots__ = ("buf", "i", "full")

    # Any: each detector keeps its own kind of value (floats, (x, y) pairs).
    def __init__(self, lag: int, fill: Any = 0.0) -> None:
        self.buf = [fill] * lag
        self.i = 0
        self.full = False

    def swap(self, value: Any) -> Any:
        old = self.buf[self.i]
        self.buf[self.i] = value
        self.i += 1
        if self.i == len(self.buf):
            self.i = 0
            self.full = True
        return old


class ForceRate(ScoredDetector):
    """Rival: slip when the total force changes fast: |dS/dt| / S above ``threshold_per_s``
    (``[detector.force_rate]``)."""

    name = "force-rate"
    columns = ("force_rate_per_s", "unused")

    def __init__(self, settings: DetectorSettings, x_mm: np.ndarray, y_mm: np.ndarray, rate_hz: float,
                 hop_s: float | None = None, confirm: int = 1, **overrides: float) -> None:
        c = replace(settings.force_rate, **overrides) if overrides else settings.force_rate
        self.threshold = c.threshold_per_s
        self.lag_s = c.lag_s
        super().__init__(settings, x_mm, y_mm, rate_hz, hop_s, confirm)

    def reset_scores(self) -> None:
        self._ring = _Lagged(max(1, round(self.lag_s * self.rate_hz)), None)

    def score(self, t: float, f: np.ndarray, s: float, xc: float, yc: float) -> tuple[float, float, bool, bool]:
        old = self._ring.swap(s)
        if old is None:
            return 0.0, 0.0, False, False
        rate = abs(s - old) / self.lag_s / s
        return rate, 0.0, rate > self.threshold, rate > 0.3 * self.threshold


class CofVelocity(ScoredDetector):
    """Rival: slip when the centre of force moves faster than ``threshold_mm_s``
    (``[detector.cof_velocity]``)."""

    name = "cof-velocity"
    columns = ("cof_speed_mm_s", "unused")

    def __init__(self, settings: DetectorSettings, x_mm: np.ndarray, y_mm: np.ndarray, rate_hz: float,
                 hop_s: float | None = None, confirm: int = 1, **overrides: float) -> None:
        c = replace(settings.cof_velocity, **overrides) if overrides else settings.cof_velocity
        self.threshold = c.threshold_mm_s
        self.lag_s = c.lag_s
        super().__init__(settings, x_mm, y_mm, rate_hz, hop_s, confirm)

    def reset_scores(self) -> None:
        self._ring = _Lagged(max(1, round(self.lag_s * self.rate_hz)), None)

    def score(self, t: float, f: np.ndarray, s: float, xc: float, yc: float) -> tuple[float, float, bool, bool]:
        old = self._ring.swap((xc, yc))
        if old is None:
            return 0.0, 0.0, False, False
        speed = math.hypot(xc - old[0], yc - old[1]) / self.lag_s
        return speed, 0.0, speed > self.threshold, False


class HfEnergy(ScoredDetector):
    """Rival (vibration-based slip detection): energy of the taxels' second difference,
    relative to its own running baseline; slip when above ``threshold`` times it.
    ``total=True`` takes the second difference of the total force instead, where a
    vibration shared by the taxels adds up coherently and their noise does not
    (``[detector.hf_energy]``)."""

    name = "hf-energy"
    columns = ("hf_energy_ratio", "unused")
    history_s = 0.3

    def __init__(self, settings: DetectorSettings, x_mm: np.ndarray, y_mm: np.ndarray, rate_hz: float,
                 hop_s: float | None = None, confirm: int = 1, **overrides: Any) -> None:
        c = replace(settings.hf_energy, **overrides) if overrides else settings.hf_energy
        self.threshold = c.threshold
        self.total = c.total
        self.smooth_s = c.smooth_s
        self.baseline_s = c.baseline_s
        super().__init__(settings, x_mm, y_mm, rate_hz, hop_s, confirm)

    def reset_scores(self) -> None:
        self._p1: np.ndarray | float | None = None  # the last two frames (or totals)
        self._p2: np.ndarray | float | None = None
        self._fast = 0.0
        self._base = 0.0
        self._a_fast = 1.0 / max(1.0, self.smooth_s * self.rate_hz)
        self._a_base = 1.0 / max(1.0, self.baseline_s * self.rate_hz)
        self._n_seen = 0

    def score(self, t: float, f: np.ndarray, s: float, xc: float, yc: float) -> tuple[float, float, bool, bool]:
        p1, p2 = self._p1, self._p2
        cur = s if self.total else f
        self._p2, self._p1 = p1, cur
        if p1 is None or p2 is None:  # p2 set implies p1 set
            return 0.0, 0.0, False, False
        d = cur - 2.0 * p1 + p2
        e = float(d * d if self.total else d @ d) / (s * s)  # type: ignore[operator]  # (total: floats; else arrays)
        self._fast += self._a_fast * (e - self._fast)
        self._n_seen += 1
        if self._n_seen < 5:
            self._base = self._fast
            return 0.0, 0.0, False, False
        ratio = self._fast / (self._base + 1e-12)
        slip = ratio > self.threshold
        if not slip:  # the baseline learns only from calm frames
            self._base += self._a_base * (e - self._base)
        return ratio, 0.0, slip, False
