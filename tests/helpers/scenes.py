"""Synthetic inputs: a still grasp as newtons, a short pressing scene as TOML."""

from __future__ import annotations

import numpy as np


def grasp(k: int, n: int = 25, force: float = 6.0, seed: int = 0, noise: float = 0.01) -> np.ndarray:
    """A still grasp: a fixed Gaussian footprint plus sensor noise, (k, n) newtons."""
    rng = np.random.default_rng(seed)
    side = int(round(np.sqrt(n))) if n == 25 else 5
    rows = n // side
    r, c = np.divmod(np.arange(n), side)
    shape = np.exp(-((r - rows / 2 + 0.3) ** 2 + (c - 2.1) ** 2) / 3.0)
    base = force * shape / shape.sum()
    return np.abs(base + rng.normal(0.0, noise, (k, n)))


def press_scene(name: str, duration_s: float, press_t: float, press_s: float, force_n: float,
                slide_t: float | None = None) -> str:
    """A short paper-5x5 scene as TOML for the end-to-end tests: a 20 mm contact pressed
    at ``press_t``, and, if ``slide_t`` is given, a 6 mm slide at 10 mm/s from then."""
    text = (f'[scene]\nname = "{name}"\nprofile = "paper-5x5"\nduration_s = {duration_s}\n\n'
            '[footprint]\nsize_mm = [20.0, 20.0]\ncentre_mm = [10.0, 10.0]\n\n'
            f'[[events]]\nkind = "press"\nt_s = {press_t}\nduration_s = {press_s}\nforce_n = {force_n}\n')
    if slide_t is not None:
        text += f'\n[[events]]\nkind = "slide"\nt_s = {slide_t}\ndistance_mm = [6.0, 0.0]\nspeed_mm_s = 10.0\n'
    return text
