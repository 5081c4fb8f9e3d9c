"""Fuzz tests of the Modbus sensor-node path: register words to raw taxel values, and
the poller's handling of whatever a read returns.

pymodbus' master does the RTU framing itself; what is ours is fuzzed here without a
serial line: the codec (:func:`encode_scan` / :func:`decode_scans`), the simulated
node's register file, and :class:`RtuSource` with a stand-in master that answers each
read with random words, wrong counts or faults.  The protocol's own pieces are fuzzed
beside their modules: the 32-bit word split in tests/modbus/test_modbus_words.py, the CRC
check that tells garbled frames from timeouts in tests/modbus/test_modbus_rtu_frame.py.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from eskin_industrial import load_profile
from eskin_industrial.bus.modbus.codec import decode_scans, encode_scan, register_count
from eskin_industrial.bus.modbus.rtu import RtuSource
from eskin_industrial.errors import ModbusFault
from eskin_industrial.profile import ModbusNodeSection
from eskin_industrial.sim.modbus_node import NodeRegisters
from tests.helpers.fuzz import fuzz
from tests.helpers.paths import PROFILES

PAPER = load_profile(PROFILES / "paper-5x5.toml")
HAND = load_profile(PROFILES / "hand-4x5.toml")
RANGES = {"uint16": (0, 0xFFFF), "int16": (-0x8000, 0x7FFF), "uint32": (0, 0xFFFFFFFF),
          "int32": (-0x80000000, 0x7FFFFFFF)}

nodes = st.builds(
    ModbusNodeSection,
    value_type=st.sampled_from(list(RANGES)),
    word_order=st.sampled_from(["big", "little"]),
    counter_register=st.booleans(),
    function=st.sampled_from([3, 4]),
    start_address=st.integers(0, 100),
)
words = st.integers(0, 0xFFFF)


@fuzz(200)
@given(node=nodes, taxels=st.sampled_from([PAPER.taxels, HAND.taxels]), data=st.data())
def test_any_register_words_decode_to_finite_values_of_the_type(node, taxels, data):
    regs = data.draw(st.lists(words, min_size=taxels * node.words_per_taxel, max_size=taxels * node.words_per_taxel))
    raw = decode_scans(node, regs)
    lo, hi = RANGES[node.value_type]
    assert raw.shape == (taxels,)
    assert np.all(np.isfinite(raw)) and np.all((raw >= lo) & (raw <= hi))
    # and back: the node would send exactly these words for these values
    assert encode_scan(node, raw) == regs


@fuzz(200)
@given(node=nodes, values=st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=1, max_size=30))
def test_any_values_encode_to_register_words(node, values):
    """The node side: NaN, infinities and out-of-range values become words in 0..65535
    (NaN as 0, the rest clipped to the value type), and decode to the clipped value."""
    regs = encode_scan(node, np.array(values))
    assert len(regs) == len(values) * node.words_per_taxel
    assert all(isinstance(r, int) and 0 <= r <= 0xFFFF for r in regs)
    lo, hi = RANGES[node.value_type]
    want = np.clip(np.rint(np.nan_to_num(np.array(values), nan=0.0)), lo, hi)
    np.testing.assert_array_equal(decode_scans(node, regs), want)


@fuzz(200)
@given(node=nodes, address=st.integers(-5, 200), count=st.integers(0, 130),
       table=st.sampled_from(["coils", "discrete", "holding", "input"]))
def test_the_node_register_file_answers_values_or_an_exception_code(node, address, count, table):
    n = register_count(node, HAND.taxels)
    regs = NodeRegisters(node, n, list(range(n)))
    out = regs.read(table, address, count)
    inside = node.start_address <= address and address + count <= node.start_address + n
    wanted = "input" if node.function == 4 else "holding"
    if table == wanted and inside:
        assert out == list(range(address - node.start_address, address - node.start_address + count))
    else:
        assert out in (1, 2)  # ILLEGAL FUNCTION / ILLEGAL DATA ADDRESS
    assert regs.write(table, address, [0] * count) == 2


class FakeMaster:
    """Answers each read from a script: a list of words (any length) or a fault kind."""

    def __init__(self, script: list) -> None:
        self.script = list(script)
        self.resets = 0

    def read(self, function: int, address: int, count: int) -> list[int]:
        answer = self.script.pop(0) if self.script else "timeout"
        if isinstance(answer, str):
            raise ModbusFault(answer, f"fake: {answer}", 2 if answer == "exception" else 0)
        return answer

    def reset_input(self) -> None:
        self.resets += 1

    def close(self) -> None:
        pass


@fuzz(100)
@given(data=st.data())
def test_the_poller_survives_any_answer_and_counts_every_attempt(data):
    base = data.draw(st.sampled_from([PAPER, HAND]))
    node = dataclasses.replace(data.draw(nodes), retries=data.draw(st.integers(0, 2)), fault_after_failures=2)
    profile = dataclasses.replace(base, modbus=dataclasses.replace(base.modbus, node=node))
    poller = RtuSource(profile, "/dev/null-not-opened")  # the master is replaced, never opened
    n = poller.count
    good = st.lists(words, min_size=n, max_size=n)
    if node.counter_register:
        # counters that repeat, step, jump and go back (a node restart)
        good = st.builds(lambda c, rest: [c, *rest], st.integers(0, 0xFFFF) | st.sampled_from([0, 1, 2, 0xFFFF]),
                         st.lists(words, min_size=n - 1, max_size=n - 1))
    answer = st.one_of(good, st.lists(words, max_size=n + 3),
                       st.sampled_from(["timeout", "crc", "exception", "connection"]))
    script = data.draw(st.lists(answer, max_size=25))
    polls = data.draw(st.integers(1, 12))
    poller.master = FakeMaster(script)  # type: ignore[assignment]
    scans = []
    for _ in range(polls):
        scan = poller.poll_once()
        if scan is not None:
            scans.append(scan)
            assert scan.raw.shape == (profile.taxels,) and np.all(np.isfinite(scan.raw))
            assert math.isfinite(scan.t)
        assert poller.bus_fault == (poller.consecutive_failures >= 2)
    c = poller.stats
    assert c.polls == polls == c.scans + c.repeats + c.failed_polls
    assert c.scans == len(scans)
    attempts = c.polls + c.retries
    assert c.timeouts + c.crc_errors + c.exceptions == attempts - c.scans - c.repeats
    seqs = [s.seq for s in scans]
    assert all(b > a for a, b in zip(seqs, seqs[1:])), seqs
    if node.counter_register:
        assert all(s.t == s.seq / profile.sensor.rate_hz for s in scans)
