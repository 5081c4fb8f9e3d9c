"""The server's PDU handler, pure: any bytes in, a response of the specification's
shape out, never an exception; and the register handler of server mode behind it
(the holding block, its input-register mirror, the coils and discrete inputs)."""

from __future__ import annotations

import struct

from hypothesis import given
from hypothesis import strategies as st

from eskin_industrial import load_profile
from eskin_industrial.modbus import pdu
from eskin_industrial.outputs.plc.image import BITS, COILS, IMAGE_COUNT
from eskin_industrial.outputs.plc.server import PlcRegisterHandler, identity_of
from tests.helpers.fuzz import fuzz
from tests.helpers.paths import PROFILES

PAPER = load_profile(PROFILES / "paper-5x5.toml")
IDENTITY = identity_of(PAPER.modbus.plc.identity, PAPER.name)


def handler() -> PlcRegisterHandler:
    h = PlcRegisterHandler(PAPER.modbus.plc)
    h.publish(list(range(100, 100 + len(h.registers))), True)
    return h


requests = st.one_of(
    st.binary(max_size=260),
    st.builds(lambda fc, rest: bytes((fc,)) + rest, st.sampled_from([1, 2, 3, 4, 5, 6, 15, 16, 17, 43]),
              st.binary(max_size=40)),
    st.builds(lambda fc, a, n: struct.pack(">BHH", fc, a, n), st.sampled_from([1, 2, 3, 4]),
              st.integers(0, 0xFFFF), st.integers(0, 0xFFFF)),
)


@fuzz(400)
@given(requests)
def test_any_request_gets_a_response_of_the_specifications_shape(req):
    resp = pdu.handle(req, handler(), IDENTITY)
    assert 2 <= len(resp) <= 253
    fc = req[0] if req else 0
    assert resp[0] in (fc, fc | 0x80)
    if resp[0] & 0x80:
        assert len(resp) == 2 and resp[1] in (1, 2, 3, 4)
    elif fc in (1, 2, 3, 4):
        count = struct.unpack(">H", req[3:5])[0]
        assert resp[1] == len(resp) - 2 == (2 * count if fc in (3, 4) else (count + 7) // 8)
    elif fc in (5, 6):
        assert resp == req
    elif fc in (15, 16):
        assert resp == req[:5]


@fuzz(100)
@given(st.integers(0, IMAGE_COUNT - 1), st.data())
def test_reads_of_each_table_give_the_published_values(start, data):
    h = handler()
    count = data.draw(st.integers(1, IMAGE_COUNT - start))
    for fc in (3, 4):  # FC4: the holding block, read-only
        resp = pdu.handle(struct.pack(">BHH", fc, start, count), h, IDENTITY)
        assert list(struct.unpack(f">{count}H", resp[2:])) == h._holding()[start: start + count]
    status = h.registers[0]
    resp = pdu.handle(struct.pack(">BHH", 2, 0, len(BITS)), h, IDENTITY)
    bits = int.from_bytes(resp[2:], "little")
    assert bits == status & ((1 << len(BITS)) - 1)
    resp = pdu.handle(struct.pack(">BHH", 1, 0, len(COILS)), h, IDENTITY)
    assert resp == bytes((1, 1, 0b100))  # ENABLE on, the act-on-1 coils read 0


def test_device_identification_splits_objects_too_long_for_one_response():
    long = pdu.Identity("v" * 150, "p" * 150, "r" * 150, "u" * 150)
    resp = pdu.handle(bytes((43, 14, 2, 0)), handler(), long)
    assert len(resp) <= 253 and resp[4] == 0xFF  # more follows
    n, next_id = resp[6], resp[5]
    assert n == 1 and next_id == 1
    rest = pdu.handle(bytes((43, 14, 2, next_id)), handler(), long)
    assert rest[7] == 1  # the stream goes on at the object it names
