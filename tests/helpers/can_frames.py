"""CAN frames built from scans, for the tests that decode them without a bus."""

from __future__ import annotations

import can


def msg(can_id, data, t=0.0, **kw):
    return can.Message(arbitration_id=can_id, data=data, timestamp=t, is_extended_id=kw.pop("ext", False), **kw)


def scans_to_messages(layout, seqs, raw, rate=100.0):
    out = []
    for seq, frames in zip(seqs, layout.encode(seqs, raw)):
        for can_id, data in frames:
            out.append(msg(can_id, data, t=seq / rate, is_fd=layout.fd, ext=layout.extended_id))
    return out
