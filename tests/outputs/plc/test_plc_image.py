from __future__ import annotations

import dataclasses
import math

import pytest
from click.testing import CliRunner

from eskin_industrial.cli import main
from eskin_industrial.detect.updates import Update
from eskin_industrial.errors import Refused
from eskin_industrial.node import Command, Health
from eskin_industrial.outputs.plc.image import (
    COIL,
    COILS,
    IMAGE_COUNT,
    REG,
    REGISTERS,
    STATUS_COUNT,
    Status,
    join32,
    map_rows,
    parse_coil_write,
    parse_register_write,
    split32,
)
from tests.helpers.paths import PROFILES
from tests.helpers.snapshots import StatusImage

FRESH = Health(frame_age_s=0.01)


def upd(state: int, valid: bool = True, r_coe: float = 0.0, r_dw: float = 0.0, f_sum: float = 6.0,
        t: float = 1.0) -> Update:
    return Update(t, r_coe, r_dw, state, valid, f_sum, 10.0, 7.5, 0)


def field(regs: list[int], name: str, word_order: str = "big") -> int:
    r = REG[name]
    v = regs[r.offset: r.offset + r.words]
    return join32(v, word_order) if r.words == 2 else v[0]


def test_map_has_no_overlaps_and_the_documented_size(paper_profile):
    used = [o for r in REGISTERS for o in range(r.offset, r.offset + r.words)]
    assert used == sorted(set(used)) == list(range(IMAGE_COUNT))
    assert STATUS_COUNT == REG["COMMAND"].offset
    image = StatusImage(paper_profile.modbus.plc)
    assert len(image.render(FRESH)) == STATUS_COUNT


def test_values_scaling_and_word_order(paper_profile):
    for order in ("big", "little"):
        settings = dataclasses.replace(paper_profile.modbus.plc, word_order=order)
        image = StatusImage(settings)
        image.observe(upd(3, r_coe=4.1234, r_dw=1000.0, f_sum=70000.5))
        regs = image.render(Health(frame_age_s=0.0123, lost_scans=70000, bus_errors=3))
        assert field(regs, "STATE") == 3
        assert field(regs, "R_COE") == 412 and field(regs, "R_DW") == 65535  # saturated
        assert field(regs, "F_SUM", order) == 70000500
        assert split32(70000500, order) == regs[REG["F_SUM"].offset: REG["F_SUM"].offset + 2]
        assert field(regs, "XC") == 1000 and field(regs, "YC") == 750
        assert field(regs, "FRAME_AGE") == 12
        assert field(regs, "LOST_SCANS", order) == 70000 and field(regs, "BUS_ERRORS", order) == 3
        assert field(regs, "SLIP_EVENTS", order) == 1
    assert split32(0x12345678, "big") == [0x1234, 0x5678] and split32(0x12345678, "little") == [0x5678, 0x1234]


def test_status_bits_tell_no_slip_from_unknown(paper_profile):
    image = StatusImage(paper_profile.modbus.plc)
    s = Status(image.bits(FRESH))
    assert not s & Status.DATA_VALID  # nothing seen yet
    image.observe(upd(1, valid=False))
    s = Status(image.bits(FRESH))
    assert s & Status.CONTACT and s & Status.STABLE and not s & Status.DATA_VALID  # warm-up: not a verdict
    image.observe(upd(1))
    assert Status(image.bits(FRESH)) & Status.DATA_VALID
    stale = Status(image.bits(Health(frame_age_s=1.0)))
    assert stale & Status.SENSOR_STALE and not stale & (Status.DATA_VALID | Status.STABLE | Status.CONTACT)
    assert Status(image.bits(Health(frame_age_s=None))) & Status.SENSOR_STALE
    fault = Status(image.bits(Health(frame_age_s=0.01, bus_fault=True)))
    assert fault & Status.BUS_FAULT and not fault & Status.DATA_VALID
    r1, r2 = image.render(FRESH), image.render(FRESH)
    assert field(r2, "HEARTBEAT") == field(r1, "HEARTBEAT") + 1
    assert (r1[0] ^ r2[0]) & Status.BRIDGE_ALIVE  # the life bit toggles


def test_slip_latch_ack_and_enable(paper_profile):
    image = StatusImage(paper_profile.modbus.plc)
    assert image.observe(upd(1))
    assert not image.observe(upd(1))  # nothing new: periodic refresh only
    assert image.observe(upd(3))  # slip: at once
    assert Status(image.bits(FRESH)) & (Status.SLIP | Status.SLIP_LATCHED) == Status.SLIP | Status.SLIP_LATCHED
    image.apply(Command("ack"))
    assert image.latched  # still slipping: the ack cannot hide it
    image.observe(upd(1))
    s = Status(image.bits(FRESH))
    assert s & Status.SLIP_LATCHED and not s & Status.SLIP  # the latch outlives the slip
    image.apply(Command("ack"))
    assert not Status(image.bits(FRESH)) & Status.SLIP_LATCHED
    image.apply(Command("disable"))
    image.observe(upd(3))
    regs = image.render(FRESH)
    s = Status(regs[0])
    assert not s & (Status.ENABLED | Status.SLIP | Status.SLIP_LATCHED | Status.DATA_VALID)
    assert field(regs, "STATE") == 0 and field(regs, "SLIP_EVENTS") == 2  # counted, not claimed
    image.apply(Command("enable"))
    assert Status(image.bits(FRESH)) & (Status.ENABLED | Status.SLIP) == Status.ENABLED | Status.SLIP


def test_writes_outside_the_command_registers_are_refused(paper_profile):
    assert parse_register_write(REG["COMMAND"].offset, [3]) == [Command("ack"), Command("tare")]
    assert parse_register_write(REG["COMMAND"].offset, [0, 1]) == [Command("enable")]
    for offset in (0, REG["STATE"].offset, REG["METHOD_ID"].offset, REG["SCORE_A"].offset, IMAGE_COUNT):
        with pytest.raises(Refused) as info:
            parse_register_write(offset, [1])
        assert info.value.code == 2
    with pytest.raises(Refused) as info:
        parse_register_write(REG["ENABLE"].offset, [7])
    assert info.value.code == 3
    with pytest.raises(Refused):
        parse_register_write(REG["COMMAND"].offset - 1, [0, 1])  # straddles into read-only
    assert parse_coil_write(COIL["ACK_SLIP"].offset, [True, False, False]) == [Command("ack"), Command("disable")]
    with pytest.raises(Refused):
        parse_coil_write(len(COILS), [True])


def test_non_finite_values_do_not_break_the_image(paper_profile):
    image = StatusImage(paper_profile.modbus.plc)
    image.observe(upd(2, r_coe=math.nan, r_dw=math.inf, f_sum=math.nan))
    regs = image.render(FRESH)
    assert all(0 <= v <= 0xFFFF for v in regs)


@pytest.mark.parametrize("fmt", ["csv", "md"])
def test_plc_map_export(fmt):
    result = CliRunner().invoke(main, ["plc", "map", "-p", str(PROFILES / "hand-4x5.toml"), "--format", fmt])
    assert result.exit_code == 0, result.output
    out = result.output
    assert "STATUS" in out and "SLIP_LATCHED" in out and "COMMAND" in out
    assert "40101" in out  # base 100 -> 4xxxx reference
    if fmt == "csv":
        assert out.splitlines()[0].startswith("table,name,address,ref")
    else:
        assert out.startswith("| table |")


def test_map_rows_follow_the_base_address(paper_profile):
    settings = dataclasses.replace(paper_profile.modbus.plc, base_address=9999)
    rows = {r["name"]: r for r in map_rows(settings) if r["table"] == "holding register"}
    assert rows["STATUS"]["address"] == "9999" and rows["STATUS"]["ref"] == "410000"
    assert rows["F_SUM"]["address"] == "10003-10004"


def test_plc_section_is_checked():
    from eskin_industrial.errors import DeprecatedKey, ProfileError
    from eskin_industrial.profile import parse_profile

    base = (PROFILES / "paper-5x5.toml").read_text(encoding="utf-8")
    with pytest.raises(ProfileError, match=r"\[modbus\] plc.word_order"):
        parse_profile(base.replace('word_order = "big"', 'word_order = "middle"'), "p.toml")
    with pytest.warns(DeprecatedKey), pytest.raises(ProfileError, match=r"\[modbus\] plc.mode"):  # an old key, checked as ever
        parse_profile(base.replace("[modbus.plc]\n", '[modbus.plc]\nmode = "master"\n'), "p.toml")
    with pytest.warns(DeprecatedKey), pytest.raises(ProfileError, match="backoff_max_s"):
        parse_profile(base.replace("[modbus.plc]\n", "[modbus.plc]\nbackoff_max_s = 0.01\n"), "p.toml")
    with pytest.raises(ProfileError, match="value_type"):
        parse_profile(base.replace('value_type = "uint16"', 'value_type = "float"'), "p.toml")


@pytest.mark.parametrize("age", [None, math.nan, 10.0])
def test_no_frame_a_broken_clock_or_an_old_frame_is_stale_never_a_verdict(paper_profile, age):
    image = StatusImage(paper_profile.modbus.plc)
    image.observe(upd(1))
    status = Status(image.bits(Health(frame_age_s=age)))
    assert status & Status.SENSOR_STALE and not status & (Status.DATA_VALID | Status.STABLE)


def test_the_offline_image_claims_nothing_and_keeps_the_counters(paper_profile):
    image = StatusImage(paper_profile.modbus.plc)
    image.observe(upd(1))
    image.observe(upd(3))
    regs = image.render_offline(FRESH)
    assert Status(field(regs, "STATUS")) == Status.BRIDGE_OFFLINE
    assert field(regs, "STATE") == 0 and field(regs, "FRAME_AGE") == 0xFFFF and field(regs, "F_SUM") == 0
    assert field(regs, "SLIP_EVENTS") == 1 and field(regs, "STATE_CHANGES") == 1


@pytest.mark.parametrize("word_order", ["big", "little"])
def test_the_rendered_words_are_the_named_values_encoded(paper_profile, word_order):
    """render writes the registers straight (it is on the urgent path): word for word
    what the named values (``values``, the register table's meaning) encode to, over
    snapshots with every field at its edges: none, NaN, infinities, overflows, negative
    values, counters past 32 bits, the offline image."""
    import random

    from eskin_industrial.outputs.plc.image import PlcImage, encode_registers, encode_tail

    settings = dataclasses.replace(paper_profile.modbus.plc, word_order=word_order)
    rng = random.Random(7)
    floats = [None, 0.0, 0.4999, 0.5, 1.5, -0.5, -1.0, 2.5, 655.36, 1e9, -1e9, math.nan, math.inf, -math.inf, 1e300,
              12.3456, -327.69, 327.675, 4294967.2955]
    ints = [0, 1, 0xFFFF, 0x10000, 0xFFFFFFFF, 0x1_0000_0001, 2**40 + 3]
    status = StatusImage(settings)
    status.observe(upd(1))
    base = status.snapshot(FRESH)
    ref = PlcImage(settings)
    image = PlcImage(settings)
    offline = status.status.offline_snapshot(FRESH, scans=0, t_event=0.0, wall_time_s=0.0)
    for i in range(3000):
        s = (offline if i % 97 == 0 else base)._replace(
            state=rng.choice([None, 0, 1, 2, 3]), valid=rng.random() < 0.5, stale=rng.random() < 0.2,
            bus_fault=rng.random() < 0.2, slip_latched=rng.random() < 0.3, enabled=rng.random() < 0.8,
            r_coe=rng.choice(floats), r_dw=rng.choice(floats), score_a=rng.choice(floats),
            score_b=rng.choice(floats), f_sum_n=rng.choice(floats), xc_mm=rng.choice(floats),
            yc_mm=rng.choice(floats), frame_age_s=rng.choice([None, 0.0, 0.0125, 65.5, 1e9, math.nan, math.inf]),
            slip_events=rng.choice(ints), state_changes=rng.choice(ints), lost_scans=rng.choice(ints),
            bus_errors=rng.choice(ints), flags=rng.choice([0, 1024, 0x1_0003]), method_code=rng.choice([0, 1, 4]))
        regs = image.render(s)
        ref.heartbeat = image.heartbeat  # the heartbeat as render advanced it
        values = ref.values(s)
        assert regs == encode_registers(values, word_order), (i, s)
        assert image.tail == encode_tail(values), (i, s)
        assert all(type(w) is int and 0 <= w <= 0xFFFF for w in regs + image.tail)
