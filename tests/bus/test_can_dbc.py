"""The DBC we write, read by cantools, decodes our frames as our decoder does."""
from __future__ import annotations

import dataclasses
import subprocess
import sys

import cantools
import numpy as np
import pytest

from eskin_industrial import load_profile
from eskin_industrial.bus.can.dbc import dbc_text
from eskin_industrial.bus.can.layout import CanLayout, NodeState, NodeStatus, decode_messages
from eskin_industrial.calibration import Calibrator
from tests.helpers.can_frames import scans_to_messages
from tests.helpers.paths import PROFILES


def variants(profile):
    for order in ("little", "big"):
        for fd in (False, True):
            for ext in (False, True):
                can = dataclasses.replace(profile.can, byte_order=order, fd=fd, extended_id=ext)
                yield pytest.param(dataclasses.replace(profile, can=can), id=f"{profile.name}-{order}-fd{int(fd)}-ext{int(ext)}")


@pytest.mark.parametrize("variant", [*variants(load_profile(PROFILES / "paper-5x5.toml")),
                                     *variants(load_profile(PROFILES / "hand-4x5.toml"))])
def test_cantools_decodes_our_frames_to_our_forces(variant):
    lay = CanLayout.from_profile(variant)
    db = cantools.database.load_string(dbc_text(variant), "dbc")
    cal = Calibrator.from_section(variant.calibration, variant.taxels)
    # forces within full scale: readings in the valid range, no flags, no clip
    raw = np.rint(cal.to_raw(np.random.default_rng(5).uniform(0.0, 7.0, (12, variant.taxels))))
    seqs = np.arange(4090, 4102)
    msgs = scans_to_messages(lay, seqs, raw)
    ours, _ = decode_messages(lay, msgs, 100.0)
    forces, flags = cal.to_newtons(np.array([s.raw for s in ours]))
    assert not flags.any()
    theirs = np.full((len(seqs), variant.taxels), np.nan)
    for k, m in enumerate(msgs):
        message = db.get_message_by_frame_id(m.arbitration_id | (0x80000000 if m.is_extended_id else 0))
        assert message.is_fd == lay.fd and message.is_extended_frame == lay.extended_id
        sig = message.decode(bytes(m.data), decode_choices=False)
        assert sig["SEQ"] == seqs[k // lay.segments] % 4096
        assert sig["SEGMENT"] == m.arbitration_id - lay.base_id
        for name, value in sig.items():
            if name.startswith("F"):
                theirs[k // lay.segments, int(name[1:])] = value
    np.testing.assert_allclose(theirs, forces, rtol=1e-9, atol=1e-9)
    status = NodeStatus(lay.node_id, NodeState.ERROR, 4, 5, 1000, 77)
    dec = db.get_message_by_name(f"{variant.name.upper().replace('-', '_')}_STATUS").decode(lay.encode_status(status))
    assert dec == {"NODE_ID": lay.node_id, "STATE": "error", "TX_ERRORS": 4, "RX_ERRORS": 5, "RATE": 1000,
                   "LAST_SEQ": 77}


def test_profile_dbc_command_writes_a_dbc_cantools_loads():
    res = subprocess.run([sys.executable, "-m", "eskin_industrial", "profile", "dbc", str(PROFILES / "hand-4x5.toml")],
                         capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr
    db = cantools.database.load_string(res.stdout, "dbc")
    assert sorted(m.frame_id for m in db.messages) == [0x280, 0x281, 0x282, 0x283, 0x284, 0x28F]
    assert db.get_message_by_frame_id(0x281).signal_tree == ["SEQ", "SEGMENT", "F04", "F05", "F06", "F07"]
