"""What the arm does with the object: a timeline of acceleration pulses (lift,
transport, bump, place) and pours, drawn per episode, tabulated over the physics'
ticks.

Axes are those of the array: x points down (gravity), y is the horizontal direction in
the pads' plane.  Accelerations are the arm's, in m/s^2: a lift is a pulse of negative
x.  The closing direction (normal to the pads) carries no friction load and is left
out.  Pulses rise and fall over ``rise_s`` (a jerk-limited profile).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...scenes.physics import smooth_ramp
from .objects import CellObject, Specimen


@dataclass(frozen=True)
class Pulse:
    """The arm accelerates by ``accel`` (x, y) over ``duration_s``, ramped in and out
    over ``rise_s``."""

    kind: str  #: lift, transport, bump, place (for the episode's description)
    t_s: float
    duration_s: float
    rise_s: float
    accel: tuple[float, float]

    def envelope(self, t: np.ndarray) -> np.ndarray:
        rise = min(self.rise_s, self.duration_s / 2)
        end = self.t_s + self.duration_s
        inside = (t >= self.t_s) & (t < end)
        env = np.minimum(smooth_ramp((t - self.t_s) / rise), smooth_ramp((end - t) / rise))
        return np.where(inside, env, 0.0)


@dataclass(frozen=True)
class Pour:
    """``kg`` of liquid poured in at a constant rate over ``duration_s``."""

    t_s: float
    duration_s: float
    kg: float


@dataclass(frozen=True)
class Task:
    """One episode's timeline.  The PLC commands the grip at ``grip_s``; the table
    carries the object until ``lift_s`` and again from ``place_s``, when the episode
    ends."""

    grip_s: float
    lift_s: float
    place_s: float
    pulses: tuple[Pulse, ...]
    pours: tuple[Pour, ...] = ()

    @property
    def end_s(self) -> float:
        return self.place_s

    def table(self, dt: float, mass_kg: float) -> TaskTable:
        """Arm acceleration, mass and support at each tick ``k * dt`` up to ``end_s``."""
        n = int(round(self.end_s / dt)) + 1
        t = np.arange(n) * dt
        ax = np.zeros(n)
        ay = np.zeros(n)
        for p in self.pulses:
            env = p.envelope(t)
            ax += p.accel[0] * env
            ay += p.accel[1] * env
        mass = np.full(n, mass_kg)
        for pour in self.pours:
            mass += pour.kg * np.clip((t - pour.t_s) / max(pour.duration_s, 1e-9), 0.0, 1.0)
        held = (t >= self.lift_s) & (t < self.place_s)
        return TaskTable(dt, ax.tolist(), ay.tolist(), mass.tolist(), held.tolist())

    def describe(self) -> str:
        parts = [f"{p.kind} {np.hypot(*p.accel):.1f} m/s^2 at {p.t_s:.2f} s" for p in self.pulses]
        parts += [f"pour {pour.kg * 1000:.0f} g at {pour.t_s:.2f} s over {pour.duration_s:.1f} s" for pour in self.pours]
        return ", ".join(parts)


@dataclass(frozen=True)
class TaskTable:
    """The timeline per tick, as plain lists (the physics reads one value a tick)."""

    dt: float
    ax: list[float]
    ay: list[float]
    mass: list[float]
    held: list[bool]  #: the fingers carry the object (not the table)

    def __len__(self) -> int:
        return len(self.mass)


def _pair(kind: str, t: float, accel: float, ramp_s: float, rise_s: float, cruise_s: float,
          axis: int) -> tuple[list[Pulse], float]:
    """Accelerate, cruise, decelerate along one axis: two pulses; returns them and the end."""
    a = (accel, 0.0) if axis == 0 else (0.0, accel)
    b = (-a[0], -a[1])
    first = Pulse(kind, t, ramp_s, rise_s, a)
    second = Pulse(kind, t + ramp_s + cruise_s, ramp_s, rise_s, b)
    return [first, second], t + 2 * ramp_s + cruise_s


def draw_task(kind: CellObject, specimen: Specimen, rng: np.random.Generator,
              accel_scale: float = 1.0) -> Task:
    """One episode's motions (docs/cell.md, *The task*): grip, wait for the skin's
    first verdict, lift, transport, pour (containers), maybe a bump, hold, place."""
    u = lambda lo, hi: lo + (hi - lo) * float(rng.random())  # noqa: E731
    grip_s = 0.2
    lift_s = 1.6  # the arm waits 1.4 s after the grip command: the skin's warm-up is 0.3-0.6 s
    pulses: list[Pulse] = []
    # lift: up (negative x) then slow down; the load is m (g + a) while speeding up
    lift, t = _pair("lift", lift_s, -u(2.0, 6.0) * accel_scale, u(0.25, 0.4), u(0.05, 0.1), u(0.2, 0.5), 0)
    pulses += lift
    # transport: along y, with a short jerk time, either way
    t += u(0.3, 0.6)
    sign = 1.0 if rng.random() < 0.5 else -1.0
    move, t = _pair("transport", t, sign * u(2.0, 8.0) * accel_scale, u(0.2, 0.4), u(0.02, 0.08), u(0.3, 1.0), 1)
    pulses += move
    pours: list[Pour] = []
    if kind.pour_kg is not None:
        start = t + u(0.5, 1.0)
        pour = Pour(start, u(1.5, 3.0), specimen.pour_kg)
        pours.append(pour)
        t = start + pour.duration_s
    if rng.random() < 0.5:  # a bump: a short jolt in any direction of the pads' plane
        at = t + u(0.5, 2.0)
        angle = u(0.0, 2 * np.pi)
        size = u(5.0, 15.0) * accel_scale
        length = u(0.02, 0.05)
        pulses.append(Pulse("bump", at, length, length / 2, (size * np.cos(angle), size * np.sin(angle))))
        t = at + length
    t += u(1.5, 4.0)  # hold still
    # place: down (positive x: the load falls), then stop (the load rises)
    place, t = _pair("place", t, u(2.0, 5.0) * accel_scale, u(0.2, 0.4), u(0.05, 0.1), u(0.2, 0.4), 0)
    pulses += place
    return Task(grip_s, lift_s, t + 0.2, tuple(pulses), tuple(pours))
