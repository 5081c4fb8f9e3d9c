"""A control's figures over many episodes: what a cell owner pays for.

- held: episodes that ended with the object in the fingers, whole (% of all);
- the distance slid per episode, p50 / p90 (mm);
- needless squeezes per hour of holding: raises of the force on a slip when nothing
  had slid in the half second before (``outcome.needless``);
- fragile objects crushed;
- the mean grip relative to the fixed grip: the grip force integrated over the holding
  time, over the fixed grip's force over the same time (how lightly the cell holds);
- against the oracle (the program fed the truth, through the same latencies), per
  episode: held where the oracle holds, crushed where the oracle holds.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .outcome import EpisodeResult


@dataclass(frozen=True)
class ControlScore:
    control: str
    episodes: int
    held: int
    dropped: int
    crushed: int
    fragile: int  #: fragile objects among the episodes
    slid_p50_mm: float
    slid_p90_mm: float
    holding_h: float
    raises: int
    needless: int
    fallbacks: int
    grip_vs_fixed: float
    #: per object: (episodes, held, dropped, crushed)
    per_object: tuple[tuple[str, int, int, int, int], ...] = ()
    #: against the oracle, when it ran on the same episodes
    oracle_held: int | None = None  #: episodes the oracle held
    held_of_oracle: int | None = None  #: of those, held here too
    crushed_of_oracle: int | None = None  #: of those, crushed here
    #: slide onset -> first raise, p50 / p90 (s), over the slides that got one
    reaction_p50_s: float = float("nan")
    reaction_p90_s: float = float("nan")

    @property
    def held_share(self) -> float:
        return self.held / self.episodes if self.episodes else float("nan")

    @property
    def needless_per_hour(self) -> float:
        return self.needless / self.holding_h if self.holding_h > 0 else float("nan")

    @property
    def of_oracle(self) -> float:
        """Held, as a share of what the oracle held (same episodes)."""
        if not self.oracle_held:
            return float("nan")
        return (self.held_of_oracle or 0) / self.oracle_held

    def as_dict(self) -> dict[str, object]:
        return {
            "control": self.control, "episodes": self.episodes, "held": self.held, "held_share": self.held_share,
            "dropped": self.dropped, "crushed": self.crushed, "fragile": self.fragile,
            "slid_p50_mm": self.slid_p50_mm, "slid_p90_mm": self.slid_p90_mm, "holding_h": self.holding_h,
            "raises": self.raises, "needless_squeezes": self.needless,
            "needless_squeezes_per_hour": self.needless_per_hour, "fallback_raises": self.fallbacks,
            "grip_vs_fixed": self.grip_vs_fixed, "oracle_held": self.oracle_held,
            "held_of_oracle": self.held_of_oracle, "held_of_oracle_share": self.of_oracle,
            "crushed_of_oracle": self.crushed_of_oracle,
            "reaction_p50_ms": self.reaction_p50_s * 1000, "reaction_p90_ms": self.reaction_p90_s * 1000,
            "per_object": {name: {"episodes": n, "held": h, "dropped": d, "crushed": c}
                           for name, n, h, d, c in self.per_object},
        }


def score(control: str, results: Sequence[EpisodeResult], oracle: Sequence[EpisodeResult] | None = None) -> ControlScore:
    """The figures of ``results``; with ``oracle`` (the same seeds), how they compare."""
    slid = np.array([r.slid_mm for r in results]) if results else np.array([np.nan])
    holding_s = sum(r.holding_s for r in results)
    fixed_ns = sum(r.fixed_n * r.holding_s for r in results)
    names = sorted({r.object for r in results}, key=lambda n: min(r.seed for r in results if r.object == n))
    per_object = tuple((n, sum(1 for r in results if r.object == n),
                        sum(1 for r in results if r.object == n and r.outcome == "held"),
                        sum(1 for r in results if r.object == n and r.outcome == "dropped"),
                        sum(1 for r in results if r.object == n and r.outcome == "crushed")) for n in names)
    reactions = [x for r in results for x in r.reactions_s if x is not None]
    out = ControlScore(
        control, len(results), sum(r.held for r in results), sum(r.outcome == "dropped" for r in results),
        sum(r.outcome == "crushed" for r in results), sum(r.fragile for r in results),
        float(np.percentile(slid, 50)), float(np.percentile(slid, 90)), holding_s / 3600.0,
        sum(r.raises for r in results), sum(r.needless for r in results), sum(r.fallbacks for r in results),
        sum(r.grip_ns for r in results) / fixed_ns if fixed_ns > 0 else float("nan"), per_object,
        reaction_p50_s=float(np.percentile(reactions, 50)) if reactions else float("nan"),
        reaction_p90_s=float(np.percentile(reactions, 90)) if reactions else float("nan"))
    if oracle is None:
        return out
    by_seed = {r.seed: r for r in oracle}
    mine = {r.seed: r for r in results}
    held_by_oracle = [s for s in mine if s in by_seed and by_seed[s].held]
    from dataclasses import replace

    return replace(out, oracle_held=len(held_by_oracle), held_of_oracle=sum(mine[s].held for s in held_by_oracle),
                   crushed_of_oracle=sum(mine[s].outcome == "crushed" for s in held_by_oracle))
