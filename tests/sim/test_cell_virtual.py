"""The cell in virtual time on one tuning episode (a glass filled while held on the
hand): the three baselines behave as their definitions say, a run is a function of
its seed, and latency added to the chain delays the reaction by as much."""
from __future__ import annotations

from dataclasses import replace

import pytest

from eskin_industrial.sim.cell.episodes import TUNING_SEEDS
from eskin_industrial.sim.cell.physics import DROP_MM
from eskin_industrial.sim.cell.runner import Setup, run_seed
from eskin_industrial.sim.cell.virtual import ChainSpec

GLASS = TUNING_SEEDS[0]  # seed mod 5 == 0: the glass


def test_the_fixed_grip_holds_the_light_grip_alone_drops_and_the_oracle_holds_lightly():
    fixed, none, oracle = (run_seed(GLASS, c, Setup()) for c in ("fixed", "none", "oracle"))
    assert (fixed.object, fixed.outcome, fixed.slid_mm, fixed.raises) == ("glass", "held", 0.0, 0)
    assert fixed.mean_grip_n == pytest.approx(fixed.fixed_n, rel=0.01)  # it is the reference
    # no slip sensing: the light grip set for the empty glass, and the pour slides it out
    assert none.outcome == "dropped" and none.slid_mm >= DROP_MM and none.raises == 0
    assert none.mean_grip_n < 0.5 * fixed.fixed_n
    # the truth the tick a slide starts, through the chain's latencies: held, each slide
    # answered within the transport, a PLC cycle and a margin, and lighter than fixed
    assert oracle.outcome == "held" and 0 < oracle.slid_mm < DROP_MM and oracle.needless == 0
    assert oracle.reactions_s and all(r is not None and r < 0.03 for r in oracle.reactions_s)
    assert none.mean_grip_n < oracle.mean_grip_n < fixed.mean_grip_n
    assert run_seed(GLASS, "none", Setup()) == none  # a run is a function of its seed


@pytest.mark.slow
def test_latency_added_to_the_chain_delays_each_reaction_by_as_much_and_the_glass_slides_farther():
    base = run_seed(GLASS, "oracle", Setup())
    later = run_seed(GLASS, "oracle", replace(Setup(), chain=replace(ChainSpec(), extra_latency_s=0.05)))
    assert len(later.reactions_s) >= 1
    first, first_later = base.reactions_s[0], later.reactions_s[0]
    assert first is not None and first_later is not None
    # 50 ms added, the PLC's 10 ms cycle either way (its edges included, to the float's rounding)
    assert 0.04 - 1e-9 <= first_later - first <= 0.06 + 1e-9
    assert later.slid_mm > base.slid_mm
