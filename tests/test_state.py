from __future__ import annotations

from dataclasses import replace

import pytest

from eskin_industrial.detect import GraspState, StateMachine

S = GraspState


def steps(machine, seq):
    return [S(machine.step(t, rc, rd, contact, valid)) for t, (rc, rd, contact, valid) in enumerate(seq)]


def test_paper_rule_needs_both_indicators(paper_profile):
    m = StateMachine(replace(paper_profile.detector, hold_s=0.0))
    got = steps(m, [(0, 0, True, True), (3, 1, True, True), (1, 3, True, True), (3, 3, True, True), (0, 0, True, True)])
    assert got == [S.STABLE, S.VARIABLE_FORCE, S.VARIABLE_FORCE, S.SLIP, S.STABLE]


def test_hysteresis_and_hold(paper_profile):
    cfg = replace(paper_profile.detector, hold_s=2.5, hysteresis=0.2)
    m = StateMachine(cfg)
    seq = [(3, 3, True, True), (2.2, 2.2, True, True), (0, 0, True, True), (0, 0, True, True), (0, 0, True, True)]
    # 2.2 > 2.5 * 0.8: still slip by hysteresis; then held until 2.5 s after entry
    assert steps(m, seq) == [S.SLIP, S.SLIP, S.SLIP, S.STABLE, S.STABLE]


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
