"""Effect families: sets of scenes that share one kind of physics, for scoring each
method per family and for leave-one-family-out evaluation (``holdout.py``).

The suite's scenes fall into the families they were made for; each new family is
scenes of the suite with one effect switched on (``hook``), or a built-in scene made
for it.  Every family is scored on the same seeds as the suite: ``TUNING_SEEDS`` to
choose, ``EVALUATION_SEEDS`` to report; each new family with draws of its own
(``Family.stream``).
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, replace
from typing import Any

from ..detect.settings import DetectorSettings
from ..progress import NO_PROGRESS, Prefixed, Progress
from ..scenes import SceneSpec
from ..scenes.spec import Event
from .conditions import Hook
from .suite import DEFAULT_SETTINGS, Factory, Result, evaluate

#: The paper's five slides, its varying force, and its still hold: the scenes most new
#: effects are switched on in.
SLIDES: tuple[str, ...] = ("case2", "case3", "case4", "case5", "case6")
PAPER: tuple[str, ...] = ("case1", *SLIDES)


@dataclass(frozen=True)
class Family:
    name: str
    description: str
    scenes: tuple[str, ...]
    #: The one effect switched on in every scene of the family (None: as the scene is).
    hook: Hook | None = None
    #: Whether the suite models it already (``False``: a family of new physics).
    in_suite: bool = False

    @property
    def stream(self) -> int | None:
        """The suite's families draw as the suite does; each new family draws its own
        noise at the same seeds (else most would repeat the suite's few noise-born false
        alarms, on case2 and case4 at tuning seed 4, once per family)."""
        return None if self.in_suite else zlib.crc32(self.name.encode())


def _slides(**changes: Any) -> Hook:
    return lambda s: replace(s, events=tuple(replace(e, **changes) if e.kind == "slide" else e for e in s.events))


def _oscillations(**changes: Any) -> Hook:
    return lambda s: replace(s, events=tuple(replace(e, **changes) if e.kind == "oscillate" else e for e in s.events))


def _sensor(**changes: Any) -> Hook:
    return lambda s: replace(s, sensor=replace(s.sensor, **changes))


def _footprint(**changes: Any) -> Hook:
    return lambda s: replace(s, footprint=replace(s.footprint, **changes))


#: The step-slip family's jumps: how many a second, and the share of each period at
#: rest, each a range drawn per seed and slide (ordinary stick-slip: a jump of
#: 0.2-1 mm at 6-18 Hz with rests of 50-80 % of each period; the step is the slide's
#: speed over the rate, 0.17-1.7 mm on the paper's slides).
STEP_HZ: tuple[float, float] = (6.0, 18.0)
STEP_REST: tuple[float, float] = (0.5, 0.8)

#: The force-drop family's loss of normal force at slip onset, drawn per seed and slide
#: (slides measured elsewhere lose 13-20 % at onset; the range reaches past both ends).
FORCE_DROP: tuple[float, float] = (0.1, 0.3)

#: The shake family's oscillation of the hand's glass (the scene sways it 15 % at 1 Hz):
#: a robot that moves a held load briskly, or stops it short, shakes the grip's force
#: at a few hertz.
SHAKE_AMPLITUDE = 0.25
SHAKE_HZ = 2.5

#: Radius at which a turn moves the footprint's edge as far as the slide it replaces
#: (the 20 mm block's half-width).
TORSION_RADIUS_MM = 10.0


def torsion(spec: SceneSpec) -> SceneSpec:
    """Every slide becomes a turn about the footprint's centre whose edge travels as far
    and as fast (a slide of 6 mm at 10 mm/s: 34 degrees at 57 degrees/s); the sign of
    the turn follows the slide's x direction, so case6 turns back and forth."""
    def turn(e: Event) -> Event:
        if e.kind != "slide":
            return e
        dist = math.hypot(*e.distance_mm)
        sign = 1.0 if e.distance_mm[0] >= 0 else -1.0
        return replace(e, kind="rotate", distance_mm=(0.0, 0.0), angle_deg=sign * math.degrees(dist / TORSION_RADIUS_MM),
                       angular_speed_deg_s=math.degrees(e.speed_mm_s / TORSION_RADIUS_MM))
    return replace(spec, events=tuple(turn(e) for e in spec.events))


def soft(spec: SceneSpec) -> SceneSpec:
    """A soft object: the footprint is its size at the grasp's force and grows as
    force^(1/3) (Hertzian) when the force rises."""
    grip = next((e.force_n for e in spec.events if e.kind == "press" and e.force_n), 1.0)
    return replace(spec, footprint=replace(spec.footprint, size_exponent=1 / 3, reference_force_n=grip))


FAMILIES: dict[str, Family] = {f.name: f for f in (
    # the suite's own
    Family("stick-slip", "the paper's slides (cases 2-6): stick-slip ripple in force and CoF", SLIDES, in_suite=True),
    Family("varying-force", "the paper's case 1: force varies 6-10 N, no sliding", ("case1",), in_suite=True),
    Family("hand", "the 4x5 hand: grab, pour, sway, slip; and its still hold", ("hand", "hand-hold"), in_suite=True),
    Family("hold", "a still 8 N hold of 70 s", ("hold",), in_suite=True),
    Family("creep", "a slow slide: 3 mm at 0.5 mm/s, little stick-slip", ("creep",), in_suite=True),
    Family("partial", "a 6 mm contact on about 4 taxels", ("partial",), in_suite=True),
    Family("vibration", "50 Hz machine vibration, then a slide", ("vibration",), in_suite=True),
    # new physics
    Family("film-creep", "piezoresistive creep of 10 % (5 s) and a 15 s recovery on unloading",
           (*PAPER, "hold"), _sensor(creep_fraction=0.1, creep_s=5.0, creep_recovery_s=15.0)),
    Family("temperature-drift", "every taxel's baseline drifts 0.5 mN/s, each with its own gain (spread 0.5)",
           (*PAPER, "hold"), _sensor(drift_n_per_s=5e-4, drift_spread=0.5)),
    Family("crosstalk", "each taxel reads 8 % of each row and column neighbour", (*PAPER, "hold"), _sensor(crosstalk=0.08)),
    Family("smooth-slide", "the paper's slides with no stick-slip: no ripple in force or CoF", SLIDES,
           _slides(stick_slip_mm=0.0, stick_slip_force=0.0)),
    Family("torsion", "the paper's slides as turns about the normal (torsional slip), and the twist scene: "
           "the CoF stays", (*SLIDES, "twist"), torsion),
    Family("soft", "the paper's cases with a soft object: its footprint grows as force^(1/3)", PAPER, soft),
    Family("lift-off", "the paper's slides tipping forward at onset (0.15 per mm: the trailing 3 mm unload)", SLIDES,
           _slides(lift_off_per_mm=0.15)),
    Family("line-contact", "the paper's cases with a cylinder: a 4 mm line contact across the slide; and the cylinder scene",
           (*PAPER, "cylinder"),
           _footprint(shape="cylinder", size_mm=(4.0, 20.0))),
    Family("point-contact", "the paper's cases with a sphere: an 8 mm Hertzian point contact; and the sphere scene",
           (*PAPER, "sphere"),
           _footprint(shape="sphere", size_mm=(8.0, 8.0))),
    Family("step-slip", "the paper's slides in jumps with rests: 6-18 jumps a second, at rest 50-80 % of each period "
           "(drawn per seed and slide); and the steps scene (2 mm/s on 4 N)", (*SLIDES, "steps"),
           _slides(step_hz=STEP_HZ, step_rest=STEP_REST)),
    Family("force-drop", "the paper's slides losing 10-30 % of their normal force over the first 30 ms "
           "(drawn per seed and slide): a grasp that gives way as the object starts to slide", SLIDES,
           _slides(force_drop=FORCE_DROP)),
    Family("shake", f"the hand's glass shaken, not swayed: {SHAKE_AMPLITUDE * 100:.0f} % at {SHAKE_HZ:g} Hz (its total falls "
           "10 % in 30 ms in each lower half, as fast as a grip that gives way)", ("hand",),
           _oscillations(amplitude=SHAKE_AMPLITUDE, freq_hz=SHAKE_HZ)),
)}


def get_family(name: str) -> Family:
    try:
        return FAMILIES[name]
    except KeyError:
        raise KeyError(f"unknown family {name!r}; families: {', '.join(FAMILIES)}") from None


def family_hook(fam: Family, spec_hook: Hook | None = None) -> Hook | None:
    """The family's effect, then ``spec_hook`` (a condition pushed on top of it)."""
    if spec_hook is None or fam.hook is None:
        return spec_hook or fam.hook
    own = fam.hook
    return lambda spec: spec_hook(own(spec))


def evaluate_families(methods: dict[str, Factory], families: tuple[str, ...], seeds: tuple[int, ...],
                      rate_hz: float = 100.0, settings: DetectorSettings = DEFAULT_SETTINGS, tolerance_s: float = 0.5,
                      progress: Progress = NO_PROGRESS, spec_hook: Hook | None = None) -> dict[str, dict[str, Result]]:
    """Every method on every family's scenes (with its effect on, and ``spec_hook`` after
    it): family -> method -> result; ``progress`` advances by one per method, scene and
    seed, labelled with the family too."""
    out = {}
    for name in families:
        fam = get_family(name)
        out[name] = evaluate(methods, scenes=fam.scenes, seeds=seeds, rate_hz=rate_hz, settings=settings,
                             spec_hook=family_hook(fam, spec_hook), tolerance_s=tolerance_s,
                             progress=Prefixed(progress, f"{name}: "), stream=fam.stream)
    return out
