"""Run methods over scenes and seeds and score them: the numbers every accuracy claim
in the docs rests on.  Which scenes and seeds (tuning, held out) is ``corpus.py``.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

from ..detect.settings import DetectorSettings
from ..detect.updates import UpdateTable
from ..methods import Factory, get_method, ready_factory
from ..progress import NO_PROGRESS, Progress
from ..scenes import Rendered, SceneSpec, load_scene, render
from .corpus import (
    EVALUATION_SEEDS,
    HOLD_EVALUATION_SEEDS,
    HOLD_FRESH_SEEDS,
    HOLD_SCENES,
    HOLD_TUNING_SEEDS,
    SUITE,
    TUNING_SEEDS,
    coordinates,
)
from .metrics import SceneScore, score_scene

#: Detector settings per layout, from the shipped profiles' [detector] sections.
DEFAULT_SETTINGS = DetectorSettings()

__all__ = ["DEFAULT_SETTINGS", "EVALUATION_SEEDS", "HOLD_EVALUATION_SEEDS", "HOLD_FRESH_SEEDS", "HOLD_SCENES",
           "HOLD_TUNING_SEEDS", "SUITE", "TUNING_SEEDS", "Factory", "Result", "by_name", "coordinates", "evaluate", "run_one"]


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


def run_one(factory: Factory, settings: DetectorSettings, rendered: Rendered) -> tuple[UpdateTable, float]:
    """One detector over one rendered scene; its updates and the seconds it took.
    (A method that needs a model is handed the shipped one, trained on the tuning
    seeds by scripts/train-learned.)"""
    x, y = coordinates(rendered)
    det = ready_factory(factory)(settings, x, y, rendered.rate_hz)
    t, f = rendered.t, rendered.forces
    push = det.push
    start = time.perf_counter()
    out = []
    for i, ti in enumerate(t.tolist()):
        out.extend(push(ti, f[i]))
    return UpdateTable.from_updates(out), time.perf_counter() - start


def evaluate(methods: dict[str, Factory], scenes: tuple[str, ...] = SUITE, seeds: tuple[int, ...] = EVALUATION_SEEDS,
             rate_hz: float = 100.0, settings: DetectorSettings = DEFAULT_SETTINGS,
             spec_hook: Callable[[SceneSpec], SceneSpec] | None = None, tolerance_s: float = 0.5,
             progress: Progress = NO_PROGRESS, stream: int | None = None) -> dict[str, Result]:
    """Score every method on every scene and seed (each scene rendered once per seed);
    ``spec_hook`` changes a scene before it is rendered (the failure map's conditions);
    ``progress`` advances by one for each method on each scene and seed (scenes x seeds
    x methods in all), labelled with the method and the scene; ``stream`` gives the
    seeds other draws (``scenes.render``)."""
    results = {name: Result(name) for name in methods}
    for scene in scenes:
        spec = load_scene(scene)
        if spec_hook is not None:
            spec = spec_hook(spec)
        for seed in seeds:
            rendered = render(spec, rate_hz, seed, stream)
            for name, factory in methods.items():
                table, seconds = run_one(factory, settings, rendered)
                s = score_scene(table, rendered.t, rendered.labels, tolerance_s)
                res = results[name]
                res.score += s
                res.per_scene.setdefault(scene, SceneScore())
                res.per_scene[scene] += s
                res.frames += len(rendered.t)
                res.seconds += seconds
                progress.advance(1, f"{name}, {scene}")
    return results


def by_name(*names: str) -> dict[str, Factory]:
    return {n: get_method(n).stream for n in names}
