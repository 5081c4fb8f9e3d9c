"""The object between two fingers, stepped in time: friction decides whether it sticks
or slides, the slide is integrated, the object drops once it has slid off the contact
and breaks once the grip passes its crush force.

The model (docs/cell.md, *Physics*, with what it leaves out):

- in the gripper's frame the object feels a load in the pads' plane, ``m (g - a)``
  (gravity along x, ``a`` the arm's acceleration); while the table carries it, none;
- the two pads hold it with ``2 mu_s F`` at most (``F`` the grip force); beyond that it
  slides, against ``2 F mu(v)``, the friction law of the slip speed ``v``:
  ``mu(v) = mu_k + (mu_s - mu_k) exp(-v / v_S) + c_v v``: kinetic friction, a Stribeck
  term (friction falling from static to kinetic over ``v_S``; ``v_S = 0``: at once, the
  classic Coulomb pair) and the pads' velocity strengthening ``c_v`` (0: pure Coulomb);
  it sticks again when it stops and the load is within ``2 mu_s F``;
- stick-slip: where the friction law weakens with speed at the slide's speed (the
  Stribeck term's fall outweighs ``c_v``), a steady slide is unstable and the pad's
  surface sticks to the object, is dragged along, and snaps back, once per stroke: a
  relaxation oscillation whose stroke grows with the friction released
  (``mu_s - mu(v)``) and whose rate is the slide's speed over the stroke.  Where the
  law does not weaken (Coulomb with ``v_S = 0``, or ``c_v`` strong enough), slides are
  smooth: no ripple;
- semi-implicit Euler on a fixed tick (1 ms), the speed-strengthening term implicit (it
  is stiff under a firm grip on a light object), the Stribeck term explicit (bounded).

No I/O, no clock: the caller advances it.  Streaming state is the object's displacement
and velocity in the gripper's frame, the pad's stick-slip phase, and what happened
(onsets, distance, drop, crush).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

G = 9.81  #: m/s^2
#: Slid this far (mm, from where it was gripped) the object has left the fingers'
#: contact: dropped.  A finger pad is 20-30 mm long; 10-30 mm is the range published.
DROP_MM = 15.0
#: The pads' velocity strengthening: friction coefficient gained per m/s of slip (0.025
#: at 25 mm/s).  An assumption (docs/cell.md, *Physics*: rubber's friction is published
#: to rise with the logarithm of the speed; no slope for gripper pads was found to
#: check), swept from 0 (pure Coulomb) to 4 s/m in docs/evaluation.md.
VISCOUS_S_PER_M = 1.0


@dataclass(frozen=True)
class Friction:
    mu_s: float
    mu_k: float
    viscous_s_per_m: float = VISCOUS_S_PER_M
    #: the Stribeck speed ``v_S`` (m/s) over which friction falls from static to kinetic;
    #: 0: at once (no velocity weakening once it slides)
    stribeck_m_per_s: float = 0.0
    contacts: int = 2  #: two fingers, each pressing with the grip force

    def __post_init__(self) -> None:
        if not 0 < self.mu_k <= self.mu_s:
            raise ValueError(f"friction: expected 0 < mu_k <= mu_s, got mu_k {self.mu_k}, mu_s {self.mu_s}")
        if not (self.viscous_s_per_m >= 0 and self.stribeck_m_per_s >= 0):
            raise ValueError(f"friction: expected c_v >= 0 and v_S >= 0, got {self.viscous_s_per_m}, "
                             f"{self.stribeck_m_per_s}")

    def weakening(self, speed: float) -> float:
        """The Stribeck term at ``speed`` (m/s): what friction has still to lose."""
        if self.stribeck_m_per_s <= 0.0:
            return 0.0
        return (self.mu_s - self.mu_k) * math.exp(-speed / self.stribeck_m_per_s)

    def mu(self, speed: float) -> float:
        """The friction coefficient of a slide at ``speed`` (m/s, > 0)."""
        return self.mu_k + self.weakening(speed) + self.viscous_s_per_m * speed

    @property
    def weakens_below_m_per_s(self) -> float:
        """The speed below which the friction law falls with speed (``mu'(v) < 0``): a
        slide slower than this sticks and slips; 0: the law never weakens."""
        drop, vs, cv = self.mu_s - self.mu_k, self.stribeck_m_per_s, self.viscous_s_per_m
        if vs <= 0.0 or drop <= 0.0:
            return 0.0
        if cv <= 0.0:
            return math.inf
        ratio = drop / (vs * cv)
        return vs * math.log(ratio) if ratio > 1.0 else 0.0


@dataclass
class Contact:
    """The object's state relative to the fingers (SI units inside, mm outside)."""

    friction: Friction
    crush_n: float = math.inf
    drop_mm: float = DROP_MM
    #: the pad's stick-slip stroke (m) where the whole static-kinetic difference is
    #: released (its shear compliance times the force released; less as less is released)
    stroke_full_m: float = 0.0002
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
    #: the pad's surface, dragged by the object since its last snap (m), and the stroke
    #: at which it snaps back (0: a smooth slide)
    pad_m: float = 0.0
    stroke_m: float = 0.0
    stick_slips: int = 0  #: snaps counted over the episode

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
        kin = (fr.mu_k + fr.weakening(speed)) * normal  # the Stribeck term at the last speed: explicit
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
        self._pad(math.hypot(nx, ny), dt)
        if math.hypot(self.x, self.y) * 1000.0 >= self.drop_mm:
            self.dropped_at = t
            self._stop(t)

    def _pad(self, speed: float, dt: float) -> None:
        """The pad's stick-slip over one tick of a slide at ``speed``: dragged along while
        it sticks to the object, snapped back by a stroke once it holds no more.  Only
        where the friction law weakens at this speed; elsewhere the slide is smooth."""
        fr = self.friction
        released = fr.mu_s - fr.mu(speed) if 0.0 < speed < fr.weakens_below_m_per_s else 0.0
        if released <= 0.0:
            self.pad_m = self.stroke_m = 0.0
            return
        self.stroke_m = self.stroke_full_m * released / (fr.mu_s - fr.mu_k)
        self.pad_m += speed * dt
        if self.pad_m >= self.stroke_m:
            self.stick_slips += int(self.pad_m // self.stroke_m)
            self.pad_m %= self.stroke_m

    @property
    def ripple(self) -> float:
        """Where the pad is in its stroke, -1 (just snapped back) to 1 (about to), and 0
        in a smooth slide or at rest."""
        return 2.0 * self.pad_m / self.stroke_m - 1.0 if self.stroke_m > 0.0 else 0.0

    @property
    def released(self) -> float:
        """The share of the static-kinetic difference the current stroke releases (0-1)."""
        fr = self.friction
        return self.stroke_m / self.stroke_full_m if self.stroke_full_m > 0 and fr.mu_s > fr.mu_k else 0.0

    def _stop(self, t: float) -> None:
        self.sliding = False
        self.pad_m = self.stroke_m = 0.0
        if self.slides and self.slides[-1][1] is None:
            self.slides[-1] = (self.slides[-1][0], t)
