"""Ground truth: the label of every sample, from the scene's events.

Labels: ``no_contact``, ``stable``, ``variable_force``, ``slip``, and ``transition``
for don't-care spans (the instant of grasping or letting go, and ``settle_s`` after).
"""

from __future__ import annotations

import numpy as np

from .spec import SceneSpec

LABELS = ("no_contact", "stable", "variable_force", "slip", "transition")


def label_samples(t: np.ndarray, spec: SceneSpec) -> np.ndarray:
    labels = np.full(t.size, "no_contact", dtype=object)
    for e in spec.events:
        if e.kind == "press":
            labels[t >= e.t_s] = "stable"
        elif e.kind == "release":
            labels[t >= e.t_s] = "no_contact"
    for e in spec.events:
        span = (t >= e.t_s) & (t < e.end_s + (spec.settle_s if e.kind in ("press", "release") else spec.tail_s))
        labels[span] = {"press": "transition", "release": "transition", "slide": "slip", "rotate": "slip"}.get(e.kind, "variable_force")
    return labels
