"""Run methods over scenes and seeds and score them: the numbers every accuracy claim
in the docs rests on.

Seeds: ``TUNING_SEEDS`` are the only ones any threshold or default was chosen on;
``EVALUATION_SEEDS`` are held out and are what the docs report.  False alarms per
hour need hours of holding, more than the suite holds (0.7 h): the still holds alone
are scored over many more seeds, ``HOLD_TUNING_SEEDS`` (11.3 h) to choose, and
``HOLD_EVALUATION_SEEDS`` (3.8 h) held out to report.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from ..detect.methods import get_method
from ..detect.settings import DetectorSettings
from ..detect.updates import UpdateTable
from ..profile import LayoutSection
from ..scenes import Rendered, SceneSpec, load_scene, render
from .metrics import SceneScore, score_scene

TUNING_SEEDS: tuple[int, ...] = (0, 1, 2, 3, 4, 7)  # 7: the demo's seed, where a false alarm was found
EVALUATION_SEEDS: tuple[int, ...] = tuple(range(1000, 1010))

#: The long-hold check: the still holds only, over many seeds.
HOLD_SCENES: tuple[str, ...] = ("hold", "hand-hold")
#: (100-159 at first; 160-399 added when a false alarm every hour and a half on the
#: light hand grip hid in the 2.3 h of the first sixty: docs/evaluation.md)
HOLD_TUNING_SEEDS: tuple[int, ...] = tuple(range(100, 400))
HOLD_EVALUATION_SEEDS: tuple[int, ...] = tuple(range(2000, 2100))

#: The built-in suite: the paper's cases, the hand, and the scenes made to break methods.
SUITE: tuple[str, ...] = ("case1", "case2", "case3", "case4", "case5", "case6", "hand",
                          "hold", "hand-hold", "creep", "partial", "vibration")

#: Detector settings per layout, from the shipped profiles' [detector] sections.
DEFAULT_SETTINGS = DetectorSettings()


def coordinates(rendered: Rendered) -> tuple[np.ndarray, np.ndarray]:
    """Taxel coordinates of the scene's array, as a profile's layout computes them."""
    a = rendered.spec.array
    return LayoutSection(a.rows, a.cols, a.pitch_mm, a.row_pitch_mm).coordinates_mm()


@dataclass
class Result:
    method: str
    score: SceneScore = field(default_factory=SceneScore)
    frames: int = 0
    seconds: float = 0.0
    per_scene: dict[str, SceneScore] = field(default_factory=dict)

    @property
    def us_per_frame(self) -> float:
        return self.seconds / self.frames * 1e6 if self.frames else float("nan")


Factory = Callable[[DetectorSettings, np.ndarray, np.ndarray, float], Any]


def run_one(factory: Factory, settings: DetectorSettings, rendered: Rendered) -> tuple[UpdateTable, float]:
    x, y = coordinates(rendered)
    det = factory(settings, x, y, rendered.rate_hz)
    t, f = rendered.t, rendered.forces
    push = det.push
    start = time.perf_counter()
    out = []
    for i, ti in enumerate(t.tolist()):
        out.extend(push(ti, f[i]))
    return UpdateTable.from_updates(out), time.perf_counter() - start


def evaluate(methods: dict[str, Factory], scenes: tuple[str, ...] = SUITE, seeds: tuple[int, ...] = EVALUATION_SEEDS,
             rate_hz: float = 100.0, settings: DetectorSettings = DEFAULT_SETTINGS,
             spec_hook: Callable[[SceneSpec], SceneSpec] | None = None, tolerance_s: float = 0.5) -> dict[str, Result]:
    """Score every method on every scene and seed (each scene rendered once per seed);
    ``spec_hook`` changes a scene before it is rendered (the failure map's conditions)."""
    results = {name: Result(name) for name in methods}
    for scene in scenes:
        spec = load_scene(scene)
        if spec_hook is not None:
            spec = spec_hook(spec)
        for seed in seeds:
            rendered = render(spec, rate_hz, seed)
            for name, factory in methods.items():
                table, seconds = run_one(factory, settings, rendered)
                s = score_scene(table, rendered.t, rendered.labels, tolerance_s)
                res = results[name]
                res.score += s
                res.per_scene.setdefault(scene, SceneScore())
                res.per_scene[scene] += s
                res.frames += len(rendered.t)
                res.seconds += seconds
    return results


def by_name(*names: str) -> dict[str, Factory]:
    return {n: get_method(n).stream for n in names}
