"""The gripper classes the closed loop can run with (``--cell gripper=NAME``): what a
drive does to a force request (its range, its force steps, its force error) and how
fast it follows it.  ``ideal`` is the cell's own drive (any force from 0 N in 0.01 N
steps, exact); the others are shaped after two common electric parallel grippers, from
their published ranges, with the steps and errors marked as assumptions in
docs/cell.md (*Gripper classes*).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from .actuator import ActuatorSpec


@dataclass(frozen=True)
class GripperClass:
    name: str
    description: str
    min_n: float
    max_n: float
    step_n: float
    error_share: float

    def spec(self, base: ActuatorSpec) -> ActuatorSpec:
        """``base`` (its rate and dead time) with this class's force range, steps and error."""
        return replace(base, min_n=self.min_n, max_n=self.max_n, step_n=self.step_n, error_share=self.error_share)


GRIPPER_CLASSES: tuple[GripperClass, ...] = (
    GripperClass("ideal", "the cell's own drive: any force from 0 N, 0.01 N steps, exact", 0.0, 100.0, 0.0, 0.0),
    GripperClass("small", "a small precise gripper (RG2-like): 3-40 N in 1 N steps, +-5 %", 3.0, 40.0, 1.0, 0.05),
    GripperClass("coarse", "a Robotiq-class gripper (2F-85-like): 20-235 N in 256 steps (0.84 N), +-8 %",
                 20.0, 235.0, (235.0 - 20.0) / 255.0, 0.08),
)
GRIPPER_CLASS = {g.name: g for g in GRIPPER_CLASSES}


def get_gripper_class(name: str) -> GripperClass:
    try:
        return GRIPPER_CLASS[name]
    except KeyError:
        raise KeyError(f"unknown gripper class {name!r}; known: {', '.join(GRIPPER_CLASS)}") from None
