"""Modbus RTU framing, pure: our CRC against pymodbus' (a framer we did not write),
the frame check that the RTU master uses to tell a garbled answer from a timeout,
and where a request ends, for any bytes."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st
from pymodbus.framer.rtu import FramerRTU

from eskin_industrial.modbus import rtu_frame
from tests.helpers.fuzz import fuzz


def framed_by_pymodbus(body: bytes) -> bytes:
    return body + FramerRTU.compute_CRC(body).to_bytes(2, "big")


@fuzz(300)
@given(st.binary(min_size=2, max_size=254))
def test_our_crc_is_pymodbus_crc(body):
    assert rtu_frame.frame(body[0], body[1:]) == framed_by_pymodbus(body)
    assert rtu_frame.intact(framed_by_pymodbus(body))


@fuzz(300)
@given(st.binary(max_size=300))
def test_request_length_takes_any_bytes(data):
    n = rtu_frame.request_length(data)
    assert n is None or 0 <= n <= rtu_frame.MAX_FRAME


@fuzz(200)
@given(body=st.binary(min_size=2, max_size=40), flip=st.integers(0, 10**6))
def test_the_rtu_frame_check_accepts_intact_frames_and_no_single_bit_error(body, flip):
    frame = framed_by_pymodbus(body)
    assert rtu_frame.intact(frame)
    bit = flip % (8 * len(frame))
    garbled = bytearray(frame)
    garbled[bit // 8] ^= 1 << (bit % 8)
    assert not rtu_frame.intact(bytes(garbled))  # CRC-16 catches every single-bit error


@fuzz(300)
@given(data=st.binary(max_size=300))
def test_the_rtu_frame_check_takes_any_bytes(data):
    assert rtu_frame.intact(data) in (True, False)
    if len(data) < 4:
        assert rtu_frame.intact(data) is False
