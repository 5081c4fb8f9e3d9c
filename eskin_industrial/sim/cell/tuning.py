"""How the recipes' choices were made, on the closed loop's tuning seeds only
(``eskin-bus evaluate --closed-loop --tune``):

- the fixed grip's safety factor: the smallest of the gripper makers' range 1.5-2.5
  with which the fixed grip drops nothing;
- the grip policy's factors: of a small grid, with the default method deciding, the
  one that holds the most objects, then with the fewest needless squeezes, then with
  the lightest mean grip, among those that grip at most 60 % of the fixed grip.
  The recipes' default departs from it once, by a point of grip: the relax spread over
  a second (``relax_s``), for the needless squeezes at 1 kHz it takes away, which this
  rule, run at 100 Hz, does not see (docs/evaluation.md, *The policy chosen again on
  this cell*).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

from ...progress import NO_PROGRESS, Progress
from .episodes import TUNING_SEEDS
from .recipes import POLICY, PolicyFactors
from .runner import Setup, run_controls
from .scoring import ControlScore, score

#: The gripper makers' safety factors, smallest first.
SAFETY_CANDIDATES: tuple[float, ...] = (1.5, 1.75, 2.0, 2.25, 2.5)


def _grid() -> tuple[PolicyFactors, ...]:
    # the former grid: step mode (the choice made on the cell with c_v = 4 s/m), and max mode
    step = replace(POLICY, mode="step", escalate_mm=0.0, light=1.3, step=0.5, relax_floor=1.5, relax_s=0.0)
    out = [replace(step, light=light, step=size, relax_floor=floor)
           for light in (1.3, 1.6) for size in (0.5, 1.0) for floor in (1.25, 1.5)]
    out.append(replace(step, mode="max"))
    out.append(replace(step, relax_floor=100.0))  # never relaxes below the last raise
    # hybrid: a step, then the maximum if the slide runs on past it (policy.py), for the
    # cell whose slides accelerate (c_v = 1 s/m and below)
    hybrid = replace(POLICY, mode="hybrid", light=1.3, relax_floor=1.5, relax_s=0.0)
    out += [replace(hybrid, step=size, escalate_mm=mm) for size in (0.5, 1.0) for mm in (2.0, 3.0, 5.0)]
    out += [replace(hybrid, step=1.0, light=1.6), replace(hybrid, step=1.0, relax_floor=1.25),
            replace(hybrid, step=0.5, repeat_s=0.1)]
    # a relax spread over a second: the soft pad's centre of force moves slowly as it shrinks
    out.append(replace(hybrid, step=1.0, light=1.6, relax_s=1.0))
    return tuple(out)


POLICY_CANDIDATES: tuple[PolicyFactors, ...] = _grid()
#: The most a candidate may grip, as a share of the fixed grip (the issue's target).
GRIP_LIMIT = 0.60


@dataclass(frozen=True)
class Candidate:
    factors: PolicyFactors
    method: ControlScore
    oracle: ControlScore


def fixed_safety(seeds: Sequence[int] = TUNING_SEEDS, jobs: int = 1,
                 progress: Progress = NO_PROGRESS) -> list[tuple[float, ControlScore]]:
    out = []
    for safety in SAFETY_CANDIDATES:
        res = run_controls(["fixed"], seeds, Setup(fixed_safety=safety), jobs, progress)
        out.append((safety, score("fixed", res["fixed"])))
    return out


def chosen_safety(rows: list[tuple[float, ControlScore]]) -> float | None:
    return next((s for s, sc in rows if sc.dropped == 0), None)


def policy_candidates(method: str, seeds: Sequence[int] = TUNING_SEEDS, jobs: int = 1,
                      progress: Progress = NO_PROGRESS) -> list[Candidate]:
    out = []
    for factors in POLICY_CANDIDATES:
        res = run_controls([method, "oracle"], seeds, Setup(factors=factors), jobs, progress)
        out.append(Candidate(factors, score(method, res[method], res["oracle"]), score("oracle", res["oracle"])))
    return out


def chosen(candidates: list[Candidate]) -> Candidate | None:
    light = [c for c in candidates if c.method.grip_vs_fixed <= GRIP_LIMIT]
    if not light:
        return None
    return min(light, key=lambda c: (-c.method.held, c.method.needless_per_hour, c.method.grip_vs_fixed))
