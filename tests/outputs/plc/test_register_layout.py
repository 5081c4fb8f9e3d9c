"""The register image is laid out by the REGISTERS table and read back by
decode_registers: the two are exact inverses, for both word orders, for any detector
update, health and PLC command, the offline image included."""
from __future__ import annotations

import dataclasses

import pytest
from hypothesis import given
from hypothesis import strategies as st

from eskin_industrial import load_profile
from eskin_industrial.node import Command
from eskin_industrial.outputs.plc.image import (
    COIL,
    COIL_COUNT,
    COILS,
    IMAGE_COUNT,
    KIND_RANGE,
    MAIN,
    PUBLISHED,
    REG,
    REGISTERS,
    STATUS_COUNT,
    TAIL,
    TAIL_AT,
    TAIL_COUNT,
    Status,
    coil_values,
    decode_registers,
    decode_tail,
    encode_registers,
    encode_tail,
    parse_coil_write,
)
from eskin_industrial.outputs.plc.server import PlcRegisterHandler
from tests.helpers.fuzz import fuzz
from tests.helpers.paths import PROFILES
from tests.helpers.snapshots import StatusImage
from tests.outputs.plc.test_fuzz_plc import commands, healths, updates

PROFILE = load_profile(PROFILES / "paper-5x5.toml")
PLC = PROFILE.modbus.plc
ORDERS = ["big", "little"]
OFFLINE = {"STATUS": int(Status.BRIDGE_OFFLINE), "STATE": 0, "R_COE": 0, "R_DW": 0, "F_SUM": 0, "FLAGS": 0,
           "FRAME_AGE": 0xFFFF, "SCORE_A": 0, "SCORE_B": 0}


@fuzz(200)
@given(steps=st.lists(st.tuples(st.one_of(updates, commands), healths, st.booleans()), min_size=1, max_size=20),
       word_order=st.sampled_from(ORDERS))
def test_decoding_a_rendered_image_gives_back_its_named_values(steps, word_order):
    image = StatusImage(dataclasses.replace(PLC, word_order=word_order), PROFILE.stale_s)
    for event, health, offline in steps:
        if isinstance(event, Command):
            image.apply(event)
        else:
            image.observe(event)
        regs = image.render_offline(health) if offline else image.render(health)
        values = image.offline_values(health) if offline else image.values(health)
        assert len(regs) == STATUS_COUNT and all(0 <= w <= 0xFFFF for w in regs)
        assert set(values) == {r.name for r in PUBLISHED}
        for r in PUBLISHED:
            lo, hi = KIND_RANGE[r.kind]
            assert lo <= values[r.name] <= hi, r.name
        assert len(image.tail) == TAIL_COUNT and all(0 <= w <= 0xFFFF for w in image.tail)
        assert {**decode_registers(regs, word_order), **decode_tail(image.tail)} == values
        assert encode_registers(values, word_order) == regs and encode_tail(values) == image.tail


@fuzz(200)
@given(words=st.lists(st.integers(0, 0xFFFF), min_size=STATUS_COUNT, max_size=STATUS_COUNT),
       word_order=st.sampled_from(ORDERS))
def test_any_published_words_decode_and_encode_back(words, word_order):
    values = decode_registers(words, word_order)
    assert set(values) == {r.name for r in MAIN}
    assert encode_registers(values, word_order) == words


@fuzz(150)
@given(steps=st.lists(st.tuples(st.one_of(updates, commands), healths), min_size=1, max_size=15),
       word_order=st.sampled_from(ORDERS))
def test_the_offline_image_is_the_image_with_the_offline_values(steps, word_order):
    online = StatusImage(dataclasses.replace(PLC, word_order=word_order), PROFILE.stale_s)
    offline = StatusImage(dataclasses.replace(PLC, word_order=word_order), PROFILE.stale_s)
    for event, health in steps:
        for image in (online, offline):
            image.apply(event) if isinstance(event, Command) else image.observe(event)
        want = {**decode_registers(online.render(health), word_order), **decode_tail(online.tail)}
        got = {**decode_registers(offline.render_offline(health), word_order), **decode_tail(offline.tail)}
        assert got == {**want, **OFFLINE}  # heartbeat, counters and XC/YC kept
        assert got["HEARTBEAT"] == offline.heartbeat


def test_words_follow_the_table_and_the_word_order():
    values = {r.name: 0 for r in PUBLISHED}
    values.update(STATUS=0x0123, XC=-2, YC=-0x8000, F_SUM=0x12345678, BUS_ERRORS=0xFFFF0001)
    for order, f_sum, bus_errors in (("big", [0x1234, 0x5678], [0xFFFF, 1]),
                                     ("little", [0x5678, 0x1234], [1, 0xFFFF])):
        regs = encode_registers(values, order)
        assert regs[REG["STATUS"].offset] == 0x0123
        assert regs[REG["XC"].offset] == 0xFFFE and regs[REG["YC"].offset] == 0x8000  # two's complement
        assert regs[REG["F_SUM"].offset: REG["F_SUM"].offset + 2] == f_sum
        assert regs[REG["BUS_ERRORS"].offset: REG["BUS_ERRORS"].offset + 2] == bus_errors
        assert decode_registers(regs, order) == {r.name: values[r.name] for r in MAIN}
        assert decode_tail(encode_tail(values)) == {r.name: values[r.name] for r in TAIL}
    with pytest.raises(KeyError):
        encode_registers({"STATUS": 0}, "big")  # a publication names every register


def test_the_read_only_registers_are_the_publication():
    # two runs: STATUS..METHOD_ID from the base, the PLC's COMMAND and ENABLE, then the
    # scores appended (so that no older address moved)
    assert [r.name for r in REGISTERS if r.offset < STATUS_COUNT] == [r.name for r in MAIN]
    assert [r.name for r in REGISTERS if STATUS_COUNT <= r.offset < TAIL_AT] == ["COMMAND", "ENABLE"]
    assert all(r.access == "RW" for r in REGISTERS if STATUS_COUNT <= r.offset < TAIL_AT)
    assert [r.name for r in REGISTERS if r.offset >= TAIL_AT] == [r.name for r in TAIL] == ["SCORE_A", "SCORE_B"]
    assert [r.name for r in PUBLISHED] == [r.name for r in MAIN + TAIL]
    assert IMAGE_COUNT == TAIL_AT + TAIL_COUNT
    # the addresses of the image before the scores were added
    assert [(r.name, r.offset) for r in REGISTERS][:19] == [
        ("STATUS", 0), ("STATE", 1), ("R_COE", 2), ("R_DW", 3), ("F_SUM", 4), ("XC", 6), ("YC", 7), ("HEARTBEAT", 8),
        ("FRAME_AGE", 9), ("SLIP_EVENTS", 10), ("STATE_CHANGES", 12), ("LOST_SCANS", 14), ("BUS_ERRORS", 16),
        ("FLAGS", 18), ("METHOD_ID", 19), ("COMMAND", 20), ("ENABLE", 21), ("SCORE_A", 22), ("SCORE_B", 23)]


def test_coil_offsets_come_from_the_table():
    assert sorted(c.offset for c in COILS) == list(range(COIL_COUNT)) and COIL_COUNT == len(COILS)
    at = {c.name: c.offset for c in COILS}
    for enabled in (True, False):
        values = coil_values(enabled)
        assert len(values) == COIL_COUNT
        assert values[at["ENABLE"]] is enabled and not values[at["ACK_SLIP"]] and not values[at["TARE"]]
    assert parse_coil_write(at["ACK_SLIP"], [True]) == [Command("ack")]
    assert parse_coil_write(at["TARE"], [True]) == [Command("tare")]
    assert parse_coil_write(at["ACK_SLIP"], [False]) == parse_coil_write(at["TARE"], [False]) == []
    assert parse_coil_write(at["ENABLE"], [False]) == [Command("disable")]
    assert parse_coil_write(at["ENABLE"], [True]) == [Command("enable")]
    assert COIL["ENABLE"].offset == at["ENABLE"]


@pytest.mark.parametrize("base", [0, 100])
def test_the_server_reads_the_coils_of_the_table(base):
    handler = PlcRegisterHandler(dataclasses.replace(PLC, base_address=base))
    for enabled in (True, False):
        handler.publish([0] * STATUS_COUNT, enabled)
        assert handler.read("coils", base, COIL_COUNT) == coil_values(enabled)
    assert handler.write("coils", base + COIL["ENABLE"].offset, [True]) is None
    assert handler.read("coils", base + COIL["ENABLE"].offset, 1) == [True]
