"""The object between two fingers, stepped in time: Coulomb friction decides whether it
sticks or slides, the slide is integrated, the object drops once it has slid off the
contact and breaks once the grip passes its crush force.

The model (docs/cell.md, *Physics*, with what it leaves out):

- in the gripper's frame the object feels a load in the pads' plane, ``m (g - a)``
  (gravity along x, ``a`` the arm's acceleration); while the table carries it, none;
- the two pads hold it with ``2 mu_s F`` at most (``F`` the grip force); beyond that it
  slides, against ``2 F (mu_k + c_v |v|)``: kinetic friction and the pads' velocity
  strengthening (an elastomer's friction grows with slip speed), which makes a slide
  under a small excess load a steady one of cm/s; it sticks again when it stops and the
  load is within ``2 mu_s F``;
- semi-implicit Euler on a fixed tick (1 ms), the speed-dependent term implicit (it is
  stiff under a firm grip on a light object).

No I/O, no clock: the caller advances it.  Streaming state is the object's displacement
and velocity in the gripper's frame, and what happened (onsets, distance, drop, crush).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

G = 9.81  #: m/s^2
#: Slid this far (mm, from where it was gripped) the object has left the fingers'
#: contact: dropped.  A finger pad is 20-30 mm long; 10-30 mm is the range published.
DROP_MM = 15.0
#: The pads' velocity strengthening: friction coefficient gained per m/s of slip
#: (0.1 at 25 mm/s; an assumption, swept in docs/evaluation.md).
VISCOUS_S_PER_M = 4.0


@dataclass(frozen=True)
class Friction:
    mu_s: float
    mu_k: float
    viscous_s_per_m: float = VISCOUS_S_PER_M
    contacts: int = 2  #: two fingers, each pressing with the grip force

    def __post_init__(self) -> None:
        if not 0 < self.mu_k <= self.mu_s:
            raise ValueError(f"friction: expected 0 < mu_k <= mu_s, got mu_k {self.mu_k}, mu_s {self.mu_s}")


@dataclass
class Contact:
    """The object's state relative to the fingers (SI units inside, mm outside)."""

    friction: Friction
    crush_n: float = math.inf
    drop_mm: float = DROP_MM
    t: float = 0.0
    x: float = 0.0  #: displacement from where it was gripped (m), x down
    y: float = 0.0
    vx: float = 0.0  #: its velocity relative to the fingers (m/s)
    vy: float = 0.0
    sliding: bool = False
    slid_m: float = 0.0  #: path length slid
    dropped_at: float | None = None
    crushed_at: float | None = None
    #: (start, end) of each slide; the last one's end is None while it lasts
    slides: list[tuple[float, float | None]] = field(default_factory=list)

    @property
    def over(self) -> bool:
        return self.dropped_at is not None or self.crushed_at is not None

    @property
    def displacement_mm(self) -> tuple[float, float]:
        return self.x * 1000.0, self.y * 1000.0

    @property
    def speed_mm_s(self) -> float:
        return math.hypot(self.vx, self.vy) * 1000.0

    @property
    def slid_mm(self) -> float:
        return self.slid_m * 1000.0

    def step(self, dt: float, grip_n: float, mass_kg: float, ax: float, ay: float, held: bool,
             t: float | None = None) -> None:
        """Advance by ``dt`` with the grip force ``grip_n`` and the arm's acceleration;
        ``held``: the fingers carry the object (else the table does: nothing moves);
        ``t``: the time at the end of the step (default: ``dt`` past the last)."""
        t = self.t + dt if t is None else t
        self.t = t
        if self.over:
            return
        if grip_n >= self.crush_n:
            self.crushed_at = t
            return
        if not held:
            if self.sliding:
                self._stop(t)
            return
        fr = self.friction
        normal = fr.contacts * grip_n
        # the load the fingers must carry, in their frame: gravity less the arm's acceleration
        px, py = mass_kg * (G - ax), mass_kg * (-ay)
        load = math.hypot(px, py)
        vx, vy = self.vx, self.vy
        if not self.sliding:
            if load <= fr.mu_s * normal:
                return  # stuck: static friction takes the load
            self.sliding = True
            self.slides.append((t, None))
        speed = math.hypot(vx, vy)
        # kinetic friction opposes the motion, or the load when starting from rest
        if speed > 0.0:
            ux, uy = vx / speed, vy / speed
        else:
            ux, uy = px / load, py / load
        kin = fr.mu_k * normal
        damp = dt * normal * fr.viscous_s_per_m / mass_kg  # implicit: stiff under a firm grip
        nx = (vx + dt * (px - kin * ux) / mass_kg) / (1.0 + damp)
        ny = (vy + dt * (py - kin * uy) / mass_kg) / (1.0 + damp)
        if speed > 0.0 and nx * vx + ny * vy <= 0.0:
            # it would reverse within the tick: it stops, and sticks if static friction holds it
            nx = ny = 0.0
            if load <= fr.mu_s * normal:
                self.vx = self.vy = 0.0
                self._stop(t)
                return
        self.vx, self.vy = nx, ny
        self.x += nx * dt
        self.y += ny * dt
        self.slid_m += math.hypot(nx, ny) * dt
        if math.hypot(self.x, self.y) * 1000.0 >= self.drop_mm:
            self.dropped_at = t
            self._stop(t)

    def _stop(self, t: float) -> None:
        self.sliding = False
        if self.slides and self.slides[-1][1] is None:
            self.slides[-1] = (self.slides[-1][0], t)
