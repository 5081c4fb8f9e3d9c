"""What the closed-loop evaluation moves: the cell's conditions by name (``--cell
NAME=VALUE``), and the sweeps of docs/evaluation.md (``--sweep NAME``): the sensor
rate, the PLC's cycle, the gripper's speed, friction and mass, and the latency budget.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

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
}

#: The sweeps: NAME -> (condition, values).  The default setup's value is in each.
SWEEPS: dict[str, tuple[str, tuple[float, ...]]] = {
    "rate": ("rate", (100.0, 1000.0)),
    "plc-cycle": ("plc_cycle", (4.0, 10.0, 20.0)),
    "actuator": ("actuator_rate", (20.0, 50.0, 200.0, 500.0, 1000.0)),
    "dead-time": ("dead_time", (5.0, 10.0, 20.0, 40.0)),
    "friction": ("friction", (0.7, 0.85, 1.0, 1.15)),
    "mass": ("mass", (0.8, 1.0, 1.25, 1.5)),
    "latency": ("latency", (0.0, 20.0, 50.0, 100.0, 200.0)),
    "viscous": ("viscous", (1.0, 2.0, 4.0, 8.0)),
}


def apply(setup: Setup, name: str, value: float) -> Setup:
    if name not in CONDITIONS:
        raise KeyError(f"unknown cell condition {name!r}; known: {', '.join(CONDITIONS)}")
    return CONDITIONS[name][2](setup, value)
