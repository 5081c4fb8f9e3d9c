"""Grasp states, and the state machine that turns indicator updates into them.

The machine is where "I don't know" is decided: an update that is not valid (warm-up
after a start or a reset, a window too short for the wavelet) never changes a
contact state into a confident one; it keeps the previous state and the update's
``valid`` is 0, which the PLC sees.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

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


@dataclass
class StateMachine:
    """Paper decision plus hysteresis, slip confirmation and a minimum hold.

    - slip: both R_coe > ``slip_r_coe`` and R_dw > ``slip_r_dw`` (the paper's rule),
      for ``slip_confirm_updates`` consecutive valid updates;
    - variable force: either indicator above its ``variable_*`` threshold;
    - a state is left downwards only after ``hold_s`` and once the indicators fall
      below threshold x (1 - ``hysteresis``); upwards at once.
    """

    settings: DetectorSettings
    state: int = _NO_CONTACT
    entered_t: float = float("-inf")
    slip_run: int = 0

    def step(self, t: float, r_coe: float, r_dw: float, contact: bool, valid: bool) -> int:
        cfg = self.settings
        cur = self.state
        if not contact:
            self.slip_run = 0
            if cur != _NO_CONTACT:
                self.state, self.entered_t = _NO_CONTACT, t
            return self.state
        if not valid:
            # Unknown: keep what we had (the update's valid bit says it is stale);
            # contact without any verdict yet reads "stable", never "slip".
            self.slip_run = 0
            if cur == _NO_CONTACT:
                self.state, self.entered_t = _STABLE, t
            return self.state
        keep = 1.0 - cfg.hysteresis
        slip_c = cfg.slip_r_coe * (keep if cur == _SLIP else 1.0)
        slip_d = cfg.slip_r_dw * (keep if cur == _SLIP else 1.0)
        var_c = cfg.variable_r_coe * (keep if cur >= _VARIABLE else 1.0)
        var_d = cfg.variable_r_dw * (keep if cur >= _VARIABLE else 1.0)
        rule = cfg.slip_rule
        over_c, over_d = r_coe > slip_c, r_dw > slip_d
        if (over_c and over_d) if rule == "both" else over_c if rule == "coe" else over_d:
            self.slip_run += 1
            candidate = _SLIP if (self.slip_run >= cfg.slip_confirm_updates or cur == _SLIP) else _VARIABLE
        else:
            self.slip_run = 0
            candidate = _VARIABLE if (r_coe > var_c or r_dw > var_d) else _STABLE
        if candidate > cur or (candidate < cur and t - self.entered_t >= cfg.hold_s):
            self.state, self.entered_t = candidate, t
        return self.state
