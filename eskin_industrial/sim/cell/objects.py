"""What the cell handles: each kind of object as ranges (a catalogue entry), and one
specimen drawn from them per episode.

The integrator knows an object's catalogue values (its design mass, a nominal
friction coefficient, a rated crush force); the specimen in the gripper has its own,
drawn from the ranges, which the integrator does not know.  Ranges and sources:
docs/cell.md (*Objects*).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...scenes.spec import ArraySpec, Footprint, SensorEffects


@dataclass(frozen=True)
class Span:
    """A range a specimen's value is drawn from, uniformly."""

    lo: float
    hi: float

    def __post_init__(self) -> None:
        if not self.lo <= self.hi:
            raise ValueError(f"span: expected lo <= hi, got {self.lo} > {self.hi}")

    def draw(self, rng: np.random.Generator) -> float:
        return self.lo + (self.hi - self.lo) * float(rng.random())

    @property
    def mid(self) -> float:
        return 0.5 * (self.lo + self.hi)

    def scaled(self, factor: float) -> Span:
        return Span(self.lo * factor, self.hi * factor)


@dataclass(frozen=True)
class CellObject:
    """One kind of object: where it lies on the array, and the ranges its specimens
    come from."""

    name: str
    description: str
    #: The built-in profile of the sensor that grips it (its layout is ``array``'s).
    profile: str
    array: ArraySpec
    footprint: Footprint
    mass_kg: Span
    #: Static friction coefficient of the pads on this object.
    mu_s: Span
    #: Kinetic over static friction (kinetic friction is 20-40 % lower).
    mu_k_ratio: Span
    #: Liquid poured in while it is held (containers); None: nothing is poured.
    pour_kg: Span | None = None
    #: The grip force that breaks it; None: not fragile.
    crush_n: Span | None = None
    #: Stick-slip where the friction law makes it (physics.py): half the pad's stroke (mm)
    #: and the force ripple (share of the grip) when the whole static-kinetic difference
    #: is released, the scenes' slides' amplitudes; less as less is released.
    stick_slip_mm: float = 0.1
    stick_slip_force: float = 0.04
    sensor: SensorEffects = field(default_factory=SensorEffects)

    # -- what the integrator knows (the recipe is built from these) -------------------
    @property
    def design_mass_kg(self) -> float:
        """The heaviest it gets: the catalogue's top mass, full if it is filled."""
        return self.mass_kg.hi + (self.pour_kg.hi if self.pour_kg is not None else 0.0)

    @property
    def nominal_mu(self) -> float:
        return self.mu_s.mid

    @property
    def rated_crush_n(self) -> float | None:
        """The crush force the data sheet gives: the middle of the specimens' range."""
        return None if self.crush_n is None else self.crush_n.mid


@dataclass(frozen=True)
class Specimen:
    """The object in the gripper in one episode."""

    kind: CellObject
    mass_kg: float
    mu_s: float
    mu_k: float
    pour_kg: float
    crush_n: float  #: inf when not fragile
    #: the friction law's Stribeck speed (m/s; 0: none): a batch property (``Batch``)
    stribeck_m_per_s: float = 0.0
    #: the share of the normal force the sensed pad loses at a slide's onset (0: none)
    force_drop: float = 0.0

    @classmethod
    def draw(cls, kind: CellObject, rng: np.random.Generator, mass_scale: float = 1.0,
             mu_scale: float = 1.0) -> Specimen:
        """A specimen; ``mass_scale`` and ``mu_scale`` move the ranges (the sweeps: a
        heavier or more slippery batch than the recipe was written for)."""
        mass = kind.mass_kg.draw(rng) * mass_scale
        mu_s = kind.mu_s.draw(rng) * mu_scale
        mu_k = mu_s * kind.mu_k_ratio.draw(rng)
        pour = kind.pour_kg.draw(rng) * mass_scale if kind.pour_kg is not None else 0.0
        crush = kind.crush_n.draw(rng) if kind.crush_n is not None else float("inf")
        return cls(kind, mass, mu_s, mu_k, pour, crush)

    @property
    def fragile(self) -> bool:
        return self.kind.crush_n is not None


_PAD = ArraySpec(rows=5, cols=5, pitch_mm=5.0)
_HAND = ArraySpec(rows=4, cols=5, pitch_mm=5.0, row_pitch_mm=20.0)

#: The objects of the closed-loop evaluation (docs/cell.md, *Objects*).  Silicone
#: pads: static friction 0.3 on oily steel (a gripper maker's worked example), up to
#: 1.0 on glass and plastic; kinetic 20-40 % lower; an egg breaks at 25-45 N; a thin
#: plastic cup buckles at 5-15 N (a guess, swept through its range).
OBJECTS: tuple[CellObject, ...] = (
    CellObject(
        "glass", "the hand's glass: water poured in while it is held", "hand-4x5", _HAND,
        # the hand scene's contact: soft fingertip pads across the four strips
        Footprint(size_mm=(9.0, 80.0), centre_mm=(11.0, 30.0), gradient_per_mm=(0.0, 0.004),
                  size_exponent=0.33, reference_force_n=3.0),
        mass_kg=Span(0.15, 0.25), mu_s=Span(0.6, 1.0), mu_k_ratio=Span(0.65, 0.85), pour_kg=Span(0.10, 0.20),
        stick_slip_mm=0.08, stick_slip_force=0.05),
    CellObject(
        "part", "a machined steel part, oily", "paper-5x5", _PAD,
        Footprint(size_mm=(20.0, 20.0), centre_mm=(10.0, 10.0)),
        mass_kg=Span(0.4, 1.2), mu_s=Span(0.25, 0.45), mu_k_ratio=Span(0.65, 0.85)),
    CellObject(
        "box", "a cardboard box of small parts", "paper-5x5", _PAD,
        Footprint(size_mm=(24.0, 24.0), centre_mm=(10.0, 10.0)),
        mass_kg=Span(0.3, 0.9), mu_s=Span(0.5, 0.8), mu_k_ratio=Span(0.65, 0.85), crush_n=Span(60.0, 120.0)),
    CellObject(
        "egg", "a hen's egg: a point contact, fragile", "paper-5x5", _PAD,
        Footprint(size_mm=(12.0, 12.0), centre_mm=(10.0, 10.0), shape="sphere"),
        mass_kg=Span(0.05, 0.07), mu_s=Span(0.4, 0.7), mu_k_ratio=Span(0.65, 0.85), crush_n=Span(25.0, 45.0)),
    CellObject(
        "cup", "a thin plastic cup, filled while it is held: a line contact, fragile", "paper-5x5", _PAD,
        # the cup's wall along gravity (x): the line contact turned a quarter turn
        Footprint(size_mm=(6.0, 22.0), centre_mm=(10.0, 10.0), shape="cylinder", angle_deg=90.0),
        mass_kg=Span(0.01, 0.02), mu_s=Span(0.35, 0.55), mu_k_ratio=Span(0.65, 0.85), pour_kg=Span(0.15, 0.25),
        crush_n=Span(5.0, 15.0)),
)
OBJECT = {o.name: o for o in OBJECTS}


def get_object(name: str) -> CellObject:
    try:
        return OBJECT[name]
    except KeyError:
        raise KeyError(f"unknown cell object {name!r}; known: {', '.join(OBJECT)}") from None
