"""Leave-one-family-out: choose the deciding method's setting with one effect family
held out, then report that setting on the held-out family.

What is chosen, precisely: one of a few candidate settings of the method
(``CANDIDATES``), on the tuning seeds (``TUNING_SEEDS``) of every *other* family,
by the rule of :func:`choose`; it is then scored on the held-out family's evaluation
seeds (``EVALUATION_SEEDS``), which no choice ever sees.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

from ..detect.settings import DetectorSettings
from ..methods import ready_method
from ..progress import NO_PROGRESS, Progress
from .families import FAMILIES, evaluate_families
from .metrics import SceneScore
from .suite import DEFAULT_SETTINGS, EVALUATION_SEEDS, TUNING_SEEDS, Factory

#: The false-alarm target a candidate must meet before its accuracy counts (per hour
#: of holding; the issue's target for slip).
FALSE_ALARMS_PER_HOUR = 0.5


@dataclass(frozen=True)
class Candidate:
    """A setting to choose among: changes to the detector settings (``top``) and to the
    method's own section (``section``, e.g. ``cof_track``)."""

    label: str
    section: str = ""
    changes: dict[str, Any] = field(default_factory=dict)
    top: dict[str, Any] = field(default_factory=dict)

    def apply(self, settings: DetectorSettings) -> DetectorSettings:
        out = replace(settings, **self.top) if self.top else settings
        if self.section:
            out = replace(out, **{self.section: replace(getattr(out, self.section), **self.changes)})
        return out


#: The candidates per deciding method: its threshold around the default, and (for
#: cof-track) its stick-slip evidence on or off, the one part of it that leans on a
#: single kind of physics, and its step channel on or off (whether the step-slip
#: family's jumps are needed to choose it: held out, they are not seen).
CANDIDATES: dict[str, tuple[Candidate, ...]] = {
    "cof-track": (
        Candidate("default (ramp_z 5.5, evidence on, step channel on)"),
        Candidate("ramp_z 5.0", "cof_track", {"ramp_z": 5.0}),
        Candidate("ramp_z 6.0", "cof_track", {"ramp_z": 6.0}),
        Candidate("no stick-slip evidence (ripple_s 0)", "cof_track", {"ripple_s": 0.0}),
        Candidate("no step channel (step_s 0)", "cof_track", {"step_s": 0.0}),
    ),
    "paper": (
        Candidate("default (R > 2.5)"),
        Candidate("R > 1.0", top={"slip_r_coe": 1.0, "slip_r_dw": 1.0}),
        Candidate("R > 4.0", top={"slip_r_coe": 4.0, "slip_r_dw": 4.0}),
    ),
}


def _factory(method: str, candidate: Candidate, base: DetectorSettings) -> Factory:
    stream = ready_method(method, base).stream
    settings = candidate.apply(base)
    return lambda _settings, x, y, rate: stream(settings, x, y, rate)


def choose(scores: dict[str, SceneScore]) -> str:
    """The candidate (label -> its score, summed over the choosing families) with the
    fewest false alarms per hour beyond ``FALSE_ALARMS_PER_HOUR`` (all within it are
    equal), then the highest event F1, then the smallest median delay; ties go to the
    first candidate (the default).  Delays are compared in whole milliseconds (they are
    differences of frame times)."""
    def key(item: tuple[int, tuple[str, SceneScore]]) -> tuple[float, float, float, int]:
        i, (_, s) = item
        median = round(s.delay_percentile(50) * 1000.0) if s.delays_s else float("inf")
        return (max(s.false_alarms_per_hour - FALSE_ALARMS_PER_HOUR, 0.0), -round(s.f1, 6), median, i)
    return min(enumerate(scores.items()), key=key)[1][0]


@dataclass
class HoldOut:
    family: str
    chosen: str
    #: The chosen candidate on the other families' tuning seeds.
    tuning: SceneScore
    #: The held-out family on its evaluation seeds: the chosen setting, and the default.
    held_out: SceneScore
    default: SceneScore


def tuning_scores(method: str, base: DetectorSettings = DEFAULT_SETTINGS, rate_hz: float = 100.0,
                  seeds: tuple[int, ...] = TUNING_SEEDS, tolerance_s: float = 0.5,
                  progress: Progress = NO_PROGRESS) -> dict[str, dict[str, SceneScore]]:
    """Every candidate on every family's tuning seeds: family -> candidate -> score."""
    if method not in CANDIDATES:
        raise KeyError(f"no candidate settings to choose among for {method!r}; methods with some: "
                       f"{', '.join(CANDIDATES)}")
    methods = {c.label: _factory(method, c, base) for c in CANDIDATES[method]}
    res = evaluate_families(methods, tuple(FAMILIES), seeds, rate_hz, base, tolerance_s, progress)
    return {fam: {label: r.score for label, r in by.items()} for fam, by in res.items()}


def hold_out(method: str, family: str, tuning: dict[str, dict[str, SceneScore]],
             base: DetectorSettings = DEFAULT_SETTINGS, rate_hz: float = 100.0,
             seeds: tuple[int, ...] = EVALUATION_SEEDS, tolerance_s: float = 0.5,
             progress: Progress = NO_PROGRESS) -> HoldOut:
    """Choose on every family but ``family`` (from ``tuning_scores``), report on it;
    ``progress`` gets a stage of its own (the chosen candidate and the default, or one
    run when they are the same)."""
    pooled: dict[str, SceneScore] = {c.label: SceneScore() for c in CANDIDATES[method]}
    for fam, by in tuning.items():
        if fam != family:
            for label, s in by.items():
                pooled[label] += s
    chosen = choose(pooled)
    wanted = {c.label: c for c in CANDIDATES[method] if c.label in (chosen, CANDIDATES[method][0].label)}
    methods = {label: _factory(method, c, base) for label, c in wanted.items()}
    progress.stage(family, len(FAMILIES[family].scenes) * len(seeds) * len(methods))
    res = evaluate_families(methods, (family,), seeds, rate_hz, base, tolerance_s, progress)[family]
    default = CANDIDATES[method][0].label
    return HoldOut(family, chosen, pooled[chosen], res[chosen].score, res[default].score)
