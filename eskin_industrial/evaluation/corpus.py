"""What the evaluation renders: the built-in suite's scenes, which seeds are for
tuning and which are held out, and the taxel coordinates of a rendered scene.

Seeds: ``TUNING_SEEDS`` are the only ones any threshold or default was chosen on (and
the only ones the learned model is trained on); ``EVALUATION_SEEDS`` are held out and
are what the docs report.  False alarms per hour need hours of holding, more than the
suite holds (0.7 h): the still holds alone are scored over many more seeds,
``HOLD_TUNING_SEEDS`` (11.3 h) to choose, and ``HOLD_EVALUATION_SEEDS`` (3.8 h) held
out to report (``HOLD_FRESH_SEEDS``, 3.8 h more, held out once).
"""

from __future__ import annotations

import numpy as np

from ..profile import LayoutSection
from ..scenes import Rendered

TUNING_SEEDS: tuple[int, ...] = (0, 1, 2, 3, 4, 7)  # 7: the demo's seed, where a false alarm was found
EVALUATION_SEEDS: tuple[int, ...] = tuple(range(1000, 1010))

#: The long-hold check: the still holds only, over many seeds.
HOLD_SCENES: tuple[str, ...] = ("hold", "hand-hold")
#: (100-159 at first; 160-399 added when a false alarm every hour and a half on the
#: light hand grip hid in the 2.3 h of the first sixty: docs/evaluation.md)
HOLD_TUNING_SEEDS: tuple[int, ...] = tuple(range(100, 400))
HOLD_EVALUATION_SEEDS: tuple[int, ...] = tuple(range(2000, 2100))
#: A second held-out set of still holds (3.8 h), opened once: for the ramp channel tested
#: once a hop at any rate, whose cause was found on the first (docs/evaluation.md).
HOLD_FRESH_SEEDS: tuple[int, ...] = tuple(range(2100, 2200))

#: The built-in suite: the paper's cases, the hand, and the scenes made to break methods.
SUITE: tuple[str, ...] = ("case1", "case2", "case3", "case4", "case5", "case6", "hand",
                          "hold", "hand-hold", "creep", "partial", "vibration")


def coordinates(rendered: Rendered) -> tuple[np.ndarray, np.ndarray]:
    """Taxel coordinates of the scene's array, as a profile's layout computes them."""
    a = rendered.spec.array
    return LayoutSection(a.rows, a.cols, a.pitch_mm, a.row_pitch_mm).coordinates_mm()
