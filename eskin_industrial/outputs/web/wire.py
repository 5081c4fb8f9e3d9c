"""The node pages' WebSocket message: one binary message a display frame, whatever it
carries (console.js decodes it with a DataView)::

    u32 LE    n: the length of the JSON part, padded with spaces to a multiple of 4
    n bytes   UTF-8 JSON: the snapshots, the lane, the episodes, the trend, the register
              block, and the frame's ``{"node", "t", "n"}`` without its forces
    4*n f32   LE: the frame's forces (N), when the JSON names a frame; NaN for a taxel
              without a value

Why binary: the heat map is most of a message, and 256 taxels as float32 are 1 kB
copied from the array once a frame for every viewer, where a JSON list is 256 floats
formatted for each viewer (docs/web.md, "Its cost").
"""

from __future__ import annotations

import json
import struct
from typing import Any

import numpy as np

_HEAD = struct.Struct("<I")


def frame_bytes(forces: np.ndarray) -> bytes:
    """The frame's forces as the message's tail (encoded once a frame, for every viewer)."""
    return np.ascontiguousarray(forces, dtype="<f4").tobytes()


def encode(text: str, tail: bytes = b"") -> bytes:
    """One message: the JSON ``text`` (already encoded by the caller) and the frame's tail."""
    body = text.encode("utf-8")
    body += b" " * (-len(body) % 4)  # the tail starts aligned: a Float32Array over the buffer
    return b"".join((_HEAD.pack(len(body)), body, tail))


def decode(data: bytes) -> dict[str, Any]:
    """The message as the page reads it: the JSON, the frame's forces in ``frame.forces``
    (a NaN as None).  For the tests and the benchmarks' viewers."""
    (n,) = _HEAD.unpack_from(data)
    out: dict[str, Any] = json.loads(data[4:4 + n])
    frame = out.get("frame")
    if frame is not None:
        forces = np.frombuffer(data, dtype="<f4", count=int(frame["n"]), offset=4 + n)
        frame["forces"] = [None if x != x else float(x) for x in forces.tolist()]
    return out
