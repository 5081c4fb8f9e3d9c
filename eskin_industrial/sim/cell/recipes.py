"""Each object's recipe, as an integrator writes it from the catalogue values
(``objects.py``): the fixed grip a cautious integrator would set with no skin, and the
grip policy's forces for a gripper with one.

The catalogue rule: grip = m (g + a) S / (n mu), with n = 2 fingers, the design (top)
mass, the nominal friction, the program's largest acceleration and a safety factor S
of 1.5-2.5 (the gripper makers' range).  A fragile object's grip is capped below its
rated crush force.  The policy's forces are shares of the force that holds the object
at rest (S = 1, a = 0).  Every factor here was chosen on the closed loop's tuning seeds
(``episodes.TUNING_SEEDS``; docs/evaluation.md, *The closed loop*), never on the
held-out ones.

Each recipe is for a gripper (``drive``, a gripper class's ``ActuatorSpec``): its
forces within the drive's range (a grip lighter than the drive's minimum is its
minimum, whatever that does to a fragile object), and a raise of at least one of its
force steps (a smaller one would not change the force it holds).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Literal

from .actuator import ActuatorSpec
from .objects import CellObject
from .physics import G
from .policy import PolicySettings

#: The largest acceleration of the cell's program (m/s^2: transports up to 8).
DESIGN_ACCEL = 8.0
#: The catalogue's safety factor the fixed grip uses: the smallest of 1.5, 1.75, ...,
#: 2.5 with which the fixed grip dropped nothing on the tuning seeds.
FIXED_SAFETY = 1.5
#: A fragile object is gripped at most at its rated crush force over this.
CRUSH_MARGIN = 1.25
#: The lightest grip the policy holds with: below it the skin sees too little of the
#: contact to tell a slide (five times the profiles' 0.2 N contact threshold).
MIN_GRIP_N = 1.0


@dataclass(frozen=True)
class PolicyFactors:
    """The policy's forces as shares of the rest force (the same for every object),
    and its timing; chosen on the tuning seeds with the default method."""

    light: float = 1.6  #: the light grip, of the rest force at the start mass
    step: float = 1.0  #: a raise, of the rest force at the design mass
    max_of_fixed: float = 1.0  #: the most it raises to, of the fixed grip
    mode: Literal["step", "max", "hybrid"] = "hybrid"
    repeat_s: float = 0.2
    escalate_mm: float = 3.0  #: ``hybrid``: the slide past the alarm that sends it to the maximum
    quiet_s: float = 3.0
    relax_share: float = 0.1
    relax_floor: float = 1.5
    relax_s: float = 1.0  #: a relax spread over this long (0: at once)


POLICY = PolicyFactors()


def rest_force_n(mass_kg: float, mu: float) -> float:
    """The grip that just holds ``mass_kg`` at rest between two pads."""
    return mass_kg * G / (2.0 * mu)


def crush_cap_n(kind: CellObject) -> float | None:
    rated = kind.rated_crush_n
    return None if rated is None else rated / CRUSH_MARGIN


def _within(force_n: float, drive: ActuatorSpec | None) -> float:
    """A force the drive can hold: within its range, on its steps."""
    return force_n if drive is None else drive.setting_n(force_n)


def fixed_grip_n(kind: CellObject, safety: float = FIXED_SAFETY, drive: ActuatorSpec | None = None) -> float:
    """The cautious integrator's grip with no skin: the catalogue rule, capped below
    the rated crush force, within the drive's range."""
    force = kind.design_mass_kg * (G + DESIGN_ACCEL) * safety / (2.0 * kind.nominal_mu)
    cap = crush_cap_n(kind)
    return _within(force if cap is None else min(force, cap), drive)


def policy_settings(kind: CellObject, factors: PolicyFactors = POLICY, safety: float = FIXED_SAFETY,
                    drive: ActuatorSpec | None = None) -> PolicySettings:
    """The grip policy's settings for ``kind`` on ``drive`` (None: the cell's own)."""
    fixed = fixed_grip_n(kind, safety, drive)
    cap = crush_cap_n(kind)
    light = max(factors.light * rest_force_n(kind.mass_kg.hi, kind.nominal_mu), MIN_GRIP_N)
    step = factors.step * rest_force_n(kind.design_mass_kg, kind.nominal_mu)
    top = factors.max_of_fixed * fixed
    if cap is not None:
        top = min(top, cap)
    if drive is not None:
        light, top = _within(light, drive), _within(top, drive)
        step = max(step, drive.step_n)
    return PolicySettings(light_n=min(light, top), step_n=step, max_n=max(top, light), fallback_n=fixed,
                          mode=factors.mode, escalate_mm=factors.escalate_mm,
                          repeat_s=factors.repeat_s, quiet_s=factors.quiet_s, relax_share=factors.relax_share,
                          relax_floor=factors.relax_floor, relax_s=factors.relax_s)


def with_factors(**changes: float | str) -> PolicyFactors:
    """The default factors with some changed (the tuning's candidates)."""
    return replace(POLICY, **changes)  # type: ignore[arg-type]
