"""Grasp states, and the one decision every method ends in.

Every detector, the paper's and the per-frame scored ones alike, reduces a hop of
frames to the same four facts: is the array in contact, is the verdict valid, is
there slip evidence, is there varying-force evidence.  :class:`Decision` turns those
into the reported state, with the same rules for all methods:

- out of contact: ``no_contact`` at once;
- in contact but not valid (warm-up after a start or a reset, a window too short for
  the wavelet): the previous state is kept, and ``no_contact`` becomes ``stable``;
  an update that does not know never reports anything confident (its ``valid`` is 0,
  which the PLC sees);
- slip evidence for ``confirm`` consecutive updates: ``slip`` (``variable_force``
  until then); varying-force evidence: ``variable_force``; else ``stable``;
- a state is entered upwards at once, and left downwards only after ``hold_s``.

Contact has one rule too, :class:`ContactRule`, applied to each frame's total force
by every method (the paper's indicators included, where it decides whether F_dis and
the centre of force are defined): contact begins when the total reaches
``contact_threshold_n`` and lasts while it stays above half of that.  A plain
threshold would make a first touch that hovers at the threshold toggle the PLC
between ``no_contact`` and ``stable`` every frame, and restart a detector's warm-up
each time.

What counts as evidence is each method's own: :class:`StateMachine` is the paper's
(R_coe and R_dw against their thresholds, with hysteresis) in front of a
:class:`Decision`; :class:`~eskin_industrial.detect.scored.ScoredDetector` votes per
frame and hands the hop's votes to its own :class:`Decision`.
"""

from __future__ import annotations

import enum
import math

import numpy as np

from .settings import DetectorSettings


class GraspState(enum.IntEnum):
    """State codes as the PLC sees them; ``label`` is the name used in files."""

    NO_CONTACT = 0
    STABLE = 1
    VARIABLE_FORCE = 2
    SLIP = 3

    @property
    def label(self) -> str:
        return self.name.lower()

    @classmethod
    def from_label(cls, label: str) -> "GraspState":
        return cls[label.upper()]


LABELS: tuple[str, ...] = tuple(s.label for s in GraspState)

_NO_CONTACT, _STABLE, _VARIABLE, _SLIP = (int(s) for s in GraspState)


class ContactRule:
    """In contact from a total force of ``enter_n``, until it falls below ``stay_n``
    (``STAY_FRACTION`` of it); never at a total of zero.

    :meth:`touching` is the per-frame form (the caller keeps the previous answer),
    :meth:`mask` the same rule over a run of frames, starting out of contact."""

    #: Contact, once made, lasts while the total stays above this share of the threshold.
    STAY_FRACTION = 0.5

    __slots__ = ("enter_n", "stay_n")

    def __init__(self, enter_n: float) -> None:
        self.enter_n = enter_n
        self.stay_n = self.STAY_FRACTION * enter_n

    @classmethod
    def from_settings(cls, settings: DetectorSettings) -> "ContactRule":
        return cls(settings.contact_threshold_n)

    def touching(self, s: float, was: bool) -> bool:
        """Contact at total force ``s``, given whether the previous frame was in contact."""
        return s > 0.0 and (s >= self.enter_n or (was and s >= self.stay_n))

    def mask(self, s: np.ndarray) -> np.ndarray:
        """:meth:`touching` frame by frame over ``s``, the frame before the first out of contact."""
        enter = (s > 0.0) & (s >= self.enter_n)
        leave = ~((s > 0.0) & (s >= self.stay_n))  # disjoint from enter: stay_n <= enter_n
        # each frame takes the answer of the last frame that enters or leaves
        last = np.maximum.accumulate(np.where(enter | leave, np.arange(len(s)), -1))
        return (last >= 0) & enter[np.maximum(last, 0)]


class Decision:
    """The grasp-state decision of every method (the rules are in the module's doc).

    ``decide`` is called once per update, not per frame; ``state`` and ``entered_t``
    persist across a detector's restarts after long gaps, as the PLC's view does."""

    __slots__ = ("hold_s", "confirm", "state", "entered_t", "slip_run")

    def __init__(self, hold_s: float, confirm: int = 1) -> None:
        self.hold_s = hold_s
        self.confirm = confirm
        self.state = _NO_CONTACT
        self.entered_t = -math.inf
        self.slip_run = 0  #: consecutive valid updates with slip evidence

    def decide(self, t: float, contact: bool, valid: bool, slip: bool, varying: bool) -> int:
        cur = self.state
        if not contact:
            self.slip_run = 0
            if cur != _NO_CONTACT:
                self.state, self.entered_t = _NO_CONTACT, t
            return self.state
        if not valid:
            # unknown: keep what we had (the update's valid bit says it is stale);
            # contact without any verdict yet reads "stable", never "slip"
            self.slip_run = 0
            if cur == _NO_CONTACT:
                self.state, self.entered_t = _STABLE, t
            return self.state
        if slip:
            self.slip_run += 1
            candidate = _SLIP if (self.slip_run >= self.confirm or cur == _SLIP) else _VARIABLE
        else:
            self.slip_run = 0
            candidate = _VARIABLE if varying else _STABLE
        if candidate > cur or (candidate < cur and t - self.entered_t >= self.hold_s):
            self.state, self.entered_t = candidate, t
        return self.state


class StateMachine:
    """The paper's evidence in front of the one :class:`Decision`.

    - slip evidence: both R_coe > ``slip_r_coe`` and R_dw > ``slip_r_dw`` (the paper's
      rule; or one alone, ``slip_rule``), reported after ``slip_confirm_updates``
      consecutive valid updates;
    - varying-force evidence: either indicator above its ``variable_*`` threshold;
    - while a state holds, its thresholds are lowered to threshold x (1 - ``hysteresis``),
      so that it is left only once the indicators have clearly fallen.

    ``contact`` is the update's newest frame under :class:`ContactRule`.
    """

    def __init__(self, settings: DetectorSettings) -> None:
        self.settings = settings
        self.decision = Decision(settings.hold_s, settings.slip_confirm_updates)
        self._rule = settings.slip_rule
        self._keep = 1.0 - settings.hysteresis

    @property
    def state(self) -> int:
        return self.decision.state

    def step(self, t: float, r_coe: float, r_dw: float, contact: bool, valid: bool) -> int:
        decision = self.decision
        if not (contact and valid):
            return decision.decide(t, contact, valid, False, False)
        cfg = self.settings
        cur = decision.state
        slip_k = self._keep if cur == _SLIP else 1.0
        var_k = self._keep if cur >= _VARIABLE else 1.0
        over_c, over_d = r_coe > cfg.slip_r_coe * slip_k, r_dw > cfg.slip_r_dw * slip_k
        rule = self._rule
        slip = (over_c and over_d) if rule == "both" else over_c if rule == "coe" else over_d
        varying = r_coe > cfg.variable_r_coe * var_k or r_dw > cfg.variable_r_dw * var_k
        return decision.decide(t, True, True, slip, varying)
