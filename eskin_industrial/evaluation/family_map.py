"""The failure map's second chart: where each effect family defeats a target, and
what the product does there (``eskin-bus evaluate --charts DIR --only families``).

Left: the default method's slip delay per family (median and 90th percentile)
against the targets, the families that miss them in red, each row with its event F1
and the most slip episodes one slide took (1: a late slip, but one slip).  Right: a
turn about the normal against the contact's size, found, missed but flagged
TURN_UNSEEN (the defined degraded behaviour), or missed unflagged (none may be).
Scored on held-out seeds; nothing was tuned on them.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..progress import NO_PROGRESS, Prefixed, Progress
from .conditions import contact_size
from .families import FAMILIES, evaluate_families
from .plotting import pyplot
from .suite import evaluate
from .sweeps import defaults

#: The slip delay targets (issue: grasp states), in seconds.
TARGET_P50_S, TARGET_P90_S = 0.040, 0.100
#: Contact sizes (mm, a square) the turn is tried on: the failure map's and those
#: around the torsion channel's footprint limit.
TURN_SIZES_MM: tuple[float, ...] = (5.0, 8.0, 10.0, 12.0, 13.0, 14.0, 16.0, 20.0)


def family_map(out: Path, seeds: tuple[int, ...], log: Any, progress: Progress = NO_PROGRESS,
               method: str = "cof-track") -> dict[str, Any]:
    """Draw ``families.png`` into ``out``; return what it shows."""
    factory = {method: defaults()[method]}
    progress.stage("families", sum(len(f.scenes) for f in FAMILIES.values()) * len(seeds)
                   + len(TURN_SIZES_MM) * len(seeds))
    res = evaluate_families(factory, tuple(FAMILIES), seeds, progress=Prefixed(progress, "families: "))
    rows: list[dict[str, Any]] = []
    for fam, by in res.items():
        s = by[method].score
        if not s.events:
            continue
        p50, p90 = s.delay_percentile(50), s.delay_percentile(90)
        rows.append({"family": fam, "events": s.events, "found": s.found, "f1": s.f1, "p50": p50, "p90": p90,
                     "episodes": max(s.slip_episodes) if s.slip_episodes else 0,
                     "misses": not (p50 <= TARGET_P50_S and p90 <= TARGET_P90_S)})
        log(f"  {fam:18s} F1 {s.f1:.3f}  delay {p50 * 1000:.0f} / {p90 * 1000:.0f} ms  "
            f"slip episodes per slide at most {rows[-1]['episodes']}")
    turns: list[dict[str, Any]] = []
    for size in TURN_SIZES_MM:
        s = evaluate(factory, scenes=("twist",), seeds=seeds, spec_hook=contact_size(size),
                     progress=Prefixed(progress, f"turn on {size:g} mm: "))[method].score
        turns.append({"size_mm": size, "events": s.events, "found": s.found, "unseen": s.missed_unseen,
                      "unflagged": s.events - s.found - s.missed_unseen})
        log(f"  turn on {size:g} mm: found {s.found} of {s.events}, missed and flagged {s.missed_unseen}")
    plt = pyplot()
    fig, (left, right) = plt.subplots(1, 2, figsize=(13, 6.5), gridspec_kw={"width_ratios": [1.6, 1.0]})
    ys = range(len(rows))
    for y, r in zip(ys, rows):
        colour = "tab:red" if r["misses"] else "tab:green"
        left.plot([r["p50"] * 1000, r["p90"] * 1000], [y, y], "-", color=colour, lw=2)
        left.plot(r["p50"] * 1000, y, "o", color=colour)
        left.plot(r["p90"] * 1000, y, "|", color=colour, ms=12, mew=2)
        left.annotate(f"F1 {r['f1']:.3f}, <= {r['episodes']} slip per slide", (r["p90"] * 1000, y),
                      xytext=(6, -3), textcoords="offset points", fontsize=8)
    left.axvline(TARGET_P50_S * 1000, color="k", ls="--", lw=0.8)
    left.axvline(TARGET_P90_S * 1000, color="k", ls=":", lw=0.8)
    left.set_yticks(list(ys), [r["family"] for r in rows])
    for tick, r in zip(left.get_yticklabels(), rows):
        tick.set_color("tab:red" if r["misses"] else "k")
    left.invert_yaxis()
    left.set_xlim(0, max(r["p90"] for r in rows) * 1000 * 1.9)
    left.set_xlabel("slip delay (ms): median (dot) to p90 (bar); targets 40 (dashed) and 100 ms (dotted)")
    left.set_title(f"{method} per effect family: red misses a delay target")
    left.grid(alpha=0.3, axis="x")
    sizes = [t["size_mm"] for t in turns]
    found = [t["found"] for t in turns]
    unseen = [t["unseen"] for t in turns]
    plain = [t["unflagged"] for t in turns]
    x = range(len(sizes))
    right.bar(x, found, color="tab:green", label="found (slip)")
    right.bar(x, unseen, bottom=found, color="tab:orange", label="missed, flagged TURN_UNSEEN (held stable)")
    right.bar(x, plain, bottom=[a + b for a, b in zip(found, unseen)], color="tab:red", label="missed, unflagged")
    right.set_xticks(list(x), [f"{v:g}" for v in sizes])
    right.set_xlabel("contact size (mm square)")
    right.set_ylabel("turns (the twist scene)")
    right.set_title("a turn about the normal against the contact's size")
    right.yaxis.get_major_locator().set_params(integer=True)
    right.set_ylim(0, max(t["events"] for t in turns) * 1.45)
    right.legend(fontsize=8, loc="upper left")
    fig.suptitle(f"Where the effect families defeat the targets, and what {method} does there "
                 f"(held-out seeds {seeds[0]}..{seeds[-1]}, 100 Hz)")
    fig.tight_layout()
    fig.savefig(out / "families.png", dpi=100)
    plt.close(fig)
    return {"families": rows, "turns": turns}
