"""Ground truth drawn under a chart: each label's spans shaded in its colour."""

from __future__ import annotations

from typing import Any

import numpy as np

from .metrics import spans

LABEL_COLOURS = {"slip": "tab:red", "variable_force": "tab:orange", "transition": "0.85", "stable": "white",
                 "no_contact": "white"}


def shade_labels(ax: Any, t: np.ndarray, labels: np.ndarray) -> None:
    for label, colour in LABEL_COLOURS.items():
        if colour == "white":
            continue
        for a, b in spans(labels == label):
            ax.axvspan(t[a], t[b - 1], color=colour, alpha=0.3, lw=0)
