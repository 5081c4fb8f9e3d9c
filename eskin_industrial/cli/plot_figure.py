"""The figure ``eskin-bus plot`` draws, apart from reading and detecting so that a test
can look at its parts (axes, labels, legends): lanes over one time axis, the total
force, the centre of force (where a slide shows as a drift), the deciding method's two
scores against its threshold, the detected state as coloured bands, and the truth as
bands of the same colours in a lane of its own.  Every legend sits right of its lane, clear of the data."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

#: One colour per state, the same in both lanes, from Paul Tol's colour-blind-safe
#: "bright" scheme (tell apart with each common colour-vision deficiency and in grey).
STATE_COLOURS: dict[str, str] = {
    "no_contact": "#DDDDDD",
    "transition": "#999999",  # (the truth only: the grip's ramp in or out)
    "stable": "#4477AA",
    "variable_force": "#CCBB44",
    "slip": "#EE6677",
}
#: The two scores, the force and the threshold: colours no band uses (and the centre
#: of force's x and y the same two, drawn solid and dashed).
SCORE_COLOURS = ("#228833", "#AA3377")
FORCE_COLOUR = "#000000"

#: How each state reads in a legend.
STATE_NAMES = {"no_contact": "no contact", "transition": "transition", "stable": "stable",
               "variable_force": "varying force", "slip": "slip"}


@dataclass(frozen=True)
class PlotData:
    """What the figure shows, in the package's units: seconds, newtons, millimetres."""

    #: The frames' times (s), their total force (N) and centre of force (x, y in mm;
    #: NaN without contact).
    t: np.ndarray
    total_n: np.ndarray
    centre_mm: tuple[np.ndarray, np.ndarray]
    #: The updates' times (s), states (labels, ``GraspState.label``) and two scores.
    update_t: np.ndarray
    states: np.ndarray
    scores: tuple[tuple[str, np.ndarray], tuple[str, np.ndarray]]
    threshold: float
    threshold_name: str
    title: str
    #: The ground truth, (times in s, labels), when given.
    truth: tuple[np.ndarray, np.ndarray] | None = None


def centre_of_force(forces: np.ndarray, x_mm: np.ndarray, y_mm: np.ndarray,
                    share: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """Each frame's force-weighted mean taxel position (mm); NaN where the frame's total
    is under ``share`` of the recording's largest (no contact, or too little force for
    the centre to be more than the taxels' noise)."""
    f = np.clip(np.nan_to_num(np.asarray(forces, dtype=float)), 0.0, None)
    total = f.sum(axis=1)
    off = total < share * float(total.max(initial=0.0)) if len(total) else np.zeros(0, bool)
    off |= total <= 0.0
    with np.errstate(invalid="ignore", divide="ignore"):
        cx, cy = (f @ x_mm) / total, (f @ y_mm) / total
    cx[off], cy[off] = np.nan, np.nan
    return cx, cy


def band_spans(t: np.ndarray, labels: np.ndarray) -> dict[str, list[tuple[float, float]]]:
    """Each label's runs as (start, width) in seconds; a run lasts until the next one
    starts (the last until its last time, plus one step)."""
    t = np.asarray(t, dtype=float)
    labels = np.asarray(labels).astype(str)
    if len(t) == 0:
        return {}
    step = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    ends = np.append(t[1:], t[-1] + step)
    starts = np.flatnonzero(np.concatenate(([True], labels[1:] != labels[:-1])))
    out: dict[str, list[tuple[float, float]]] = {}
    for i, a in enumerate(starts):
        b = starts[i + 1] if i + 1 < len(starts) else len(t)
        out.setdefault(str(labels[a]), []).append((float(t[a]), float(ends[b - 1] - t[a])))
    return out


def _lane(ax: Any, spans: dict[str, list[tuple[float, float]]], name: str) -> None:
    from matplotlib.patches import Patch

    for label in STATE_COLOURS:  # in a fixed order, so both legends read alike
        if label in spans:
            ax.broken_barh(spans[label], (0, 1), facecolors=STATE_COLOURS[label], linewidth=0)
    handles = [Patch(facecolor=STATE_COLOURS[s], label=STATE_NAMES[s]) for s in STATE_COLOURS if s in spans]
    ax.set_ylim(0, 1)
    ax.set_yticks([])
    ax.set_ylabel(name, rotation=0, ha="right", va="center")
    ax.legend(handles=handles, title=name, loc="center left", bbox_to_anchor=(1.01, 0.5), ncol=2, fontsize=8,
              title_fontsize=8, frameon=False, handlelength=1.2, columnspacing=1.0)


def state_figure(plt: Any, data: PlotData) -> Any:
    """The figure (matplotlib's), for ``plt`` = ``matplotlib.pyplot``."""
    lanes = 5 if data.truth is not None else 4
    ratios: Sequence[float] = [1.2, 1.0, 2.0, 0.55, 0.55][:lanes]
    fig, axes = plt.subplots(lanes, 1, figsize=(11, 7.5), sharex=True, layout="constrained",
                             gridspec_kw={"height_ratios": ratios})
    ax_f, ax_c, ax_s, ax_state = axes[0], axes[1], axes[2], axes[3]

    ax_f.plot(data.t, data.total_n, color=FORCE_COLOUR, lw=0.8)
    ax_f.set_ylabel("total force (N)")
    ax_f.grid(True, lw=0.3, alpha=0.5)

    for values, axis, style in zip(data.centre_mm, ("x", "y"), ("-", "--")):
        ax_c.plot(data.t, values, ls=style, lw=0.9, color=SCORE_COLOURS[0] if axis == "x" else SCORE_COLOURS[1],
                  label=f"{axis} of the centre")
    ax_c.set_ylabel("centre of\nforce (mm)")
    ax_c.grid(True, lw=0.3, alpha=0.5)
    ax_c.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)

    for (name, values), colour in zip(data.scores, SCORE_COLOURS):
        ax_s.plot(data.update_t, values, lw=1.0, color=colour, label=name)
    ax_s.axhline(data.threshold, color="k", ls="--", lw=0.8, label=data.threshold_name)
    ax_s.set_yscale("symlog", linthresh=1.0)
    ax_s.set_ylim(bottom=0.0)
    ax_s.set_ylabel("score (dimensionless)")
    ax_s.grid(True, lw=0.3, alpha=0.5)
    ax_s.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)

    _lane(ax_state, band_spans(data.update_t, data.states), "detected")
    if data.truth is not None:
        _lane(axes[4], band_spans(*data.truth), "truth")
    axes[-1].set_xlabel("time (s)")
    axes[-1].set_xlim(float(data.t[0]) if len(data.t) else 0.0, float(data.t[-1]) if len(data.t) else 1.0)
    fig.suptitle(data.title)
    return fig
