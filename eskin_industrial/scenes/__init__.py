"""Scenes with ground truth: seeded, at any sample rate, from data files.

    >>> rec = render("case2", rate_hz=100.0, seed=1)
    >>> rec.forces.shape[1], rec.profile_name
    (25, 'paper-5x5')
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources
from importlib.resources.abc import Traversable
from pathlib import Path

import numpy as np

from ..errors import ProfileError
from . import physics, sensor
from .labels import LABELS, label_samples
from .spec import SceneSpec, load_scene_file, parse_scene

__all__ = ["LABELS", "Rendered", "SceneSpec", "list_scenes", "load_scene", "render"]


@dataclass(frozen=True)
class Rendered:
    name: str
    profile_name: str
    rate_hz: float
    seed: int
    t: np.ndarray  #: (K,) seconds (frames lost by ``drop_rate`` are absent)
    forces: np.ndarray  #: (K, n) newtons, row-major
    labels: np.ndarray  #: (K,) label per frame
    spec: SceneSpec


def _builtin_dir() -> Traversable:
    return resources.files(__package__) / "builtin"


def list_scenes() -> dict[str, str]:
    """Built-in scene names and descriptions."""
    out = {}
    for entry in sorted(_builtin_dir().iterdir(), key=lambda p: p.name):
        if entry.name.endswith(".toml"):
            spec = parse_scene(entry.read_text(encoding="utf-8"), entry.name)
            out[spec.scene.name] = spec.scene.description
    return out


def load_scene(name_or_path: str) -> SceneSpec:
    """A built-in scene by name, or a scene file by path."""
    path = Path(name_or_path)
    if path.suffix == ".toml" or path.exists():
        return load_scene_file(path)
    entry = _builtin_dir() / f"{name_or_path}.toml"
    if not entry.is_file():
        known = ", ".join(list_scenes())
        raise ProfileError(f"unknown scene {name_or_path!r}; built-in scenes: {known} (or give a .toml file)")
    return parse_scene(entry.read_text(encoding="utf-8"), f"{name_or_path}.toml")


def render(name_or_path: str | SceneSpec, rate_hz: float, seed: int, stream: int | None = None) -> Rendered:
    """The scene at this rate, its random draws from ``seed`` (and, if given, ``stream``:
    another set of draws for the same seed, so that variants of one scene do not share
    their noise)."""
    spec = name_or_path if isinstance(name_or_path, SceneSpec) else load_scene(name_or_path)
    if not rate_hz > 0:
        raise ValueError(f"rate_hz: expected a positive rate, got {rate_hz}")
    rng = np.random.default_rng(seed if stream is None else (seed, stream))
    t = np.arange(int(round(spec.scene.duration_s * rate_hz))) / rate_hz
    events = spec.events
    force = physics.force_profile(t, events) * physics.oscillation_factor(t, events)
    if any(e.kind == "slide" and e.force_drop for e in events):
        force = force * physics.force_drop_factor(t, events, rng)
    jitter, ripple = physics.stick_slip(t, events, rng)
    centre = np.asarray(spec.footprint.centre_mm)[None, :] + physics.slide_offset(t, events) + jitter
    if spec.sensor.cof_jitter_mm:  # (drawn only when asked for: the other scenes' draws stay as they were)
        centre = centre + physics.cof_jitter(t, spec.sensor.cof_jitter_mm, spec.sensor.cof_jitter_hz, rng)
    if physics.needs_sampling(spec.footprint, events):
        angle = physics.rotation_deg(t, events, spec.footprint.angle_deg)
        gradient = np.asarray(spec.footprint.gradient_per_mm)[None, :] + physics.lift_off_gradient(t, events)
        true = physics.sampled_forces(spec.array, spec.footprint, centre, angle, gradient, force * ripple)
    else:
        true = physics.footprint_forces(spec.array, spec.footprint, centre, force * ripple)
    keep, measured = sensor.apply(true, t, spec.sensor, rng, (spec.array.rows, spec.array.cols))
    return Rendered(spec.scene.name, spec.scene.profile, rate_hz, seed, t[keep], measured,
                    label_samples(t, spec)[keep], spec)
