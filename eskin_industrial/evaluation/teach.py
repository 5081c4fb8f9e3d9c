"""Teach-in: a method's thresholds set from the user's own holds (``eskin-bus profile
tune``, docs/profiles.md *Teach-in*).

The rule, for each threshold the method declares (``Method.tunable``): run the method
over the holds (every recording's whole length counts as holding: any slip in it is a
false alarm), cut each score into one-second blocks and take each block's peak; of the
peaks in falling order, skip as many as the target allows with a margin of two
(``floor(rate x hours / 2)``: none under two hours at 1 an hour) and set the threshold
``SAFETY`` times above the next one.  Then run the holds again with the new settings
and count their false alarms: a method whose own state moves with its thresholds (our
method learns its noise only while calm) may still cross, and is then set again from
that run, up to ``ROUNDS`` times.  The holds must last ``min_hold_hours`` at least.

A scene option for the sensor it is proven on lives here too: taxel noise four times
the scenes' default and a centre of force that jitters by up to 1 mm while held
(``jittery``).  No family uses it and no threshold of the project's own was chosen on
it; its seeds are its own (``JITTERY_TUNING_SEEDS`` to teach, ``JITTERY_HELD_OUT_SEEDS``
to check).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..detect.methods import Method, Threshold
from ..detect.settings import DetectorSettings
from ..detect.state import GraspState
from ..detect.updates import UpdateTable
from ..methods import ready_method
from ..scenes import SceneSpec, list_scenes, load_scene, render
from .corpus import EVALUATION_SEEDS, coordinates
from .families import SLIDES
from .metrics import SceneScore, score_scene, spans

_SLIP = int(GraspState.SLIP)
_NO_CONTACT = int(GraspState.NO_CONTACT)

#: The jittery sensor: taxel noise (N rms; the scenes' default is 0.01 N) ...
JITTERY_NOISE_N = 0.04
#: ... and the held contact's centre wandering by up to this far on each axis, in a
#: band up to ``JITTERY_JITTER_HZ`` (a servo that hunts, a compliant finger).
JITTERY_JITTER_MM = 1.0
JITTERY_JITTER_HZ = 20.0
#: Its seeds: to teach, and held out (to check what was taught); no other set's.
JITTERY_TUNING_SEEDS: tuple[int, ...] = tuple(range(3000, 3100))
JITTERY_HELD_OUT_SEEDS: tuple[int, ...] = tuple(range(3100, 3200))

#: The threshold sits this far above the score the rule picks (scores in its units).
SAFETY = 1.25
#: Score peaks are taken per block this long.
BLOCK_S = 1.0
#: The holds are run again at most this many times after the first setting.
ROUNDS = 4


def jittery(spec: SceneSpec, noise_n: float = JITTERY_NOISE_N, jitter_mm: float = JITTERY_JITTER_MM,
            jitter_hz: float = JITTERY_JITTER_HZ) -> SceneSpec:
    """``spec`` seen through the noisy, jittery sensor."""
    return replace(spec, sensor=replace(spec.sensor, noise_n=noise_n, cof_jitter_mm=jitter_mm, cof_jitter_hz=jitter_hz))


def min_hold_hours(per_hour: float) -> float:
    """The shortest holding that can say ``per_hour``: a sixth of the time in which one
    false alarm is allowed (10 minutes at 1 an hour).  Beyond the largest score of that
    long, the safety factor leaves a z-like score's tail far below the rate (on the
    jittery sensor: none in the held-out half hour, tests/profile/test_profile_tune.py)."""
    return 1.0 / (6.0 * per_hour)


@dataclass(frozen=True)
class Hold:
    """One recording of holding: frame times (s) and forces (N, row-major)."""

    name: str
    t: np.ndarray
    forces: np.ndarray

    @property
    def seconds(self) -> float:
        return float(self.t[-1] - self.t[0]) + (float(np.median(np.diff(self.t))) if len(self.t) > 1 else 0.0)


@dataclass(frozen=True)
class Change:
    key: str
    old: float
    new: float
    #: The value the rule asked for, when a bound of the key held it back (else None).
    wanted: float | None = None


@dataclass(frozen=True)
class Taught:
    method: str
    section: str  #: where the keys sit: ``detector.<key>``, or ``detector`` itself
    changes: tuple[Change, ...]
    settings: DetectorSettings  #: the new settings
    hours: float  #: holding, all recordings
    before: int  #: false alarms on the holds at the old settings ...
    after: int  #: ... and at the new ones
    allowed: int  #: what the rule allowed on the holds (with its margin)
    rounds: int

    @property
    def met(self) -> bool:
        return self.after <= self.allowed


#: After contact begins and before it ends, this long is a grab or a release, not the
#: hold: its updates neither count nor set a threshold (the scenes' ``settle_s``, the
#: "transition" the evaluation does not score).
TRANSITION_S = 0.5


def holding(table: UpdateTable) -> np.ndarray:
    """Which updates of a recording are holding: in contact, and not within
    ``TRANSITION_S`` of the contact's start or of an end inside the recording."""
    t = np.asarray(table.t, float)
    touching = np.asarray(table.state) != _NO_CONTACT
    out = np.zeros(len(t), bool)
    for a, b in spans(touching):
        end = t[b - 1] - TRANSITION_S if b < len(t) else np.inf
        out[a:b] = (t[a:b] >= t[a] + TRANSITION_S) & (t[a:b] <= end)
    return out


def slip_entries(table: UpdateTable) -> int:
    """False alarms in a recording of holding: each entry into the slip state, but for
    those wholly within a grab or a release (``holding``)."""
    held = holding(table)
    return sum(1 for a, b in spans(np.asarray(table.state) == _SLIP) if held[a:b].any())


def run(method: Method, settings: DetectorSettings, x_mm: np.ndarray, y_mm: np.ndarray, rate_hz: float,
        hold: Hold) -> UpdateTable:
    """The method's stream detector over one recording (frame by frame: the live path)."""
    det = method.stream(settings, x_mm, y_mm, rate_hz)
    return UpdateTable.from_updates(det.feed(hold.t, hold.forces, None))


def _column(method: Method, score: str) -> str:
    names = [s.name for s in method.scores]
    if score not in names:
        raise ValueError(f"method {method.name}: a threshold reads score {score!r}, which is none of its {names}")
    return ("score_a", "score_b")[names.index(score)]


def block_peaks(tables: list[UpdateTable], columns: tuple[str, ...], below: bool = False) -> np.ndarray:
    """Each one-second block's most alarming score over ``columns`` (the largest, or with
    ``below`` the smallest, negated) while holding, every recording's blocks, in falling
    order."""
    peaks: list[np.ndarray] = []
    for tab in tables:
        ok = np.asarray(tab.valid, bool) & holding(tab)
        if not ok.any():
            continue
        scores = np.column_stack([np.asarray(getattr(tab, c), float) for c in columns])[ok]
        worst = (-scores.min(axis=1)) if below else scores.max(axis=1)
        t = np.asarray(tab.t, float)[ok]
        block = np.floor((t - t[0]) / BLOCK_S).astype(np.int64)
        out = np.full(int(block[-1]) + 1, -np.inf)
        np.maximum.at(out, block, np.where(np.isfinite(worst), worst, -np.inf))
        peaks.append(out[np.isfinite(out)])
    return np.sort(np.concatenate(peaks))[::-1] if peaks else np.zeros(0)


def _bounds(cls: type, key: str) -> tuple[float, float]:
    f = next(f for f in dataclasses.fields(cls) if f.name == key)
    lo, hi = f.metadata.get("range", (-math.inf, math.inf))
    return float(lo), float(hi)


def _with(method: Method, settings: DetectorSettings, values: dict[str, Any]) -> DetectorSettings:
    """``settings`` with the method's keys set to ``values``."""
    if method.key == "":  # the paper's rule: its varying-force thresholds stay at most the slip ones
        floors = {f"variable_{k.removeprefix('slip_')}": min(getattr(settings, f"variable_{k.removeprefix('slip_')}"), v)
                  for k, v in values.items() if k in ("slip_r_coe", "slip_r_dw")}
        return replace(settings, **values, **floors)
    own = replace(method.settings_of(settings), **values)
    if method.key in {f.name for f in dataclasses.fields(DetectorSettings)}:
        return replace(settings, **{method.key: own})
    return settings.with_section(method.key, own)


def _set(method: Method, threshold: Threshold, own: Any, level: float) -> dict[str, tuple[float, float | None]]:
    """The keys of ``threshold`` set from the picked score ``level`` (in the score's
    unit; negated for ``below``): key -> (value within bounds, the value wanted if a
    bound held it back)."""
    out: dict[str, tuple[float, float | None]] = {}
    for key in threshold.keys:
        old = float(getattr(own, key))
        if threshold.relative:
            wanted = old * max(level, 0.0) * SAFETY
        elif threshold.direction == "below":
            wanted = -level / SAFETY
        else:
            wanted = level * SAFETY
        lo, hi = _bounds(type(own), key)
        value = min(max(wanted, lo), hi)
        out[key] = (round(value, 6), None if value == wanted else round(wanted, 6))
    return out


def teach(method_name: str, settings: DetectorSettings, x_mm: np.ndarray, y_mm: np.ndarray, rate_hz: float,
          holds: list[Hold], per_hour: float = 1.0) -> Taught:
    """The method's declared thresholds set from ``holds`` by the module's rule."""
    method = ready_method(method_name, settings)
    if not method.tunable:
        raise ValueError(f"method {method.name} declares no threshold to teach")
    hours = sum(h.seconds for h in holds) / 3600.0
    allowed = int(math.floor(per_hour * hours / 2.0))
    first = [run(method, settings, x_mm, y_mm, rate_hz, h) for h in holds]
    before = sum(slip_entries(t) for t in first)
    old = method.settings_of(settings)
    start = {k: float(getattr(old, k)) for th in method.tunable for k in th.keys}
    wanted: dict[str, float | None] = {}
    tables, current, rounds, after = first, settings, 0, before
    while rounds == 0 or (after > allowed and rounds <= ROUNDS):
        own = method.settings_of(current)
        values: dict[str, Any] = {}
        for th in method.tunable:
            peaks = block_peaks(tables, tuple(_column(method, s) for s in th.scores), th.direction == "below")
            level = float(peaks[allowed]) if allowed < len(peaks) else 0.0
            if rounds and th.relative:
                level = max(level, 1.0 / SAFETY + 1e-9)  # (a later round only raises: never undo the first)
            for key, (value, want) in _set(method, th, own, level).items():
                values[key] = value
                wanted[key] = want
        current = _with(method, current, values)
        tables = [run(method, current, x_mm, y_mm, rate_hz, h) for h in holds]
        after = sum(slip_entries(t) for t in tables)
        rounds += 1
        if all(w is not None for w in wanted.values()):
            break  # every key at its bound: another round cannot move them
    new = method.settings_of(current)
    changes = tuple(Change(k, v, float(getattr(new, k)), wanted.get(k)) for k, v in start.items())
    section = "detector" if method.key == "" else f"detector.{method.key}"
    return Taught(method.name, section, changes, current, hours, before, after, allowed, rounds)


@dataclass(frozen=True)
class SensorNoise:
    """What the holds show of the sensor: taxel noise (N rms) and the centre of force's
    largest excursion from its mean while held (mm)."""

    noise_n: float
    jitter_mm: float


def sensor_noise(holds: list[Hold], x_mm: np.ndarray, y_mm: np.ndarray) -> SensorNoise:
    """Estimated from the holds, over the frames of firm contact (half the median total
    or more): the taxels' noise from the spread of their changes from frame to frame (a
    robust one, the median absolute change, of the loaded taxels), and the jitter from
    the spread of the centre of force less what that noise alone spreads it by (each
    axis; the larger), turned into the largest excursion the scenes' jitter of that
    spread makes over as long (``physics.cof_jitter`` scales by its peak)."""
    from ..scenes.physics import cof_jitter

    noise, jitter = [], []
    for h in holds:
        f = np.nan_to_num(np.asarray(h.forces, float))
        total = f.sum(axis=1)
        firm = total >= 0.5 * float(np.median(total[total > 0])) if (total > 0).any() else np.zeros(len(f), bool)
        if firm.sum() < 100:
            continue
        loaded = f[firm]
        mean = loaded.mean(axis=0)
        on = mean > 0.05 * mean.max()
        d = np.diff(loaded[:, on], axis=0)
        sigma = float(np.median(np.median(np.abs(d - np.median(d, axis=0)), axis=0))) * 1.4826 / math.sqrt(2.0)
        noise.append(sigma)
        s = total[firm]
        spread = []
        for coord in (x_mm, y_mm):
            c = loaded @ coord / s
            own = sigma ** 2 * float(np.sum((coord[on] - c.mean()) ** 2)) / float(s.mean()) ** 2
            spread.append(math.sqrt(max(float(c.var()) - own, 0.0)))
        t = h.t[firm]
        unit = cof_jitter(t - t[0], 1.0, JITTERY_JITTER_HZ, np.random.default_rng(0))
        jitter.append(max(spread) / float(unit.std(axis=0).mean()))
    return SensorNoise(float(np.median(noise)) if noise else 0.0, float(np.median(jitter)) if jitter else 0.0)


def slide_scenes(rows: int, cols: int) -> tuple[str, ...]:
    """The project's slides for an array of this shape: the paper's five on the 5 x 5,
    else every built-in scene of that shape with a slide or a turn in it."""
    if (rows, cols) == (5, 5):
        return SLIDES
    out = []
    for name in list_scenes():
        spec = load_scene(name)
        if (spec.array.rows, spec.array.cols) == (rows, cols) and any(e.kind in ("slide", "rotate")
                                                                      for e in spec.events):
            out.append(name)
    return tuple(out)


def slide_score(method_name: str, settings: DetectorSettings, scenes: tuple[str, ...], rate_hz: float,
                sensor: SensorNoise, seeds: tuple[int, ...] = EVALUATION_SEEDS[:2]) -> SceneScore:
    """The method on the project's slides seen through a sensor like the holds' (their
    noise and jitter, ``sensor``), at ``seeds``: slips found, delays, false alarms."""
    method = ready_method(method_name, settings)
    total = SceneScore()
    for name in scenes:
        spec = jittery(load_scene(name), sensor.noise_n, min(sensor.jitter_mm, 10.0), JITTERY_JITTER_HZ)
        for seed in seeds:
            r = render(spec, rate_hz, seed)
            x, y = coordinates(r)
            table = run(method, settings, x, y, rate_hz, Hold(name, r.t, r.forces))
            total += score_scene(table, r.t, r.labels)
    return total


__all__ = ["JITTERY_HELD_OUT_SEEDS", "JITTERY_JITTER_HZ", "JITTERY_JITTER_MM", "JITTERY_NOISE_N",
           "JITTERY_TUNING_SEEDS", "SAFETY", "TRANSITION_S", "Change", "Hold", "SensorNoise", "Taught", "block_peaks",
           "holding", "jittery", "min_hold_hours", "run", "sensor_noise", "slide_scenes", "slide_score", "slip_entries", "teach"]
