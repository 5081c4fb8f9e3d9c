"""The CAN frame layout and scan assembly: pure, no bus."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from eskin_industrial.bus.can.layout import SEQ_MODULO, CanLayout, NodeState, NodeStatus, ScanAssembler, decode_messages
from eskin_industrial.errors import ProfileError
from tests.helpers.can_frames import msg, scans_to_messages


def random_raw(layout, k, seed=0):
    return np.random.default_rng(seed).integers(0, layout.max_raw + 1, (k, layout.taxels))


def test_golden_bytes_12_bit_both_byte_orders():
    raw = np.array([[0x123, 0x456, 0x789, 0xABC, 0xFFF]])
    little = CanLayout(5, 12, "little", 0x280).encode([5], raw)[0]
    assert little == [(0x280, bytes.fromhex("0500 236145 89C7AB")), (0x281, bytes.fromhex("0510 FF0F"))]
    big = CanLayout(5, 12, "big", 0x280).encode([5], raw)[0]
    assert big == [(0x280, bytes.fromhex("0005 123456 789ABC")), (0x281, bytes.fromhex("1005 FFF0"))]


def test_golden_bytes_16_bit_and_fd():
    raw = np.array([[0x1234, 0xABCD, 7, 0xFFFF]])
    assert CanLayout(4, 16, "little", 0x200).encode([0xFFF], raw)[0] == [
        (0x200, bytes.fromhex("FF0F 3412 CDAB 0700")), (0x201, bytes.fromhex("FF1F FFFF"))]
    (fd,) = CanLayout(4, 16, "big", 0x200, fd=True).encode([1], raw)[0]
    assert fd == (0x200, bytes.fromhex("0001 1234 ABCD 0007 FFFF 0000"))  # padded to 12, a valid FD length


def test_frames_per_scan_of_the_profiles(paper_profile, hand_profile):
    paper = CanLayout.from_profile(paper_profile)
    assert (paper.bits, paper.segments, paper.bytes_per_scan) == (16, 9, 68)
    assert CanLayout.from_profile(paper_profile, fd=True).bytes_per_scan == 64
    hand = CanLayout.from_profile(hand_profile)
    assert (hand.bits, hand.segments, hand.frame_length(4)) == (12, 5, 8)
    # 25 taxels: 12-bit packing saves two frames of nine
    assert CanLayout(25, 12, "little", 0).segments == 7 and CanLayout(25, 16, "little", 0).segments == 9
    assert CanLayout(25, 12, "little", 0, fd=True).frame_length(0) == 48


def test_raw_values_that_do_not_fit_the_bits_are_refused(paper_profile):
    twelve = dataclasses.replace(paper_profile, can=dataclasses.replace(paper_profile.can, taxel_bits=12))
    with pytest.raises(ProfileError, match=r"\[can\] taxel_bits: 12 bits carry raw values up to 4095.*20000"):
        CanLayout.from_profile(twelve)


@settings(max_examples=60, deadline=None)
@given(taxels=st.integers(1, 30), bits=st.sampled_from([12, 16]), order=st.sampled_from(["little", "big"]),
       fd=st.booleans(), seed=st.integers(0, 2**32 - 1))
def test_every_layout_round_trips(taxels, bits, order, fd, seed):
    if fd and 2 + -(-taxels * bits // 8) > 64:
        return
    lay = CanLayout(taxels, bits, order, 0x100, fd=fd)
    raw = random_raw(lay, 20, seed)
    np.testing.assert_array_equal(lay.unpack(lay.pack(raw)), raw)
    seqs = np.arange(4090, 4110)  # through the counter's wrap
    scans, asm = decode_messages(lay, scans_to_messages(lay, seqs, raw), 100.0)
    assert [s.seq for s in scans] == list(range(4090, 4110))
    np.testing.assert_array_equal(np.array([s.raw for s in scans]), raw)
    np.testing.assert_allclose([s.t for s in scans], seqs / 100.0)
    assert asm.counters["frames"] == 20 * lay.segments and asm.counters["malformed_frames"] == 0


@pytest.fixture
def lay():
    return CanLayout(25, 12, "little", 0x200)


def test_a_missing_segment_tears_its_scan_and_the_gap_shows(lay):
    raw = random_raw(lay, 5)
    frames = scans_to_messages(lay, np.arange(5), raw)
    del frames[2 * 7 + 3]  # scan 2 loses segment 3
    scans, asm = decode_messages(lay, frames, 100.0)
    assert [s.seq for s in scans] == [0, 1, 3, 4]
    assert asm.counters["torn_scans"] == 1


def test_duplicates_are_dropped_and_counted(lay):
    raw = random_raw(lay, 3)
    frames = scans_to_messages(lay, np.arange(3), raw)
    frames.insert(3, frames[2])  # one segment twice
    frames[15:15] = frames[8:15]  # scan 1 (now frames 8..14) sent twice
    scans, asm = decode_messages(lay, frames, 100.0)
    assert [s.seq for s in scans] == [0, 1, 2]
    assert asm.counters["duplicate_frames"] == 8 and asm.counters["torn_scans"] == 0


def test_reordered_segments_within_a_scan_are_fine_across_scans_detected(lay):
    raw = random_raw(lay, 3)
    frames = scans_to_messages(lay, np.arange(3), raw)
    frames[1], frames[4] = frames[4], frames[1]  # within scan 0
    frames[13], frames[14] = frames[14], frames[13]  # scan 1's last segment after scan 2's first
    scans, asm = decode_messages(lay, frames, 100.0)
    assert [s.seq for s in scans] == [0, 2]
    np.testing.assert_array_equal(scans[0].raw, raw[0])
    assert asm.counters["torn_scans"] == 1 and asm.counters["late_frames"] == 1


@pytest.mark.parametrize("bad,expect", [
    (msg(0x200, bytes(7)), "malformed_frames"),  # one byte short
    (msg(0x200, bytes.fromhex("0010") + bytes(6)), "malformed_frames"),  # header says segment 1 on segment 0's ID
    (msg(0x209, bytes(8)), "malformed_frames"),  # in the node's range, not a segment
    (msg(0x200, None, is_remote_frame=True, dlc=8), "malformed_frames"),
    (msg(0x20F, bytes(3)), "malformed_frames"),  # short heartbeat
    (msg(0x300, bytes(8)), "foreign_frames"),
    (msg(0x200, bytes(8), ext=True), "foreign_frames"),
    (msg(0x40, bytes(8), is_error_frame=True), "error_frames"),
])
def test_malformed_and_foreign_frames_are_counted_never_raised(lay, bad, expect):
    raw = random_raw(lay, 2)
    frames = scans_to_messages(lay, np.arange(2), raw)
    frames.insert(9, bad)  # in the middle of scan 1: it must still assemble
    scans, asm = decode_messages(lay, frames, 100.0)
    assert [s.seq for s in scans] == [0, 1]
    assert asm.counters[expect] == 1
    assert sum(asm.counters[k] for k in ("malformed_frames", "foreign_frames", "error_frames")) == 1


def test_bus_off_error_frames_are_surfaced(lay):
    asm = ScanAssembler(lay, 100.0)
    asm.feed(msg(0x040, bytes(8), is_error_frame=True))  # CAN_ERR_BUSOFF
    asm.feed(msg(0x004, bytes(8), is_error_frame=True))  # controller problem only
    assert asm.counters["error_frames"] == 2 and asm.counters["bus_off"] == 1


def test_heartbeat_round_trips_and_a_wrong_node_is_counted(lay):
    asm = ScanAssembler(lay, 100.0)
    for order in ("little", "big"):
        other = dataclasses.replace(lay, byte_order=order)
        status = NodeStatus(1, NodeState.RUNNING, 3, 250, 1000, 4095)
        assert other.decode_status(other.encode_status(status)) == dataclasses.replace(status, t=other.decode_status(
            other.encode_status(status)).t)
    asm.feed(msg(0x20F, lay.encode_status(NodeStatus(1, NodeState.ERROR, 9, 8, 100, 17)), t=2.0))
    assert asm.status.state == NodeState.ERROR and asm.status.tx_errors == 9 and asm.status.rate_hz == 100
    asm.feed(msg(0x20F, lay.encode_status(NodeStatus(7, NodeState.RUNNING, 0, 0, 100, 17))))
    assert asm.counters["heartbeats"] == 2 and asm.counters["node_id_mismatch"] == 1


def test_a_long_silence_is_unwrapped_from_the_receipt_times(lay):
    raw = random_raw(lay, 2)
    seqs = np.array([10, 10 + 3 * SEQ_MODULO + 5])  # 122.9 s of silence at 100 Hz
    scans, _ = decode_messages(lay, scans_to_messages(lay, seqs, raw), 100.0)
    assert [s.seq for s in scans] == list(seqs)
    assert scans[1].t == pytest.approx(seqs[1] / 100.0)


@settings(max_examples=80, deadline=None)
@given(ops=st.lists(st.tuples(st.sampled_from(["drop", "dup", "swap", "short", "keep"]), st.integers(0, 10**6)),
                    min_size=0, max_size=40))
def test_faults_never_mix_two_scans(ops):
    """Whatever happens to the frames, a scan that comes out is exactly one scan that
    went in, seq increases strictly, and nothing raises."""
    lay = CanLayout(25, 12, "little", 0x200)
    raw = random_raw(lay, 30, seed=3)
    frames = scans_to_messages(lay, np.arange(30), raw)
    for op, where in ops:
        i = where % len(frames)
        if op == "drop":
            del frames[i]
        elif op == "dup":
            frames.insert(i, frames[i])
        elif op == "swap" and i + 1 < len(frames):
            frames[i], frames[i + 1] = frames[i + 1], frames[i]
        elif op == "short":
            frames[i] = msg(frames[i].arbitration_id, bytes(frames[i].data[:-1]))
    scans, asm = decode_messages(lay, frames, 100.0)
    seqs = [s.seq for s in scans]
    assert seqs == sorted(set(seqs))
    for s in scans:
        np.testing.assert_array_equal(s.raw, raw[s.seq])
    if not ops or all(op == "keep" for op, _ in ops):
        assert seqs == list(range(30))
