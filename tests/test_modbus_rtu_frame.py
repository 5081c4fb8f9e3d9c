"""Modbus RTU framing, pure: our CRC against pymodbus' (a framer we did not write),
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

