"""The cell's world, advanced tick by tick: the task's timeline, the gripper's drive
and the object's contact, and the frames the node renders from them.  What the
real-time run and the virtual-time run share: each calls :meth:`CellWorld.advance_to`
and :meth:`CellWorld.frame`, and only the commands' arrival times differ.

No I/O and no clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .actuator import Actuator, ActuatorSpec
from .objects import CellObject, Specimen
from .physics import Contact, Friction, G
from .render import FrameRenderer
from .task import Task

#: The physics' tick (s): 1 kHz, the fastest sensor rate and a tenth of the slowest
#: PLC cycle.
TICK_S = 0.001
#: After a drop or a crush the episode runs this much longer (the skin sees it go).
TAIL_S = 0.3
#: A normal force lost at a slide's onset (``Specimen.force_drop``) is all gone this
#: long after the onset, and back this long after the object sticks again.
DROP_RISE_S = 0.02
DROP_RECOVER_S = 0.1


@dataclass(frozen=True)
class Episode:
    """One object, one task, one seed: everything random about an episode."""

    seed: int
    specimen: Specimen
    task: Task
    #: the seed of the sensor's draws (noise, jitter), apart from the physics' draws
    render_seed: int

    @property
    def kind(self) -> CellObject:
        return self.specimen.kind

    def describe(self) -> str:
        s = self.specimen
        crush = f", crushes at {s.crush_n:.1f} N" if s.fragile else ""
        pour = f" + {s.pour_kg * 1000:.0f} g poured" if s.pour_kg else ""
        return (f"{s.kind.name} (seed {self.seed}): {s.mass_kg * 1000:.0f} g{pour}, mu_s {s.mu_s:.2f}, "
                f"mu_k {s.mu_k:.2f}{crush}")


class CellWorld:
    """The physical cell of one episode."""

    def __init__(self, episode: Episode, actuator: ActuatorSpec, rate_hz: float,
                 viscous_s_per_m: float | None = None) -> None:
        s = episode.specimen
        self.episode = episode
        self.table = episode.task.table(TICK_S, s.mass_kg)
        tab = self.table
        # the load the fingers carry at each tick (0 while the table carries it): for
        # skipping ahead while the object sticks and the grip is steady
        self._load = np.where(tab.held, np.hypot(np.asarray(tab.mass) * (G - np.asarray(tab.ax)),
                                                 np.asarray(tab.mass) * np.asarray(tab.ay)), 0.0)
        self._held = np.asarray(tab.held)
        friction = Friction(s.mu_s, s.mu_k, stribeck_m_per_s=s.stribeck_m_per_s) if viscous_s_per_m is None else \
            Friction(s.mu_s, s.mu_k, viscous_s_per_m, s.stribeck_m_per_s)
        self.contact = Contact(friction, s.crush_n, stroke_full_m=2.0 * s.kind.stick_slip_mm / 1000.0)
        # the drive's force error: drawn once per episode, apart from every other draw
        error = float(np.random.default_rng((episode.seed, 3801)).uniform(-1.0, 1.0)) * actuator.error_share \
            if actuator.error_share else 0.0
        self.actuator = Actuator(actuator, error)
        self.rate_hz = rate_hz
        frames = int(math.ceil((episode.task.end_s + TAIL_S) * rate_hz)) + 2
        self.renderer = FrameRenderer(s.kind, rate_hz, frames, np.random.default_rng(episode.render_seed))
        self.k = 0  #: ticks done
        self.grip_n = 0.0
        self.holding_s = 0.0  #: time the fingers carried the object, intact
        self.grip_ns = 0.0  #: the grip force integrated over that time (N s)
        self.peak_n = 0.0  #: the largest grip force while holding
        self._end_s = episode.task.end_s

    @property
    def t(self) -> float:
        return self.k * TICK_S

    @property
    def done(self) -> bool:
        c = self.contact
        over = c.dropped_at if c.dropped_at is not None else c.crushed_at
        end = self._end_s if over is None else min(self._end_s, over + TAIL_S)
        return self.t >= end - 1e-9

    def command(self, t_arrival: float, request_n: float) -> None:
        """A force request that reached the gripper at ``t_arrival`` (s)."""
        self.actuator.command(t_arrival, request_n)

    def advance_to(self, t: float) -> None:
        """Every tick up to ``t`` (s)."""
        table, contact, actuator = self.table, self.contact, self.actuator
        last = len(table) - 1
        target = int(math.floor(t / TICK_S + 1e-9))
        dt = TICK_S
        while self.k < target:
            if not contact.sliding and not contact.over and actuator.settled and self.k < last:
                self._skip(min(target, last))
                if self.k >= target:
                    break
            k = min(self.k, last)
            self.k += 1
            grip = actuator.step(self.k * dt, dt)
            self.grip_n = grip
            contact.step(dt, grip, table.mass[k], table.ax[k], table.ay[k], table.held[k], self.k * dt)
            if table.held[k] and not contact.over:
                self.holding_s += dt
                self.grip_ns += grip * dt
                if grip > self.peak_n:
                    self.peak_n = grip

    def _skip(self, target: int) -> None:
        """Ticks up to ``target`` at once while nothing can happen: the object sticks,
        the grip is steady (below its crush force), and the load stays within static
        friction; stops at the first tick that would make it slide (the caller steps it)."""
        grip = self.actuator.force_n
        c = self.contact
        if grip >= c.crush_n:
            return
        k = self.k
        cap = c.friction.mu_s * c.friction.contacts * grip
        over = np.flatnonzero(self._load[k:target] > cap)
        stop = k + int(over[0]) if over.size else target
        if stop <= k:
            return
        held = int(np.count_nonzero(self._held[k:stop]))
        self.holding_s += held * TICK_S
        self.grip_ns += held * TICK_S * grip
        if held and grip > self.peak_n:
            self.peak_n = grip
        self.grip_n = grip
        self.k = stop
        c.t = stop * TICK_S

    def frame(self, index: int, t: float) -> np.ndarray:
        """Frame ``index`` (at ``t``) as the array sees the cell now: nothing once the
        object has gone (dropped) or given way (crushed); the pad's stick-slip where the
        physics has one (its stroke along the slide, the grip's ripple with it), and the
        normal force the sensed pad loses at a slide's onset."""
        c = self.contact
        kind = self.episode.kind
        force = 0.0 if c.over else self.grip_n
        dx, dy = c.displacement_mm
        ripple = c.ripple
        if ripple:
            speed = math.hypot(c.vx, c.vy)
            ux, uy = (c.vx / speed, c.vy / speed) if speed > 0 else (1.0, 0.0)
            wobble = kind.stick_slip_mm * c.released * ripple
            dx += wobble * ux
            dy += wobble * uy
            force *= 1.0 + kind.stick_slip_force * c.released * ripple
        drop = self.episode.specimen.force_drop
        if drop and force > 0.0:
            force *= 1.0 - drop * self._drop_level(t)
        return self.renderer.frame(index, t, force, dx, dy)

    def _drop_level(self, t: float) -> float:
        """How much of a slide's normal-force loss holds at ``t`` (0-1): all of it
        ``DROP_RISE_S`` after the onset, gone ``DROP_RECOVER_S`` after the end."""
        slides = self.contact.slides
        if not slides:
            return 0.0
        start, end = slides[-1]
        if end is None or t < end:
            return min(1.0, max(0.0, (t - start) / DROP_RISE_S))
        at_end = min(1.0, (end - start) / DROP_RISE_S)
        return at_end * max(0.0, 1.0 - (t - end) / DROP_RECOVER_S)

    @property
    def mean_grip_n(self) -> float:
        return self.grip_ns / self.holding_s if self.holding_s > 0 else 0.0
