"""The closed loop's figures from episode results: what counts as a needless squeeze
and a reaction, and how a control's results add up against the oracle's."""
from __future__ import annotations

import math

import pytest

from eskin_industrial.sim.cell.outcome import NEEDLESS_WINDOW_S, EpisodeResult, needless, reactions
from eskin_industrial.sim.cell.policy import Raise
from eskin_industrial.sim.cell.scoring import score


def test_a_raise_with_no_slide_in_the_window_before_it_is_needless_and_a_fallback_never_is():
    slides = [(2.0, 2.1), (5.0, None)]  # one that ended, one that went on to the end
    raises = [
        Raise(2.05, 3.0, "slip"),  # during the first slide
        Raise(2.1 + NEEDLESS_WINDOW_S - 0.01, 4.0, "still slipping"),  # just inside the window after it
        Raise(2.1 + NEEDLESS_WINDOW_S + 0.01, 4.0, "slip"),  # just outside: needless
        Raise(3.5, 8.0, "no verdict"),  # the fallback: not a slip alarm
        Raise(1.0, 3.0, "slip"),  # before any slide: needless
        Raise(6.0, 5.0, "slip"),  # during the slide that goes on
    ]
    assert needless(raises, slides) == 2
    got = reactions(raises, slides)
    assert got[0] == pytest.approx(0.05) and got[1] == pytest.approx(1.0)
    assert reactions([Raise(3.5, 8.0, "no verdict")], [(2.0, 2.1)]) == (None,)  # no slip raise: no reaction


def _result(seed: int, control: str, outcome: str, *, obj: str = "glass", slid: float = 0.0, holding_s: float = 3600.0,
            grip_n: float = 5.0, fixed_n: float = 10.0, raises: int = 0, needless_: int = 0,
            reaction: float | None = None) -> EpisodeResult:
    return EpisodeResult(control, obj, seed, obj == "egg", outcome, slid, int(reaction is not None), holding_s,  # type: ignore[arg-type]
                         grip_n * holding_s, fixed_n, grip_n, raises, needless_, 0,
                         () if reaction is None else (reaction,))


def test_a_controls_figures_and_how_it_compares_with_the_oracle():
    oracle = [_result(1, "oracle", "held"), _result(2, "oracle", "held", obj="egg"), _result(3, "oracle", "dropped")]
    mine = [
        _result(1, "m", "held", slid=2.0, grip_n=4.0, raises=2, needless_=1, reaction=0.05),
        _result(2, "m", "crushed", obj="egg", slid=0.0, grip_n=6.0, holding_s=1800.0, reaction=0.03),
        _result(3, "m", "held", slid=10.0, grip_n=5.0, raises=1, reaction=0.07),
    ]
    s = score("m", mine, oracle)
    assert (s.episodes, s.held, s.dropped, s.crushed, s.fragile) == (3, 2, 0, 1, 1)
    assert s.held_share == pytest.approx(2 / 3)
    assert s.holding_h == pytest.approx(2.5) and s.needless_per_hour == pytest.approx(1 / 2.5)
    # the grip integrated over the holding time, over the fixed grip's over the same time
    assert s.grip_vs_fixed == pytest.approx((4.0 * 3600 + 6.0 * 1800 + 5.0 * 3600) / (10.0 * 9000))
    assert (s.slid_p50_mm, s.reaction_p50_s) == (pytest.approx(2.0), pytest.approx(0.05))
    # against the oracle: it held seeds 1 and 2; this control held 1 of them and crushed the other
    assert (s.oracle_held, s.held_of_oracle, s.crushed_of_oracle) == (2, 1, 1) and s.of_oracle == 0.5
    assert dict((n, (e, h, d, c)) for n, e, h, d, c in s.per_object) == {"glass": (2, 2, 0, 0), "egg": (1, 0, 0, 1)}
    record = s.as_dict()
    assert record["needless_squeezes_per_hour"] == s.needless_per_hour and record["crushed"] == 1
    assert math.isnan(score("m", mine).of_oracle)  # no oracle run: no share of it
