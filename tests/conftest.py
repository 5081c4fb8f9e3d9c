from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from eskin_industrial import load_profile

ROOT = Path(__file__).resolve().parent.parent
PROFILES = ROOT / "profiles"


@pytest.fixture(scope="session")
def paper_profile():
    return load_profile(PROFILES / "paper-5x5.toml")


@pytest.fixture(scope="session")
def hand_profile():
    return load_profile(PROFILES / "hand-4x5.toml")


def grasp(k: int, n: int = 25, force: float = 6.0, seed: int = 0, noise: float = 0.01) -> np.ndarray:
    """A still grasp: a fixed Gaussian footprint plus sensor noise, (k, n) newtons."""
    rng = np.random.default_rng(seed)
    side = int(round(np.sqrt(n))) if n == 25 else 5
    rows = n // side
    r, c = np.divmod(np.arange(n), side)
    shape = np.exp(-((r - rows / 2 + 0.3) ** 2 + (c - 2.1) ** 2) / 3.0)
    base = force * shape / shape.sum()
    return np.abs(base + rng.normal(0.0, noise, (k, n)))
