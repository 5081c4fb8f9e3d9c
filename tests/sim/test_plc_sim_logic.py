"""The PLC stand-in's example logic: grip harder when the latch rises, acknowledge
the latch only once the slip is over (the latch stays set while it lasts)."""
from __future__ import annotations

from eskin_industrial.outputs.plc.image import Status
from eskin_industrial.sim.plc import Gripper

BASE = Status.CONTACT | Status.DATA_VALID | Status.ENABLED


def scan(g: Gripper, status: int, hb: int, now: float):
    return g.cycle({"STATUS": int(status), "HEARTBEAT": hb}, now)


def test_raise_on_the_latch_then_ack_after_the_slip():
    g = Gripper(force_n=5.0, step_n=2.0)
    assert scan(g, BASE | Status.STABLE, 1, 0.00) == (["data trusted"], False)
    msgs, ack = scan(g, BASE | Status.SLIP | Status.SLIP_LATCHED, 2, 0.01)
    assert g.force_n == 7.0 and g.raises == 1 and not ack  # slipping: latch cannot clear yet
    msgs, ack = scan(g, BASE | Status.SLIP | Status.SLIP_LATCHED, 3, 0.02)
    assert not ack and g.raises == 1
    msgs, ack = scan(g, BASE | Status.STABLE | Status.SLIP_LATCHED, 4, 0.03)
    assert ack and "acknowledging" in msgs[0]
    msgs, ack = scan(g, BASE | Status.STABLE | Status.SLIP_LATCHED, 5, 0.04)
    assert ack and msgs == []  # keeps asking until the bridge clears it, without repeating itself
    assert scan(g, BASE | Status.STABLE, 6, 0.05) == ([], False)
    scan(g, BASE | Status.SLIP | Status.SLIP_LATCHED, 7, 0.06)
    assert g.raises == 2 and g.force_n == 9.0


def test_a_silent_bridge_gets_no_reaction():
    g = Gripper(heartbeat_timeout_s=0.5)
    scan(g, BASE | Status.STABLE, 1, 0.0)
    msgs, ack = scan(g, BASE | Status.SLIP | Status.SLIP_LATCHED, 1, 1.0)  # heartbeat frozen
    assert g.raises == 0 and not ack and any("NO VERDICT" in m for m in msgs)


def test_the_turn_unseen_flag_is_mirrored_as_the_function_block_does():
    """FLAGS bit TURN_UNSEEN, read like FB_SlipGuard's bTurnUnseen: said once when it
    rises and once when it clears; not while the data cannot be trusted."""
    from eskin_industrial.frames import FrameFlag

    g = Gripper()
    unseen = int(FrameFlag.TURN_UNSEEN)
    assert g.cycle({"STATUS": int(BASE | Status.STABLE), "HEARTBEAT": 1, "FLAGS": 0}, 0.0)[0] == ["data trusted"]
    msgs, _ = g.cycle({"STATUS": int(BASE | Status.STABLE), "HEARTBEAT": 2, "FLAGS": unseen}, 0.01)
    assert g.turn_unseen and len(msgs) == 1 and msgs[0].startswith("TURN UNSEEN")
    assert g.cycle({"STATUS": int(BASE | Status.STABLE), "HEARTBEAT": 3, "FLAGS": unseen}, 0.02)[0] == []
    msgs, _ = g.cycle({"STATUS": int(BASE | Status.STABLE), "HEARTBEAT": 4, "FLAGS": 0}, 0.03)
    assert not g.turn_unseen and msgs == ["turns seen again"]
    g.cycle({"STATUS": int(BASE | Status.STABLE), "HEARTBEAT": 4, "FLAGS": unseen}, 1.0)  # heartbeat frozen
    assert not g.turn_unseen
