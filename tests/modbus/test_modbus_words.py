"""A 32-bit value in two registers: the protocol package's word split, the one the
sensor node's scan codec and the PLC register image share."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from eskin_industrial.modbus.words import join32, split32
from tests.helpers.fuzz import fuzz


@fuzz(200)
@given(values=st.lists(st.integers(-2**40, 2**40) | st.integers(0, 0xFFFFFFFF), min_size=1, max_size=20),
       word_order=st.sampled_from(["big", "little"]))
def test_the_word_split_is_one_for_ints_and_arrays(values, word_order):
    """split32 / join32 are the only 32-bit word split (scan codec and PLC image): two
    words in 0..65535, in word order, the same for an int as for an array, and back."""
    arr = np.array(values, dtype=np.int64)
    pairs = np.stack(split32(arr, word_order), axis=-1)
    for v, pair in zip(values, pairs.tolist()):
        words = split32(v, word_order)
        assert words == pair and all(0 <= w <= 0xFFFF for w in words)
        hi, lo = words if word_order == "big" else words[::-1]
        assert (hi << 16) | lo == v & 0xFFFFFFFF
        assert join32(words, word_order) == v & 0xFFFFFFFF
    np.testing.assert_array_equal(join32((pairs[:, 0], pairs[:, 1]), word_order), arr & 0xFFFFFFFF)
