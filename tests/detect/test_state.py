from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from eskin_industrial.detect import GraspState, StateMachine, get_method
from eskin_industrial.detect.state import ContactRule, Decision, VaryingLatch

S = GraspState


def steps(machine, seq):
    return [S(machine.step(t, rc, rd, contact, valid)) for t, (rc, rd, contact, valid) in enumerate(seq)]


def paper_reading(cfg, **latch):
    """The paper's own varying-force evidence (R over ``variable_r_*``), latch settings given."""
    return replace(cfg, varying_force=replace(cfg.varying_force, evidence="method", **latch))


def test_paper_rule_needs_both_indicators(paper_profile):
    m = StateMachine(paper_reading(replace(paper_profile.detector, hold_s=0.0), exit_s=0.0, min_dwell_s=0.0))
    got = steps(m, [(0, 0, True, True), (3, 1, True, True), (1, 3, True, True), (3, 3, True, True), (0, 0, True, True)])
    assert got == [S.STABLE, S.VARIABLE_FORCE, S.VARIABLE_FORCE, S.SLIP, S.STABLE]


def test_hysteresis_and_hold(paper_profile):
    cfg = replace(paper_profile.detector, hold_s=2.5, hysteresis=0.2)
    m = StateMachine(cfg)
    seq = [(3, 3, True, True), (2.2, 2.2, True, True), (0, 0, True, True), (0, 0, True, True), (0, 0, True, True)]
    # 2.2 > 2.5 * 0.8: still slip by hysteresis; then held until 2.5 s after that evidence (t = 1)
    assert steps(m, seq) == [S.SLIP, S.SLIP, S.SLIP, S.SLIP, S.STABLE]


def test_confirmation(paper_profile):
    m = StateMachine(replace(paper_profile.detector, slip_confirm_updates=2, hold_s=0.0))
    assert steps(m, [(3, 3, True, True), (3, 3, True, True)]) == [S.VARIABLE_FORCE, S.SLIP]


def test_unknown_never_becomes_confident(paper_profile):
    m = StateMachine(paper_profile.detector)
    got = steps(m, [(9, 9, True, False), (9, 9, True, False), (9, 9, False, True)])
    assert got == [S.STABLE, S.STABLE, S.NO_CONTACT]  # invalid updates never read slip


@pytest.mark.parametrize("state", list(S))
def test_labels_round_trip(state):
    assert S.from_label(state.label) is state
    assert state.label in ("no_contact", "stable", "variable_force", "slip")


def test_decision_rules():
    d = Decision(hold_s=1.0, confirm=2)
    assert d.decide(0.0, True, False, True, True) == S.STABLE  # contact, no verdict yet: never slip
    assert d.decide(0.1, True, True, True, False) == S.VARIABLE_FORCE  # slip evidence, not yet confirmed
    assert d.decide(0.2, True, True, True, False) == S.SLIP
    assert d.decide(0.3, True, True, False, False) == S.SLIP  # held for hold_s after entry
    assert d.decide(0.4, True, False, False, False) == S.SLIP  # not valid: kept
    assert d.decide(1.2, True, True, False, True) == S.VARIABLE_FORCE  # down once the hold is over
    assert d.decide(1.3, False, True, True, True) == S.NO_CONTACT  # out of contact: at once, hold or not


def test_varying_force_is_one_entry_and_one_exit():
    """Entered at the first score of 1; kept while the score stays at or above the exit
    level, and through dips below it shorter than exit_s; left once it has been below
    for exit_s and the state has lasted min_dwell_s."""
    d = Decision(hold_s=0.2, latch=VaryingLatch(exit_level=0.8, exit_s=0.15, min_dwell_s=0.5))
    scores = {0.0: 0.5, 0.1: 1.2, 0.2: 0.9, 0.3: 0.3, 0.4: 0.6, 0.5: 1.5, 0.6: 0.7, 0.7: 0.85, 0.8: 0.7,
              0.9: 0.5, 1.0: 0.4, 1.1: 0.2, 1.2: 0.95, 1.3: 0.5}
    got = {t: S(d.decide(t, True, True, False, v)) for t, v in scores.items()}
    changes = [t for t in sorted(got) if t > 0 and got[t] != got[round(t - 0.1, 1)]]
    # in at 0.1; the dips at 0.3-0.4 and 0.6 are shorter than 0.15 s; below 0.8 from 0.8:
    # out at 0.95 at the earliest, so at 1.0; 0.95 later is under the entry level: no re-entry
    assert changes == [0.1, 1.0]
    assert got[0.9] == S.VARIABLE_FORCE and got[1.0] == S.STABLE and got[1.2] == S.STABLE


def test_varying_force_lasts_its_minimum_dwell():
    d = Decision(hold_s=0.2, latch=VaryingLatch(exit_level=0.8, exit_s=0.0, min_dwell_s=0.5))
    got = [S(d.decide(t / 10, True, True, False, 1.0 if t == 1 else 0.0)) for t in range(10)]
    assert got == [S.STABLE] + [S.VARIABLE_FORCE] * 5 + [S.STABLE] * 4  # in at 0.1, out at 0.6


def test_slip_pre_empts_varying_force_at_once_and_comes_back_to_it():
    d = Decision(hold_s=0.2, latch=VaryingLatch(exit_level=0.8, exit_s=0.15, min_dwell_s=0.5))
    seq = [(0.0, False, 2.0), (0.01, True, 2.0), (0.02, False, 2.0), (0.1, False, 2.0), (0.22, False, 2.0),
           (0.3, False, 0.0), (0.4, False, 0.0), (0.5, False, 0.0)]
    got = [S(d.decide(t, True, True, slip, v)) for t, slip, v in seq]
    # slip at the first update with slip evidence, in the middle of a varying force;
    # held for hold_s (0.2 s), then back to the varying force, which is still on; its
    # exit waits exit_s after the score falls
    assert got == [S.VARIABLE_FORCE, S.SLIP, S.SLIP, S.SLIP, S.VARIABLE_FORCE, S.VARIABLE_FORCE,
                   S.VARIABLE_FORCE, S.STABLE]
    # and from a still grip too, with no varying force before or after
    d = Decision(hold_s=0.2)
    assert [S(d.decide(t, True, True, slip, 0.0)) for t, slip in [(0.0, False), (0.01, True), (0.3, False)]] == [
        S.STABLE, S.SLIP, S.STABLE]


def test_losing_contact_clears_the_varying_force_latch():
    d = Decision(hold_s=0.2, latch=VaryingLatch(exit_level=0.8, exit_s=0.15, min_dwell_s=5.0))
    assert d.decide(0.0, True, True, False, 1.0) == S.VARIABLE_FORCE
    assert d.decide(0.1, False, True, False, 0.0) == S.NO_CONTACT
    assert d.decide(0.2, True, False, False, 0.0) == S.STABLE  # a new contact, not yet valid
    assert d.decide(0.3, True, True, False, 0.0) == S.STABLE  # not the old episode's dwell


def test_contact_rule_enters_at_the_threshold_and_stays_above_half_of_it():
    rule = ContactRule(0.2)
    totals = [0.15, 0.2, 0.15, 0.11, 0.09, 0.15, 0.25, 0.0, 0.1]
    was, got = False, []
    for s in totals:
        was = rule.touching(s, was)
        got.append(was)
    assert got == [False, True, True, True, False, False, True, False, False]
    assert rule.mask(np.array(totals)).tolist() == got
    assert not ContactRule(0.0).touching(0.0, True)  # a zero total is never contact


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(0.0, 0.4), max_size=200), st.floats(0.0, 0.3))
def test_contact_mask_is_the_per_frame_rule(totals, threshold):
    rule = ContactRule(threshold)
    was, expected = False, []
    for s in totals:
        was = rule.touching(s, was)
        expected.append(was)
    assert rule.mask(np.asarray(totals, float)).tolist() == expected


def hovering_touch(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The total force wobbles around contact_threshold_n (0.2 N) for two seconds."""
    rng = np.random.default_rng(seed)
    t = np.arange(300) / 100.0
    total = np.where(t < 0.5, 0.0, 0.2 + 0.03 * rng.standard_normal(300))
    return t, np.tile(total[:, None] / 25.0, (1, 25)) * (1 + 0.1 * rng.standard_normal((300, 25)))


@pytest.mark.parametrize("method", ["paper", "paper-dw", "force-rate", "hf-energy", "cof-velocity", "cof-track"])
def test_every_method_uses_the_one_contact_rule(paper_profile, method):
    # a first touch hovering at the threshold: once touching, no method flickers back
    t, f = hovering_touch()
    x, y = paper_profile.coordinates_mm
    cfg = replace(paper_profile.detector, hop_s=0.05, window_s=0.2)  # updates often enough to see a flicker
    states = get_method(method).batch(cfg, x, y, 100.0, t, f).state
    touched = np.flatnonzero(states != S.NO_CONTACT)
    assert touched.size and not (states[touched[0]:] == S.NO_CONTACT).any()


def test_slip_is_left_only_once_its_evidence_has_been_absent_for_hold_s():
    """An off-delay (a PLC's TOF): evidence that comes and goes during one slide, with
    gaps shorter than hold_s, is one slip; it is left hold_s after the last evidence.
    Counted from the entry instead, the state left at the first gap after hold_s and
    came back at the next vote: a new slip, and SLIP_EVENTS count, each time."""
    d = Decision(hold_s=0.2)
    seq = [(0.0, False), (0.01, True), (0.15, False), (0.25, True), (0.3, False), (0.4, True), (0.5, False),
           (0.59, False), (0.61, False)]
    got = [S(d.decide(t, True, True, slip, 0.0)) for t, slip in seq]
    assert got == [S.STABLE] + [S.SLIP] * 7 + [S.STABLE]  # out at 0.61: 0.2 s after the vote at 0.4
    assert d.entered_t == 0.61


def test_a_slow_slide_whose_evidence_comes_and_goes_is_one_slip():
    """Paper case 5 (4 N, 3 mm/s) at tuning seed 0: near its end the slide's evidence
    hovers at its threshold; with the hold counted from the entry the STATE went
    slip, variable_force, slip, ... five slips for one slide.  Now one."""
    from eskin_industrial.detect.cof_track import CofTrack
    from eskin_industrial.detect.updates import UpdateTable
    from eskin_industrial.evaluation.corpus import coordinates
    from eskin_industrial.evaluation.metrics import score_scene
    from eskin_industrial.evaluation.suite import DEFAULT_SETTINGS
    from eskin_industrial.scenes import render

    r = render("case5", 100.0, 0)
    det = CofTrack(DEFAULT_SETTINGS, *coordinates(r), r.rate_hz)
    updates = UpdateTable.from_updates(det.feed(r.t, r.forces))
    score = score_scene(updates, r.t, r.labels)
    assert score.found == score.events == 1 and score.slip_episodes == [1]
    slips = np.flatnonzero(np.diff(np.r_[0, (updates.state == S.SLIP).astype(int)]) == 1)
    assert len(slips) == 1


def test_hold_from_entry_keeps_the_minimum_length_rule(tmp_path):
    """``hold_from = "entry"`` counts hold_s from the slip's entry (a minimum length,
    the rule before the off-delay): the same evidence flickers the state; a profile
    sets it, and a misspelt value is refused before anything starts."""
    from eskin_industrial import load_profile
    from eskin_industrial.errors import ProfileError
    from tests.helpers.paths import PROFILES

    d = Decision(hold_s=0.2, hold_from="entry")
    seq = [(0.0, False), (0.01, True), (0.15, False), (0.25, True), (0.3, False), (0.4, True), (0.5, False)]
    got = [S(d.decide(t, True, True, slip, 0.0)) for t, slip in seq]
    assert got == [S.STABLE, S.SLIP, S.SLIP, S.SLIP, S.STABLE, S.SLIP, S.SLIP]  # out at 0.3, a new slip at 0.4
    text = (PROFILES / "paper-5x5.toml").read_text()
    path = tmp_path / "p.toml"
    path.write_text(text.replace("hold_s = 0.2\n", 'hold_s = 0.2\nhold_from = "entry"\n', 1))
    det = load_profile(path).detector
    assert det.hold_from == "entry" and Decision.from_settings(det).from_entry
    assert not Decision.from_settings(load_profile(PROFILES / "paper-5x5.toml").detector).from_entry
    path.write_text(text.replace("hold_s = 0.2\n", 'hold_s = 0.2\nhold_from = "entri"\n', 1))
    with pytest.raises(ProfileError, match="hold_from"):
        load_profile(path)


def test_cof_track_keeps_a_slip_while_its_evidence_stays_above_the_hysteresis_level():
    """In the slip state cof-track's scores keep the slip above (1 - hysteresis) of
    their thresholds, as the paper's rule keeps its indicators: a slide slowing to a
    stop (paper case 3 at 1 mm/s, tuning seed 0) is one slip; entries are unchanged."""
    from eskin_industrial.detect.cof_track import CofTrack
    from eskin_industrial.detect.updates import UpdateTable
    from eskin_industrial.evaluation.conditions import CONDITIONS
    from eskin_industrial.evaluation.corpus import coordinates
    from eskin_industrial.evaluation.metrics import score_scene
    from eskin_industrial.evaluation.suite import DEFAULT_SETTINGS
    from eskin_industrial.scenes import load_scene, render

    r = render(CONDITIONS["speed"][2](1.0)(load_scene("case3")), 100.0, 0)
    runs = {}
    for hysteresis in (0.0, DEFAULT_SETTINGS.hysteresis):
        det = CofTrack(replace(DEFAULT_SETTINGS, hysteresis=hysteresis), *coordinates(r), r.rate_hz)
        table = UpdateTable.from_updates(det.feed(r.t, r.forces))
        runs[hysteresis] = (table, score_scene(table, r.t, r.labels))
    without, kept = runs[0.0][1], runs[DEFAULT_SETTINGS.hysteresis][1]
    assert without.slip_episodes[0] >= 3 and kept.slip_episodes == [1]  # (4 before the step channel, 3 with it)
    assert kept.delays_s == without.delays_s  # the entry is the same
    slip = [np.asarray(t.state) == S.SLIP for t, _ in runs.values()]
    assert not (slip[0] & ~slip[1]).any()  # the kept run reads slip wherever the other does
