"""The closed loop's charts (docs/evaluation.md, *The closed loop*): objects held
against needless squeezes, the Pareto front marked; and objects held against the
end-to-end latency, where the physics stops forgiving."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

from ...evaluation.charts import pareto
from ...evaluation.plotting import pyplot
from .scoring import ControlScore

BASELINES = ("fixed", "none", "oracle")


def held_vs_squeezes(scores: Sequence[ControlScore], path: Path, title: str) -> None:
    """Each control a point: held (%) against needless squeezes per hour of holding;
    the controls no other beats on both are joined (the Pareto front)."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7.5, 4.8))
    # a log-like axis that keeps zero: squeezes per hour span 0 to hundreds
    xs = [s.needless_per_hour for s in scores]
    ys = [100 * s.held_share for s in scores]
    front = sorted(pareto(list(zip(xs, ys))), key=lambda i: xs[i])
    for i, s in enumerate(scores):
        marker = "s" if s.control in BASELINES else "o"
        colour = "tab:red" if i in front else "tab:gray"
        ax.plot(xs[i], ys[i], marker, color=colour, ms=7)
    # controls that land on one spot (the oracle and the cof methods, two of the paper's)
    # share one label, a line each, or their names are printed over each other
    for group in _near(xs, ys):
        text = "\n".join(f"{scores[i].control} ({100 * scores[i].grip_vs_fixed:.0f} %)" for i in group)
        ax.annotate(text, (xs[group[0]], ys[group[0]]), textcoords="offset points", xytext=(8, 0), fontsize=8,
                    va="center")
    ax.plot([xs[i] for i in front], [ys[i] for i in front], "-", color="tab:red", lw=1.0, label="Pareto front")
    ax.set_xscale("symlog", linthresh=1.0)
    ax.set_xlabel("needless squeezes per hour of holding (symlog)")
    ax.set_ylabel("objects held (%)")
    ax.set_title(title + "\n(in brackets: mean grip, % of the fixed grip)", fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="center right", fontsize=8)  # the corners hold points
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _near(xs: Sequence[float], ys: Sequence[float], dx: float = 0.3, dy: float = 1.5) -> list[list[int]]:
    """The points in groups closer than ``dx`` on the symlog axis (in decades, zero
    and one a decade apart) and ``dy`` percentage points, highest first in each."""
    def at(x: float) -> float:
        return math.log10(x) + 1.0 if x >= 1.0 else x  # symlog with linthresh 1, roughly

    groups: list[list[int]] = []
    for i in sorted(range(len(xs)), key=lambda i: -ys[i]):
        for g in groups:
            if abs(at(xs[g[0]]) - at(xs[i])) < dx and abs(ys[g[0]] - ys[i]) < dy:
                g.append(i)
                break
        else:
            groups.append([i])
    return groups


def held_vs_latency(points: dict[str, list[tuple[float, float]]], path: Path, title: str,
                    floors: dict[str, float] | None = None) -> None:
    """``points``: per control, (end-to-end latency in ms, held %) as latency is added;
    ``floors``: controls that do not react (fixed, none), drawn as levels."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7.5, 4.5))
    colours = {"oracle": "k"}
    for control, pts in points.items():
        pts = sorted(pts)
        ax.plot([p[0] for p in pts], [p[1] for p in pts], "o-", color=colours.get(control, "tab:red"),
                label=f"{control}" + (" (the physical limit)" if control == "oracle" else ""))
    for control, level in (floors or {}).items():
        ax.axhline(level, ls="--", lw=1.0, color="tab:blue" if control == "fixed" else "tab:gray",
                   label=f"{control}: {level:.1f} %")
    ax.set_xlabel("end-to-end latency: slide onset -> the grip starts to rise, median (ms)")
    ax.set_ylabel("objects held (%)")
    ax.set_title(title, fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="lower left", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
