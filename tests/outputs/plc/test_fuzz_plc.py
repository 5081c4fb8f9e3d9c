"""Fuzz tests of the PLC side: the writes a PLC may send, the register image rendered
from any detector update and health, and the server's register handler.

The PLC must never see a register outside 0..65535, two states at once, or
DATA_VALID over a stale sensor, a bus fault or an update that is no verdict.
"""
from __future__ import annotations

import dataclasses

from hypothesis import given
from hypothesis import strategies as st

from eskin_industrial import load_profile
from eskin_industrial.detect.state import GraspState
from eskin_industrial.detect.updates import Update
from eskin_industrial.errors import Refused
from eskin_industrial.node import Command, Health
from eskin_industrial.outputs.plc.image import (
    COILS,
    IMAGE_COUNT,
    REG,
    STATUS_COUNT,
    Status,
    parse_coil_write,
    parse_register_write,
)
from eskin_industrial.outputs.plc.server import PlcRegisterHandler
from tests.helpers.fuzz import fuzz
from tests.helpers.paths import PROFILES
from tests.helpers.snapshots import StatusImage

PROFILE = load_profile(PROFILES / "paper-5x5.toml")
PLC = PROFILE.modbus.plc
STALE_S = PROFILE.stale_s
COMMAND_NAMES = {"ack", "tare", "enable", "disable"}
STATE_BITS = {GraspState.STABLE: Status.STABLE, GraspState.VARIABLE_FORCE: Status.VARIABLE_FORCE,
              GraspState.SLIP: Status.SLIP}

# any float, with the extremes drawn often: a finite value can still overflow once scaled
any_float = st.floats(allow_nan=True, allow_infinity=True) | st.sampled_from(
    [0.0, -0.0, 1e-300, 1e300, -1e300, 1.7e308, -1.7e308, 65535.5, 4294967.2955, -32768.5])
updates = st.builds(
    Update, t=any_float, r_coe=any_float, r_dw=any_float, state=st.sampled_from([int(s) for s in GraspState]),
    valid=st.booleans(), f_sum=any_float, xc=any_float, yc=any_float, flags=st.integers(0, 2**40),
)
healths = st.builds(
    Health,
    frame_age_s=st.none() | st.floats(-1.0, 1e9) | st.sampled_from([0.0, STALE_S, STALE_S * 1.0001]),
    bus_fault=st.booleans(), lost_scans=st.integers(0, 2**40), bus_errors=st.integers(0, 2**40),
)
commands = st.builds(Command, st.sampled_from(sorted(COMMAND_NAMES)))


@fuzz(300)
@given(offset=st.integers(-5, IMAGE_COUNT + 5),
       values=st.lists(st.integers(0, 0xFFFF) | st.integers(-2**20, 2**20), max_size=8))
def test_register_writes_are_refused_or_valid_commands(offset, values):
    try:
        cmds = parse_register_write(offset, values)
    except Refused as exc:
        assert exc.code in (2, 3) and "\n" not in str(exc)
        return
    at = {offset + i: v for i, v in enumerate(values)}
    assert set(at) <= {REG["COMMAND"].offset, REG["ENABLE"].offset}
    assert all(isinstance(c, Command) and c.name in COMMAND_NAMES for c in cmds)
    if REG["ENABLE"].offset in at:
        assert at[REG["ENABLE"].offset] in (0, 1)
    if REG["COMMAND"].offset in at:
        assert 0 <= at[REG["COMMAND"].offset] <= 3


@fuzz(300)
@given(offset=st.integers(-5, 10), values=st.lists(st.booleans(), max_size=8))
def test_coil_writes_are_refused_or_valid_commands(offset, values):
    try:
        cmds = parse_coil_write(offset, values)
    except Refused as exc:
        assert exc.code == 2
        assert not 0 <= offset or offset + len(values) > len(COILS)
        return
    assert 0 <= offset and offset + len(values) <= len(COILS) or not values
    assert all(c.name in COMMAND_NAMES for c in cmds)


@fuzz(150)
@given(steps=st.lists(st.tuples(st.one_of(updates, commands), healths), min_size=1, max_size=25),
       word_order=st.sampled_from(["big", "little"]))
def test_the_image_is_always_in_range_and_consistent(steps, word_order):
    image = StatusImage(dataclasses.replace(PLC, word_order=word_order), STALE_S)
    for event, health in steps:
        if isinstance(event, Command):
            image.apply(event)
        else:
            assert image.observe(event) in (True, False)
        regs = image.render(health)
        assert len(regs) == STATUS_COUNT
        assert all(isinstance(v, int) and 0 <= v <= 0xFFFF for v in regs), regs
        status = Status(regs[REG["STATUS"].offset])
        state = regs[REG["STATE"].offset]
        u = image.update
        stale = health.frame_age_s is None or health.frame_age_s > STALE_S
        assert bool(status & Status.SENSOR_STALE) == stale
        assert bool(status & Status.BUS_FAULT) == health.bus_fault
        assert bool(status & Status.ENABLED) == image.enabled
        # one state at most, and the STATE register says the same as the bits
        assert sum(bool(status & b) for b in STATE_BITS.values()) <= 1
        assert not (status & Status.STABLE and status & Status.SLIP)
        assert state in (0, 1, 2, 3)
        for s, bit in STATE_BITS.items():
            assert bool(status & bit) == (state == s)
        assert bool(status & Status.CONTACT) == (state != 0)
        if status & Status.DATA_VALID:
            assert u is not None and u.valid and image.enabled and not stale and not health.bus_fault
        if stale or not image.enabled or u is None:
            assert state == 0 and regs[REG["R_COE"].offset] == 0 and regs[REG["R_DW"].offset] == 0
            assert not status & (Status.DATA_VALID | Status.CONTACT)
        if status & Status.SLIP_LATCHED:
            assert image.enabled


@fuzz(300)
@given(base=st.integers(0, 200), data=st.data())
def test_the_register_handler_answers_values_or_an_exception_code(base, data):
    handler = PlcRegisterHandler(dataclasses.replace(PLC, base_address=base))
    handler.publish(data.draw(st.lists(st.integers(0, 0xFFFF), min_size=STATUS_COUNT, max_size=STATUS_COUNT)),
                    data.draw(st.booleans()))
    for _ in range(data.draw(st.integers(1, 6))):
        table = data.draw(st.sampled_from(["coils", "discrete", "holding", "input"]))
        address = data.draw(st.integers(max(0, base - 5), base + IMAGE_COUNT + 5) | st.integers(0, 0xFFFF))
        if data.draw(st.booleans()):
            count = data.draw(st.integers(0, 130))
            out = handler.read(table, address, count)
            if isinstance(out, int):
                assert out == 2
            else:
                assert len(out) == count
                # input registers: the holding block, read-only (function 4)
                assert all(isinstance(v, bool) for v in out) if table in ("coils", "discrete") else all(
                    0 <= v <= 0xFFFF for v in out)
        else:
            values = data.draw(st.lists(st.integers(0, 0xFFFF) if table == "holding" else st.booleans(),
                                        max_size=8))
            before, tares_before = handler.refused, handler.tares_refused
            result = handler.write(table, address, values)
            assert result in (None, 2, 3, 4)  # 4: a tare, with nothing known of the contact (no update yet)
            assert handler.tares_refused == tares_before + (result == 4)
            assert handler.refused == before + (result in (2, 3) and table in ("holding", "coils"))
            holding = handler.read("holding", base, IMAGE_COUNT)
            assert isinstance(holding, list) and holding[REG["ENABLE"].offset] == int(handler.enabled)
