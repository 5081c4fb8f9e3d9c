"""What the closed-loop evaluation moves: the cell's conditions by name (``--cell
NAME=VALUE``), and the sweeps of docs/evaluation.md (``--sweep NAME``): the sensor
rate, the PLC's cycle, the gripper's speed and class, friction (its level, its
velocity strengthening, its Stribeck weakening) and mass, a normal force lost at a
slide's onset, and the latency budget.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

from .grippers import GRIPPER_CLASS, get_gripper_class
from .runner import Setup

#: A condition: what it changes, given its value.
Condition = Callable[[Setup, float], Setup]


def _chain(setup: Setup, **changes: object) -> Setup:
    return replace(setup, chain=replace(setup.chain, **changes))  # type: ignore[arg-type]


def _actuator(setup: Setup, **changes: float) -> Setup:
    return _chain(setup, actuator=replace(setup.chain.actuator, **changes))


def _batch(setup: Setup, **changes: float) -> Setup:
    return replace(setup, batch=replace(setup.batch, **changes))  # type: ignore[arg-type]


#: NAME -> (what it is, its unit, how it changes the setup).
CONDITIONS: dict[str, tuple[str, str, Condition]] = {
    "rate": ("the sensor's scan rate", "Hz", lambda s, v: _chain(s, rate_hz=v)),
    "plc_cycle": ("the PLC's scan cycle", "ms", lambda s, v: _chain(s, plc_cycle_s=v / 1000.0)),
    "actuator_rate": ("the gripper's force slew rate", "N/s", lambda s, v: _actuator(s, rate_n_per_s=v)),
    "dead_time": ("the gripper's dead time", "ms", lambda s, v: _actuator(s, dead_s=v / 1000.0)),
    "latency": ("added to the scan -> PLC transport", "ms", lambda s, v: _chain(s, extra_latency_s=v / 1000.0)),
    "mass": ("the specimens' mass (and pour) over the recipe's", "x", lambda s, v: _batch(s, mass_scale=v)),
    "friction": ("the specimens' friction over the recipe's", "x", lambda s, v: _batch(s, mu_scale=v)),
    "accel": ("the program's accelerations", "x", lambda s, v: _batch(s, accel_scale=v)),
    "viscous": ("the pads' velocity strengthening", "s/m", lambda s, v: _chain(s, viscous_s_per_m=v)),
    "stribeck": ("the friction law's Stribeck speed (0: no weakening, no stick-slip)", "mm/s",
                 lambda s, v: _batch(s, stribeck_mm_s=v)),
    "force_drop": ("the normal force the sensed pad loses at a slide's onset", "share",
                   lambda s, v: _batch(s, force_drop=v)),
}
#: Conditions that may be 0 (the others must be positive).
ZERO_ALLOWED = frozenset({"latency", "viscous", "stribeck", "force_drop"})
#: Conditions whose value is a name: NAME -> (what it is, the names).
NAMED: dict[str, tuple[str, tuple[str, ...]]] = {
    "gripper": ("the gripper class (its force range, steps and error)", tuple(GRIPPER_CLASS)),
}


def gripper(setup: Setup, name: str) -> Setup:
    """``setup`` with the drive of the gripper class ``name`` (its recipes follow it)."""
    return _chain(setup, actuator=get_gripper_class(name).spec(setup.chain.actuator))

#: The sweeps: NAME -> (condition, values).  The default setup's value is in each.
SWEEPS: dict[str, tuple[str, tuple[float, ...]]] = {
    "rate": ("rate", (100.0, 1000.0)),
    "plc-cycle": ("plc_cycle", (4.0, 10.0, 20.0)),
    "actuator": ("actuator_rate", (20.0, 50.0, 200.0, 500.0, 1000.0)),
    "dead-time": ("dead_time", (5.0, 10.0, 20.0, 40.0)),
    "friction": ("friction", (0.7, 0.85, 1.0, 1.15)),
    "mass": ("mass", (0.8, 1.0, 1.25, 1.5)),
    "latency": ("latency", (0.0, 20.0, 50.0, 100.0, 200.0)),
    "viscous": ("viscous", (0.0, 0.5, 1.0, 2.0, 4.0)),
    "stribeck": ("stribeck", (0.0, 2.0, 5.0, 10.0)),
    "force-drop": ("force_drop", (0.0, 0.1, 0.2, 0.3)),
}
#: The sweeps over named values.
NAMED_SWEEPS: dict[str, tuple[str, tuple[str, ...]]] = {
    "gripper": ("gripper", tuple(GRIPPER_CLASS)),
}


def apply(setup: Setup, name: str, value: float | str) -> Setup:
    if name in NAMED:
        return gripper(setup, str(value))
    if name not in CONDITIONS:
        raise KeyError(f"unknown cell condition {name!r}; known: {', '.join([*CONDITIONS, *NAMED])}")
    return CONDITIONS[name][2](setup, float(value))
