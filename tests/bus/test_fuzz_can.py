"""Fuzz tests of the CAN decoders: the scan assembler and the heartbeat decoder.

The product rule: bad input is counted and dropped, never raises, never yields a scan
that was not sent.  Every layout of the shipped profiles is fuzzed (paper-5x5: 16-bit
taxels, 9 segments; hand-4x5: 12-bit, 5 segments; both also as one CAN FD frame), in
both byte orders and with standard or extended IDs.
"""
from __future__ import annotations

import dataclasses
import math

import can
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from eskin_industrial import load_profile
from eskin_industrial.bus.can.layout import ID_RANGE, SEQ_MASK, SEQ_MODULO, STATUS_LENGTH, CanLayout, ScanAssembler
from eskin_industrial.errors import DecodeError
from tests.helpers.fuzz import fuzz
from tests.helpers.paths import PROFILES

RATE_HZ = 100.0


def _layouts() -> list[CanLayout]:
    out = []
    for name in ("paper-5x5.toml", "hand-4x5.toml"):
        profile = load_profile(PROFILES / name)
        for fd in (False, True):
            out.append(CanLayout.from_profile(profile, fd=fd))
    return out


PROFILE_LAYOUTS = _layouts()


@st.composite
def layouts(draw) -> CanLayout:
    """A shipped profile's layout, possibly in the other byte order or with 29-bit IDs."""
    lay = draw(st.sampled_from(PROFILE_LAYOUTS))
    order = draw(st.sampled_from(["little", "big"]))
    ext = draw(st.booleans())
    base = draw(st.sampled_from([lay.base_id, 0x1ABCDE0])) if ext else lay.base_id
    return dataclasses.replace(lay, byte_order=order, extended_id=ext, base_id=base)


timestamps = st.one_of(
    st.floats(-1e3, 1e6, allow_nan=False),
    st.floats(allow_nan=True, allow_infinity=True),
)


@st.composite
def garbage(draw, lay: CanLayout, t=timestamps) -> can.Message:
    """Any frame at all: IDs in and around the node's range or anywhere, either ID
    format, remote, error and FD frames, random lengths and payloads."""
    can_id = draw(st.one_of(
        st.integers(lay.base_id - 3, lay.base_id + ID_RANGE + 3).filter(lambda i: i >= 0),
        st.integers(0, 0x1FFFFFFF),
    ))
    data = draw(st.one_of(
        st.binary(max_size=64),
        # the right length for the ID (a header that may or may not match)
        st.binary(min_size=lay.frame_length(0), max_size=lay.frame_length(0)),
        st.binary(min_size=STATUS_LENGTH, max_size=STATUS_LENGTH),
    ))
    return can.Message(
        timestamp=draw(t), arbitration_id=can_id, data=data, dlc=len(data),
        is_extended_id=draw(st.booleans()), is_remote_frame=draw(st.booleans()),
        is_error_frame=draw(st.booleans()), is_fd=draw(st.booleans()), check=False,
    )


def frames_of(lay: CanLayout, seqs: list[int], raw: np.ndarray, t: list[float] | None = None) -> list[can.Message]:
    out: list[can.Message] = []
    if not seqs:
        return out
    for k, frames in enumerate(lay.encode(np.asarray(seqs), raw)):
        ts = seqs[k] / RATE_HZ if t is None else t[k]
        for can_id, data in frames:
            out.append(can.Message(timestamp=ts, arbitration_id=can_id, data=data, is_extended_id=lay.extended_id,
                                   is_fd=lay.fd))
    return out


def raw_scans(draw, lay: CanLayout, k: int) -> np.ndarray:
    """``k`` scans of raw values over the whole wire range, the extremes included."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    raw = rng.integers(0, lay.max_raw + 1, (k, lay.taxels))
    raw[rng.random((k, lay.taxels)) < 0.1] = 0
    raw[rng.random((k, lay.taxels)) < 0.1] = lay.max_raw
    return raw


def feed_all(lay: CanLayout, messages: list[can.Message]) -> tuple[list, ScanAssembler]:
    asm = ScanAssembler(lay, RATE_HZ)
    scans = [s for s in (asm.feed(m) for m in messages) if s is not None]
    asm.flush()
    return scans, asm


def check_accounting(lay: CanLayout, asm: ScanAssembler, fed: int, emitted: int) -> None:
    """Every frame fed lands in exactly one place.

    Outside the node: ``error_frames`` + ``foreign_frames`` + ``frames`` = frames fed.
    Inside (``frames``): each is malformed, a duplicate, late, a heartbeat, or a
    segment kept for a scan; kept segments are those of the emitted scans plus those
    of the torn ones (after ``flush`` nothing is under way), and a torn scan had at
    least one segment and lacked at least one.
    """
    c = asm.counters
    assert c["error_frames"] + c["foreign_frames"] + c["frames"] == fed
    assert 0 <= c["bus_off"] <= c["error_frames"]
    assert 0 <= c["node_id_mismatch"] <= c["heartbeats"]
    rejected = c["malformed_frames"] + c["duplicate_frames"] + c["late_frames"] + c["heartbeats"]
    in_torn = c["frames"] - rejected - emitted * lay.segments
    assert c["torn_scans"] <= in_torn <= c["torn_scans"] * (lay.segments - 1)
    if lay.segments == 1:
        assert c["torn_scans"] == 0


def check_scans(lay: CanLayout, scans: list) -> None:
    """Scans that come out are whole, in the wire range, strictly in order, finite."""
    for s in scans:
        assert s.raw.shape == (lay.taxels,)
        assert np.all(np.isfinite(s.raw)) and np.all((s.raw >= 0) & (s.raw <= lay.max_raw))
        assert np.array_equal(s.raw, np.rint(s.raw))
        assert math.isfinite(s.t) and s.t == pytest.approx(s.seq / RATE_HZ)
    seqs = [s.seq for s in scans]
    assert all(b > a for a, b in zip(seqs, seqs[1:])), seqs


@fuzz(80)
@given(data=st.data())
def test_arbitrary_frames_never_raise_and_every_frame_is_counted_once(data):
    lay = data.draw(layouts())
    k = data.draw(st.integers(0, 4))
    raw = raw_scans(data.draw, lay, k)
    seqs = data.draw(st.lists(st.integers(0, 3 * SEQ_MODULO), min_size=k, max_size=k))
    valid = frames_of(lay, seqs, raw, t=data.draw(st.lists(timestamps, min_size=k, max_size=k)))
    junk = data.draw(st.lists(garbage(lay), max_size=20))
    # valid segments torn, duplicated and reordered among the garbage
    messages = data.draw(st.permutations(valid + junk + data.draw(st.lists(st.sampled_from(valid), max_size=8))
                                         if valid else junk))
    scans, asm = feed_all(lay, messages)
    check_accounting(lay, asm, len(messages), len(scans))
    check_scans(lay, scans)


@st.composite
def harmless(draw, lay: CanLayout) -> can.Message:
    """Frames the assembler must drop without touching the scan under way: other
    nodes, the other ID format, error frames, remote frames, wrong lengths, IDs of
    the range that carry no segment, a header naming another segment, heartbeats."""
    kind = draw(st.sampled_from(["foreign", "format", "error", "remote", "length", "spare", "segment", "status"]))
    t = draw(timestamps)
    ext = lay.extended_id
    can_id = lay.data_id(draw(st.integers(0, lay.segments - 1)))
    data = draw(st.binary(min_size=lay.frame_length(0), max_size=lay.frame_length(0)))
    remote = error = False
    if kind == "foreign":
        top = 0x1FFFFFFF if ext else 0x7FF
        can_id = draw(st.one_of(st.integers(0, lay.base_id - 1), st.integers(lay.base_id + ID_RANGE, top)))
    elif kind == "format":
        ext = not ext
    elif kind == "error":
        error = True
    elif kind == "remote":
        remote = True
    elif kind == "length":
        want = lay.frame_length(can_id - lay.base_id)
        data = draw(st.binary(max_size=64).filter(lambda b: len(b) != want))
    elif kind == "spare":
        if lay.segments == ID_RANGE - 1:
            can_id = lay.base_id - 1  # no spare ID: another node's
        else:
            can_id = draw(st.integers(lay.base_id + lay.segments, lay.status_id - 1))
    elif kind == "segment":
        segment = can_id - lay.base_id
        wrong = draw(st.integers(0, 15).filter(lambda s: s != segment))
        header = draw(st.integers(0, SEQ_MASK)) | wrong << 12
        want = lay.frame_length(segment)
        data = header.to_bytes(2, lay.byte_order) + draw(st.binary(min_size=want - 2, max_size=want - 2))
    elif kind == "status":
        can_id, data = lay.status_id, draw(st.binary(min_size=STATUS_LENGTH, max_size=STATUS_LENGTH))
    return can.Message(timestamp=t, arbitration_id=can_id, data=data, dlc=len(data), is_extended_id=ext,
                       is_remote_frame=remote, is_error_frame=error, is_fd=lay.fd, check=False)


@fuzz(50)
@given(data=st.data())
def test_valid_scans_among_garbage_come_out_intact(data):
    lay = data.draw(layouts())
    k = data.draw(st.integers(1, 5))
    first = data.draw(st.integers(0, SEQ_MODULO - 1))
    seqs = [first + i for i in range(k)]  # through the counter's wrap when first is near 4095
    raw = raw_scans(data.draw, lay, k)
    stream: list[can.Message] = []
    sent: list[can.Message] = []
    repeats = 0
    for scan in (frames_of(lay, [q], raw[i:i + 1]) for i, q in enumerate(seqs)):
        for m in data.draw(st.permutations(scan)):  # segments of one scan in any order
            stream += data.draw(st.lists(harmless(lay), max_size=3))
            stream.append(m)
            sent.append(m)
            if data.draw(st.booleans()):
                # a repeat of any frame already sent, as a node's retransmission would
                stream.append(data.draw(st.sampled_from(sent)))
                repeats += 1
    scans, asm = feed_all(lay, stream)
    assert [s.seq for s in scans] == seqs
    np.testing.assert_array_equal(np.array([s.raw for s in scans]), raw)
    c = asm.counters
    # a repeat is a duplicate (of the scan under way or the last one) or late (older)
    assert c["torn_scans"] == 0 and c["late_frames"] + c["duplicate_frames"] == repeats
    check_accounting(lay, asm, len(stream), len(scans))


@fuzz(150)
@given(data=st.data())
def test_any_receipt_times_keep_seq_increasing_and_times_finite(data):
    """Receipt times that jump, go backwards, are NaN or infinite (a broken clock or a
    garbled log) never make the unwrapped counter repeat or go back, nor raise."""
    lay = data.draw(layouts())
    k = data.draw(st.integers(1, 10))
    seqs = data.draw(st.lists(st.integers(0, SEQ_MASK), min_size=k, max_size=k))
    raw = raw_scans(data.draw, lay, k)
    messages = frames_of(lay, seqs, raw)
    for m in messages:
        m.timestamp = data.draw(st.one_of(st.just(m.timestamp), timestamps))
    scans, asm = feed_all(lay, messages)
    check_scans(lay, scans)
    check_accounting(lay, asm, len(messages), len(scans))


@fuzz(200)
@given(lay=layouts(), payload=st.binary(max_size=16))
def test_decode_status_on_random_bytes(lay, payload):
    if len(payload) != STATUS_LENGTH:
        with pytest.raises(DecodeError, match=f"heartbeat: expected {STATUS_LENGTH} bytes, got {len(payload)}"):
            lay.decode_status(payload)
        return
    s = lay.decode_status(payload, 1.5)
    assert 0 <= s.node_id <= 255 and 0 <= s.state <= 255 and 0 <= s.tx_errors <= 255 and 0 <= s.rx_errors <= 255
    assert 0 <= s.rate_hz <= 0xFFFF and 0 <= s.seq <= SEQ_MASK and s.t == 1.5
    # everything but the 4 spare bits above the 12-bit counter survives a round trip
    again = lay.encode_status(s)
    assert again[:6] == payload[:6]
    assert int.from_bytes(again[6:], lay.byte_order) == int.from_bytes(payload[6:], lay.byte_order) & SEQ_MASK
    assert lay.decode_status(again, 1.5) == s
