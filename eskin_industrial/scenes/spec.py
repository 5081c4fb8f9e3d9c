"""A scene is data: a TOML file that names the array, the contact, what happens over
time, and which sensor imperfections apply.  Built once into frozen dataclasses by the
same validator as the profiles, so a typo in a user's scene is refused with the key."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from ..schema import SchemaError, in_range, non_negative, parse_toml, positive, read_toml_file


@dataclass(frozen=True)
class SceneInfo:
    name: str
    description: str = ""
    #: The profile this scene is meant for (its layout must match ``[array]``).
    profile: str = "paper-5x5"
    duration_s: float = field(default=10.0, metadata=positive())


@dataclass(frozen=True)
class ArraySpec:
    rows: int = field(default=5, metadata=positive())
    cols: int = field(default=5, metadata=positive())
    pitch_mm: float = field(default=5.0, metadata=positive())
    row_pitch_mm: float | None = field(default=None, metadata=positive())


@dataclass(frozen=True)
class Footprint:
    """An object pressing on the array: by default a flat-bottomed rectangle of uniform
    pressure, tilted by a linear gradient (relative change per mm, from its centre)."""

    size_mm: tuple[float, ...] = (20.0, 20.0)
    centre_mm: tuple[float, ...] = (10.0, 10.0)
    gradient_per_mm: tuple[float, ...] = (0.0, 0.0)
    #: Soft contact: the footprint's size scales as (F / reference_force_n)^exponent
    #: (1/3 for a Hertzian pad, 0 for a rigid flat block).
    size_exponent: float = field(default=0.0, metadata=in_range(0.0, 1.0))
    reference_force_n: float = field(default=1.0, metadata=positive())
    #: ``rectangle``: a flat face (uniform pressure); ``cylinder``: a line contact along
    #: y, ``size_mm[0]`` wide, with a semi-elliptic (Hertzian) pressure across it;
    #: ``sphere``: a point contact, a disc (an ellipse if the sizes differ) of diameter
    #: ``size_mm`` with Hertzian pressure sqrt(1 - r^2 / a^2) (an edge: a narrow cylinder).
    shape: Literal["rectangle", "cylinder", "sphere"] = "rectangle"
    #: Orientation about the normal at the start (degrees; ``rotate`` events add to it).
    angle_deg: float = 0.0

    def __post_init__(self) -> None:
        for key in ("size_mm", "centre_mm", "gradient_per_mm"):
            if len(getattr(self, key)) != 2:
                raise ValueError(f"{key}: expected [x, y], got {len(getattr(self, key))} values")


EventKind = Literal["press", "force", "oscillate", "slide", "rotate", "release"]


@dataclass(frozen=True)
class Event:
    """One thing that happens; the timeline is the list of events in time order.

    - press: the force ramps from 0 to ``force_n`` over ``duration_s`` (label: transition)
    - force: the force ramps to ``force_n`` over ``duration_s`` (variable_force)
    - oscillate: force x (1 + amplitude sin 2 pi f t) for ``duration_s`` (variable_force)
    - slide: the footprint moves by ``distance_mm`` at ``speed_mm_s`` (slip); the force
      may change to ``force_n`` meanwhile (a glass slipping out of a grasp); with
      ``stick_slip_mm = 0`` and ``stick_slip_force = 0`` it is smooth; with ``step_hz``
      it moves in jumps with rests between them; ``lift_off_per_mm``
      tips the object forward as it starts (partial lift-off)
    - rotate: the footprint turns about its own centre by ``angle_deg`` at
      ``angular_speed_deg_s`` (torsional slip: label slip, the centre stays)
    - release: the force ramps to 0 over ``duration_s`` (transition, then no_contact)
    """

    kind: EventKind
    t_s: float = field(metadata=non_negative())
    duration_s: float = field(default=0.3, metadata=non_negative())
    force_n: float | None = field(default=None, metadata=non_negative())
    amplitude: float = field(default=0.0, metadata=non_negative())
    freq_hz: float = field(default=1.0, metadata=positive())
    distance_mm: tuple[float, ...] = (0.0, 0.0)
    speed_mm_s: float = field(default=10.0, metadata=positive())
    #: Stick-slip while sliding: position jitter (mm) and force ripple (fraction) at
    #: ``stick_slip_hz``; the vibration the slide excites.
    stick_slip_mm: float = field(default=0.15, metadata=non_negative())
    stick_slip_force: float = field(default=0.04, metadata=non_negative())
    stick_slip_hz: float = field(default=25.0, metadata=positive())
    #: Stick-slip as discrete jumps (the way it often is: the contact sticks while the
    #: drive loads it, then jumps): ``step_hz`` jumps a second, the footprint at rest
    #: for ``step_rest`` of each period and covering the period's share of the slide in
    #: the rest of it (so the slide keeps its speed, length and label).  Each is one
    #: value, or a range ``[low, high]`` drawn per seed and slide; the periods wander by
    #: 20 %.  The force ripple (``stick_slip_force``) then follows the jumps; the
    #: sawtooth micro-motion (``stick_slip_mm``, ``stick_slip_hz``) is not used.  Empty
    #: (the default): the smooth slide with the sawtooth.
    step_hz: tuple[float, ...] = field(default=(), metadata=in_range(0.5, 100.0))
    step_rest: tuple[float, ...] = field(default=(0.65,), metadata=in_range(0.0, 0.95))
    #: Partial lift-off at slip onset: a pressure gradient (relative change per mm)
    #: along the slide's direction, ramped in over the slide's first ``lift_off_s`` and
    #: out as long after it ends; where 1 + gradient x distance falls below 0 the
    #: trailing part of the footprint carries nothing (the normal force is unchanged).
    lift_off_per_mm: float = field(default=0.0, metadata=non_negative())
    lift_off_s: float = field(default=0.1, metadata=positive())
    #: A normal-force drop at slip onset (a grasp losing part of its squeeze as the
    #: object gives way): the force falls by this fraction over ``force_drop_s`` from
    #: the slide's start and stays down; one value or a range ``[low, high]`` drawn
    #: per seed and slide.  Empty (the default): the force as the other events set it.
    force_drop: tuple[float, ...] = field(default=(), metadata=in_range(0.0, 0.9))
    force_drop_s: float = field(default=0.03, metadata=positive())
    #: Rotation (``rotate``): angle (degrees, signed) and speed.
    angle_deg: float = 0.0
    angular_speed_deg_s: float = field(default=30.0, metadata=positive())

    def __post_init__(self) -> None:
        if self.kind in ("press", "force") and self.force_n is None:
            raise ValueError(f"force_n: expected a force for a {self.kind} event")
        if len(self.distance_mm) != 2:
            raise ValueError("distance_mm: expected [x, y]")
        for key, empty in (("step_hz", True), ("step_rest", False), ("force_drop", True)):
            value = getattr(self, key)
            if not (empty or value) or len(value) > 2 or (len(value) == 2 and value[0] > value[1]):
                raise ValueError(f"{key}: expected one value or a range [low, high]{' (or none)' if empty else ''}, "
                                 f"got {list(value)}")

    @property
    def end_s(self) -> float:
        if self.kind == "slide":
            dist = (self.distance_mm[0] ** 2 + self.distance_mm[1] ** 2) ** 0.5
            return self.t_s + dist / self.speed_mm_s
        if self.kind == "rotate":
            return self.t_s + abs(self.angle_deg) / self.angular_speed_deg_s
        return self.t_s + self.duration_s


@dataclass(frozen=True)
class SensorEffects:
    """What the sensor adds; every effect is off (0, empty) unless set."""

    noise_n: float = field(default=0.01, metadata=non_negative())
    #: The unloaded film's offset: this total (N) spread evenly over the taxels, read
    #: loaded or not (an idle piezoresistive sensor that never reads 0).
    offset_n: float = field(default=0.0, metadata=non_negative())
    gain_mismatch: float = field(default=0.0, metadata=in_range(0.0, 0.9))
    quantization_n: float = field(default=0.0, metadata=non_negative())
    saturation_n: float | None = field(default=None, metadata=positive())
    dead_taxels: tuple[int, ...] = ()
    stuck_taxels: tuple[int, ...] = ()
    stuck_value_n: float = 0.5
    drop_rate: float = field(default=0.0, metadata=in_range(0.0, 0.9))
    machine_vibration_n: float = field(default=0.0, metadata=non_negative())
    machine_vibration_hz: float = field(default=50.0, metadata=positive())
    #: The machine starts shaking at this time (0: from the start).
    machine_vibration_start_s: float = field(default=0.0, metadata=non_negative())
    #: Piezoresistive creep (the TPU/carbon-black film): under a constant load the
    #: reading rises by ``creep_fraction`` of the load with time constant ``creep_s``;
    #: unloading, the excess decays with ``creep_recovery_s`` (longer: hysteresis).
    creep_fraction: float = field(default=0.0, metadata=in_range(0.0, 1.0))
    creep_s: float = field(default=5.0, metadata=positive())
    creep_recovery_s: float = field(default=15.0, metadata=positive())
    #: Baseline drift with temperature: every taxel's offset drifts at this rate
    #: (N/s), each with its own gain 1 + spread x N(0, 1) (and its own sign if large).
    drift_n_per_s: float = 0.0
    drift_spread: float = field(default=0.3, metadata=non_negative())
    #: Crosstalk: each taxel also reads this fraction of each of its (up to four)
    #: row and column neighbours' forces.
    crosstalk: float = field(default=0.0, metadata=in_range(0.0, 0.25))
    #: A jittery mount: the contact's centre wanders by up to this far (mm, each axis)
    #: while it is held, a smooth random motion with nothing sliding (a gripper's
    #: servo hunting, a compliant finger); 0: none.  Its band reaches ``cof_jitter_hz``.
    cof_jitter_mm: float = field(default=0.0, metadata=in_range(0.0, 10.0))
    cof_jitter_hz: float = field(default=3.0, metadata=in_range(0.01, 50.0))


@dataclass(frozen=True)
class SceneSpec:
    scene: SceneInfo
    array: ArraySpec = field(default_factory=ArraySpec)
    footprint: Footprint = field(default_factory=Footprint)
    events: tuple[Event, ...] = ()
    sensor: SensorEffects = field(default_factory=SensorEffects)
    #: After a press or release, this long is "transition" (don't care) in the labels.
    settle_s: float = field(default=0.5, metadata=non_negative())
    #: After a slide or force change ends, this long is still labelled as it was.
    tail_s: float = field(default=0.0, metadata=non_negative())

    def __post_init__(self) -> None:
        n = self.array.rows * self.array.cols
        for key in ("dead_taxels", "stuck_taxels"):
            bad = [i for i in getattr(self.sensor, key) if not 0 <= i < n]
            if bad:
                raise SchemaError(f"sensor.{key}", f"expected taxel indices below {n}, got {bad}")
        starts = [e.t_s for e in self.events]
        if starts != sorted(starts):
            raise SchemaError("events", "expected events in time order")


def parse_scene(text: str, source: str) -> SceneSpec:
    return parse_toml(SceneSpec, text, source)


def load_scene_file(path: Path) -> SceneSpec:
    return parse_scene(read_toml_file(path, "scene"), str(path))
