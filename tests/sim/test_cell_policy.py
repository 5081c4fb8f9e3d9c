"""The closed loop's PLC program: raise on a slip, acknowledge once it is over, raise
again only while the part still moves, relax after a quiet time; and "I don't know"
(a still heartbeat, DATA_VALID clear, SENSOR_STALE, BUS_FAULT, BRIDGE_OFFLINE) is not
"no slip"."""
from __future__ import annotations

from dataclasses import replace

import pytest

from eskin_industrial.outputs.plc.image import Status
from eskin_industrial.sim.cell.objects import OBJECTS
from eskin_industrial.sim.cell.policy import GripPolicy, PolicySettings
from eskin_industrial.sim.cell.recipes import MIN_GRIP_N, crush_cap_n, fixed_grip_n, policy_settings

SETTINGS = PolicySettings(light_n=2.0, step_n=1.0, max_n=6.0, fallback_n=8.0, repeat_s=0.2, repeat_mm=1.0,
                          quiet_s=1.0, relax_share=0.25, relax_floor=0.0, heartbeat_timeout_s=0.5, grace_s=1.0)
HELD = Status.CONTACT | Status.STABLE | Status.DATA_VALID | Status.ENABLED
SLIP = Status.CONTACT | Status.SLIP | Status.SLIP_LATCHED | Status.DATA_VALID | Status.ENABLED


class Plc:
    """The program on a 10 ms cycle against registers the test sets; the heartbeat
    moves at every cycle unless told not to."""

    def __init__(self, settings: PolicySettings = SETTINGS) -> None:
        self.policy = GripPolicy(settings)
        self.t = 0.0
        self.hb = 0
        self.xc = 1000
        self.acks = 0

    def run(self, seconds: float, status: int, beat: bool = True, moving_mm_s: float = 0.0) -> float:
        out = None
        for _ in range(int(round(seconds / 0.01))):
            self.t += 0.01
            if beat:
                self.hb += 1
            self.xc += int(round(moving_mm_s * 0.01 * 100))
            out = self.policy.cycle(self.t, {"STATUS": int(status), "HEARTBEAT": self.hb, "XC": self.xc, "YC": 0})
            self.acks += out.ack
        assert out is not None
        return out.request_n


def gripping(settings: PolicySettings = SETTINGS) -> Plc:
    plc = Plc(settings)
    plc.policy.grip(0.0)
    assert plc.run(1.0, HELD) == settings.light_n  # trusted, no slip: the light grip
    return plc


def test_a_slip_raises_one_step_and_the_latch_is_acknowledged_once_it_is_over():
    plc = gripping()
    assert plc.run(0.05, SLIP) == 3.0
    assert plc.acks == 0  # not while it slips
    assert plc.run(0.5, SLIP) == 3.0  # the slip state outlasts the slide: the part does not move, no more
    latched_only = HELD | Status.SLIP_LATCHED
    plc.run(0.02, latched_only)
    assert plc.acks > 0
    assert [r.why for r in plc.policy.raises] == ["slip"]


def test_a_part_that_still_moves_gets_another_step_each_repeat_time_up_to_the_maximum():
    plc = gripping()
    assert plc.run(0.25, SLIP, moving_mm_s=20.0) == 4.0  # 20 mm/s: 4 mm in 0.2 s
    assert plc.run(2.0, SLIP, moving_mm_s=20.0) == SETTINGS.max_n
    assert [r.why for r in plc.policy.raises] == ["slip"] + ["still slipping"] * 3


def test_the_centre_of_force_moving_while_the_grip_rises_is_not_taken_for_a_slide():
    # a soft pad's contact grows with the force: the raise itself moves the centre
    plc = gripping()
    assert plc.run(0.05, SLIP) == 3.0
    assert plc.run(0.05, SLIP, moving_mm_s=30.0) == 3.0  # 1.5 mm while the grip settles
    assert plc.run(0.5, SLIP) == 3.0  # then still: no second step
    assert [r.why for r in plc.policy.raises] == ["slip"]


def test_max_mode_goes_straight_to_the_maximum():
    plc = gripping(replace(SETTINGS, mode="max"))
    assert plc.run(0.05, SLIP) == SETTINGS.max_n


def test_after_a_quiet_time_it_relaxes_by_a_share_to_the_light_grip_or_its_floor():
    plc = gripping()
    plc.run(0.05, SLIP, moving_mm_s=30.0)
    plc.run(0.3, SLIP, moving_mm_s=30.0)
    assert plc.policy.request_n == 4.0
    assert plc.run(0.9, HELD) == 4.0  # not before quiet_s
    assert plc.run(0.2, HELD) == 3.0  # a quarter of the request
    assert plc.run(1.0, HELD) == 2.25 and plc.run(3.0, HELD) == 2.0  # never below the light grip
    floored = gripping(replace(SETTINGS, relax_floor=1.25))
    floored.run(0.05, SLIP, moving_mm_s=30.0)
    floored.run(0.3, SLIP, moving_mm_s=30.0)  # last slipped at 3 N: no lower than 3.75 N
    assert floored.run(5.0, HELD) == 3.75


@pytest.mark.parametrize("why, status, beat", [
    ("heartbeat still", HELD, False),
    ("DATA_VALID clear", Status.CONTACT | Status.STABLE | Status.ENABLED, True),
    ("SENSOR_STALE", Status.SENSOR_STALE | Status.ENABLED, True),
    ("BUS_FAULT", HELD | Status.BUS_FAULT, True),
    ("BRIDGE_OFFLINE", Status.BRIDGE_OFFLINE, True),
])
def test_no_verdict_is_not_no_slip_the_grip_goes_to_the_fallback_and_never_relaxes(why, status, beat):
    plc = gripping()
    if not beat:
        assert plc.run(0.4, status, beat=beat) == SETTINGS.light_n  # the heartbeat's watchdog takes 0.5 s
    assert plc.run(0.2, status, beat=beat) == SETTINGS.fallback_n, why
    assert plc.policy.no_verdict
    assert plc.run(5.0, status, beat=beat) == SETTINGS.fallback_n  # no relaxing while it cannot tell
    assert [r.why for r in plc.policy.raises] == ["no verdict"]
    # trusted again: "no slip" now, and after the quiet time it relaxes
    assert plc.run(1.1, HELD) < SETTINGS.fallback_n and not plc.policy.no_verdict


def test_the_skins_warm_up_after_the_grip_is_no_fault_until_its_grace_ends():
    plc = Plc()
    plc.run(0.2, Status.DATA_VALID | Status.ENABLED)  # open: "no contact" is a verdict
    plc.policy.grip(plc.t)
    warming = Status.CONTACT | Status.STABLE | Status.ENABLED
    assert plc.run(0.9, warming) == SETTINGS.light_n and not plc.policy.no_verdict
    assert plc.run(0.2, warming) == SETTINGS.fallback_n  # still no verdict 1 s after the grip
    late = Plc()
    late.policy.grip(0.0)
    late.run(0.5, HELD)  # the first verdict in contact ends the grace at once
    assert late.run(0.05, warming) == SETTINGS.fallback_n


def test_each_objects_recipe_grips_lightly_below_its_fixed_grip_and_never_past_its_crush_cap():
    for kind in OBJECTS:
        s = policy_settings(kind)
        fixed = fixed_grip_n(kind)
        assert MIN_GRIP_N <= s.light_n < s.max_n <= fixed == s.fallback_n
        cap = crush_cap_n(kind)
        if cap is not None:
            assert fixed <= cap


def test_a_creep_too_slow_for_the_repeat_test_is_still_answered_by_the_distance_slid():
    # 4 mm/s: 0.8 mm per 0.2 s, under repeat_mm (a cup crept so at 4.6 mm/s for 1.9 s with SLIP set
    # and dropped)
    plc = gripping()
    assert plc.run(0.05, SLIP, moving_mm_s=4.0) == 3.0
    assert plc.run(0.4, SLIP, moving_mm_s=4.0) == 3.0  # 1.4 mm since the raise settled: not yet
    assert plc.run(0.3, SLIP, moving_mm_s=4.0) == 4.0  # 2 mm from where it stood: another step
    assert plc.run(1.2, SLIP, moving_mm_s=4.0) == SETTINGS.max_n
    assert [r.why for r in plc.policy.raises] == ["slip"] + ["still slipping"] * 3


def test_a_centre_that_wanders_back_and_forth_under_a_lingering_slip_state_is_no_creep():
    # the slip state outlasts the slide; a centre of force jittering by a millimetre is not a slide
    plc = gripping()
    assert plc.run(0.05, SLIP) == 3.0
    for _ in range(10):
        plc.run(0.1, SLIP, moving_mm_s=10.0)  # 1 mm out
        plc.run(0.1, SLIP, moving_mm_s=-10.0)  # and back
    assert plc.policy.request_n == 3.0 and [r.why for r in plc.policy.raises] == ["slip"]


def test_the_creep_test_can_be_switched_off():
    plc = gripping(replace(SETTINGS, creep_mm=0.0))
    plc.run(0.05, SLIP, moving_mm_s=4.0)
    assert plc.run(2.0, SLIP, moving_mm_s=4.0) == 3.0


HYBRID = replace(SETTINGS, mode="hybrid", escalate_mm=3.0)


def test_hybrid_mode_answers_a_slip_with_one_step_and_holds_there_if_the_part_stops():
    plc = gripping(HYBRID)
    assert plc.run(0.05, SLIP) == 3.0  # the first answer is a step, as in step mode
    assert plc.run(0.05, SLIP, moving_mm_s=30.0) == 3.0  # 1.5 mm while the pads grow under it: no more
    assert plc.run(1.0, SLIP) == 3.0
    assert [r.why for r in plc.policy.raises] == ["slip"]


def test_hybrid_mode_sends_a_slide_that_runs_past_the_step_to_the_maximum_at_once():
    # 100 mm/s: 3 mm from the alarm within 30 ms, long before the 0.2 s repeat (step mode's
    # second step would come after the part had slid 20 mm)
    plc = gripping(HYBRID)
    assert plc.run(0.01, SLIP, moving_mm_s=100.0) == 3.0
    assert plc.run(0.03, SLIP, moving_mm_s=100.0) == SETTINGS.max_n
    assert plc.policy.raises[-1].t < 1.05 and [r.why for r in plc.policy.raises] == ["slip", "still slipping"]
    stepping = gripping()
    stepping.run(0.01, SLIP, moving_mm_s=100.0)
    assert stepping.run(0.03, SLIP, moving_mm_s=100.0) == 3.0  # step mode waits for its repeat


def test_hybrid_mode_escalates_a_slow_slide_to_the_maximum_on_the_repeat_test():
    # with the distance test off, the repeat test's further raise is the maximum, not another step
    plc = gripping(replace(HYBRID, escalate_mm=0.0))
    assert plc.run(0.05, SLIP, moving_mm_s=20.0) == 3.0
    assert plc.run(0.2, SLIP, moving_mm_s=20.0) == SETTINGS.max_n  # 4 mm in 0.2 s: one step was not enough
    assert [r.why for r in plc.policy.raises] == ["slip", "still slipping"]


def test_hybrid_mode_counts_the_distance_of_each_slip_from_its_own_alarm():
    plc = gripping(HYBRID)
    plc.run(0.05, SLIP, moving_mm_s=20.0)  # 1 mm, stopped by the step
    plc.run(0.5, SLIP)
    plc.run(0.1, HELD)  # over and acknowledged
    plc.run(0.5, HELD, moving_mm_s=10.0)  # the hand moves the part 5 mm with no slip: no alarm
    assert plc.run(0.05, SLIP) == 4.0  # a new slip: a new step, not the maximum
    assert [r.why for r in plc.policy.raises] == ["slip", "slip"]


def test_a_relax_spread_over_its_time_lowers_the_request_a_little_each_cycle_and_a_slip_stops_it():
    plc = gripping(replace(SETTINGS, relax_s=0.5))
    plc.run(0.05, SLIP, moving_mm_s=30.0)
    plc.run(0.3, SLIP, moving_mm_s=30.0)
    assert plc.policy.request_n == 4.0
    assert plc.run(1.0, HELD) == 4.0  # not before quiet_s
    halfway = plc.run(0.25, HELD)
    assert 3.0 < halfway < 4.0 and plc.policy.relaxes == 0  # under way: about half of the quarter
    assert plc.run(0.3, HELD) == pytest.approx(3.0)  # the whole share once relax_s is over
    assert plc.policy.relaxes == 1
    again = gripping(replace(SETTINGS, relax_s=0.5))
    again.run(0.05, SLIP, moving_mm_s=30.0)
    again.run(0.3, SLIP, moving_mm_s=30.0)
    again.run(1.1, HELD)
    stopped = again.run(0.01, SLIP)  # a slip during the relax: it stops there, and the step comes on top
    assert stopped > 4.0 and again.policy.relaxes == 0
