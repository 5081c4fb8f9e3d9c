"""The recipes' choice is one the tuning can make again: the default factors are a
candidate of its grid, and the rule picks the most held, then the fewest needless
squeezes, then the lightest grip, of those within the grip limit."""
from __future__ import annotations

from dataclasses import replace

from eskin_industrial.sim.cell.recipes import POLICY
from eskin_industrial.sim.cell.scoring import ControlScore
from eskin_industrial.sim.cell.tuning import GRIP_LIMIT, POLICY_CANDIDATES, Candidate, chosen


def _score(held: int, needless: int, grip: float) -> ControlScore:
    return ControlScore("m", 200, held, 200 - held, 0, 40, 0.0, 0.0, 0.5, 0, needless, 0, grip)


def test_the_default_factors_are_a_candidate_of_the_grid_and_the_grid_has_each_mode():
    assert POLICY in POLICY_CANDIDATES
    assert len(set(POLICY_CANDIDATES)) == len(POLICY_CANDIDATES)  # no candidate twice
    assert {f.mode for f in POLICY_CANDIDATES} == {"step", "max", "hybrid"}


def test_the_choice_holds_the_most_within_the_grip_limit_then_squeezes_least_then_grips_lightest():
    a, b, c, d = (replace(POLICY, step=s) for s in (0.25, 0.5, 0.75, 2.0))
    oracle = _score(200, 0, 0.5)
    cands = [Candidate(a, _score(190, 0, 0.45), oracle), Candidate(b, _score(197, 1, 0.50), oracle),
             Candidate(c, _score(197, 0, 0.55), oracle), Candidate(d, _score(200, 0, GRIP_LIMIT + 0.01), oracle)]
    best = chosen(cands)
    assert best is not None and best.factors == c  # d holds more but grips past the limit
    assert chosen([cands[3]]) is None
