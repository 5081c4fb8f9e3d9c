"""A DBC file that describes a node's frames, so that DBC tools decode them.

Each data segment is one message whose taxel signals are scaled straight to newtons:
the calibration is linear per taxel, ``F = raw * raw_scale / per_newton -
zero / per_newton``, which is a DBC factor and offset.  (The range checks and the
saturation clip of :mod:`~eskin_industrial.calibration` are not expressible in a DBC;
readings outside ``[valid_min, valid_max]`` decode to numbers a bridge would flag.)
The heartbeat is a message too, with its node states as a value table.

Every message carries its cycle time and send type (``GenMsgCycleTime``,
``GenMsgSendType``: the scan period, the heartbeat period, "Cyclic").
:func:`plant_dbc_text` describes several nodes in one file (every CAN node of a
bridge), each message name prefixed with its node's name.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass

from ...calibration import Calibrator
from ...profile import Profile
from .layout import HEADER_BYTES, SEQ_BITS, STATUS_LENGTH, CanLayout, NodeState


def _start_bit(layout: CanLayout, first_bit: int, length: int) -> tuple[int, str]:
    """DBC start bit and byte-order code of a field that starts ``first_bit`` bits
    into the payload, in the layout's bit numbering.

    Little endian (``@1``): bit i of the payload is bit i % 8 of byte i // 8, the
    field's LSB comes first.  Big endian (``@0``): the payload is one MSB-first bit
    stream and DBC names the field by its most significant bit.
    """
    if layout.byte_order == "little":
        return first_bit, "1"
    byte, bit = divmod(first_bit, 8)
    return byte * 8 + (7 - bit), "0"


def _num(x: float) -> str:
    return repr(float(x)) if x != int(x) else str(int(x))


def _fields(layout: CanLayout, segment: int) -> list[tuple[int, int]]:
    """(first bit, length) of each taxel of a segment, in layout bit numbering."""
    return [(HEADER_BYTES * 8 + layout.bits * j, layout.bits) for j in range(layout.segment_taxels(segment))]


@dataclass(frozen=True)
class DbcNode:
    """One node of a DBC: its name (the DBC node and the prefix of its messages), its
    profile, the frame layout it sends and its scan rate."""

    name: str
    profile: Profile
    layout: CanLayout
    rate_hz: float
    prefix: str = ""  #: of its message names; default: the name in capitals

    @property
    def message_prefix(self) -> str:
        return self.prefix or self.name.upper()


def dbc_name(text: str) -> str:
    """A DBC (C) identifier from a node or profile name: ``gripper-left`` -> ``gripper_left``."""
    s = re.sub(r"[^A-Za-z0-9_]+", "_", text).strip("_")
    return s if s and not s[0].isdigit() else f"N_{s}"


#: The send types of Vector's attribute definition (index 0 "Cyclic").
_SEND_TYPES = ('"Cyclic","NotUsed","NotUsed","NotUsed","NotUsed","Cyclic","NotUsed","IfActive",'
               '"NoMsgSendType","NotUsed"')
_FRAME_FORMATS = ('"StandardCAN","ExtendedCAN","reserved","reserved","reserved","reserved","reserved",'
                  '"reserved","reserved","reserved","reserved","reserved","reserved","reserved",'
                  '"StandardCAN_FD","ExtendedCAN_FD"')


def _cycle_ms(period_s: float) -> int:
    """A period as GenMsgCycleTime's integer milliseconds (at least 1)."""
    return max(1, round(period_s * 1000.0))


@dataclass
class _Parts:
    messages: list[str]
    comments: list[str]
    attributes: list[str]
    values: list[str]
    fd: bool = False


def _node_parts(node: DbcNode) -> _Parts:
    profile, lay = node.profile, node.layout
    cal = Calibrator.from_section(profile.calibration, profile.taxels)
    factor = cal.raw_scale / cal.per_newton
    offset = -cal.zero / cal.per_newton
    ext = 0x80000000 if lay.extended_id else 0
    name, pre = node.name, node.message_prefix
    out = _Parts([], [], [], [], lay.fd)
    scan_ms = _cycle_ms(1.0 / node.rate_hz)
    lines = out.messages
    for s in range(lay.segments):
        can_id = lay.data_id(s) | ext
        msg = f"{pre}_SCAN" if lay.fd else f"{pre}_SEG{s}"
        lines.append(f"BO_ {can_id} {msg}: {lay.frame_length(s)} {name}")
        if lay.byte_order == "little":
            lines.append(f' SG_ SEQ : 0|{SEQ_BITS}@1+ (1,0) [0|{(1 << SEQ_BITS) - 1}] "" Vector__XXX')
            lines.append(f' SG_ SEGMENT : {SEQ_BITS}|4@1+ (1,0) [0|15] "" Vector__XXX')
        else:  # header is a big-endian uint16: segment in the top 4 bits, then the counter
            lines.append(f' SG_ SEGMENT : {_start_bit(lay, 0, 4)[0]}|4@0+ (1,0) [0|15] "" Vector__XXX')
            lines.append(f' SG_ SEQ : {_start_bit(lay, 4, 12)[0]}|{SEQ_BITS}@0+ (1,0) [0|{(1 << SEQ_BITS) - 1}] "" Vector__XXX')
        for j, (first, length) in enumerate(_fields(lay, s)):
            i = s * lay.per_segment + j
            start, order = _start_bit(lay, first, length)
            lo, hi = sorted((offset[i], offset[i] + factor[i] * lay.max_raw))
            lines.append(f' SG_ F{i:02d} : {start}|{length}@{order}+ ({_num(factor[i])},{_num(offset[i])}) '
                         f'[{_num(lo)}|{_num(hi)}] "N" Vector__XXX')
        lines.append("")
        first_taxel = s * lay.per_segment
        out.comments.append(f'CM_ BO_ {can_id} "taxels {first_taxel}..{first_taxel + lay.segment_taxels(s) - 1}, '
                            f'{lay.bits} bits, {profile.calibration.raw_unit} calibrated to newtons";')
        if lay.fd:
            out.attributes.append(f'BA_ "VFrameFormat" BO_ {can_id} {15 if lay.extended_id else 14};')
        out.attributes.append(f'BA_ "GenMsgCycleTime" BO_ {can_id} {scan_ms};')
        out.attributes.append(f'BA_ "GenMsgSendType" BO_ {can_id} 0;')
    status_id = lay.status_id | ext
    lines.append(f"BO_ {status_id} {pre}_STATUS: {STATUS_LENGTH} {name}")
    sgn = "1" if lay.byte_order == "little" else "0"
    for label, first, length, unit in (("NODE_ID", 0, 8, ""), ("STATE", 8, 8, ""), ("TX_ERRORS", 16, 8, ""),
                                       ("RX_ERRORS", 24, 8, ""), ("RATE", 32, 16, "Hz"), ("LAST_SEQ", 48, 16, "")):
        start, _ = _start_bit(lay, first, length)
        top = (1 << length) - 1
        lines.append(f' SG_ {label} : {start}|{length}@{sgn}+ (1,0) [0|{top}] "{unit}" Vector__XXX')
    lines.append("")
    out.comments.insert(0, f'CM_ BU_ {name} "{profile.sensor.description or profile.name}";')
    out.attributes.append(f'BA_ "GenMsgCycleTime" BO_ {status_id} {_cycle_ms(profile.can.heartbeat_s)};')
    out.attributes.append(f'BA_ "GenMsgSendType" BO_ {status_id} 0;')
    states = " ".join(f'{s.value} "{s.name.lower()}"' for s in NodeState)
    out.values.append(f"VAL_ {status_id} STATE {states} ;")
    return out


def plant_dbc_text(nodes: Sequence[DbcNode]) -> str:
    """One DBC for several nodes; :class:`ValueError` when two nodes would share a
    frame ID or a message name (one DBC describes one bus)."""
    ids: dict[tuple[int, bool], str] = {}
    names: dict[str, str] = {}
    prefixes: dict[str, str] = {}
    for n in nodes:
        for key, seen, what in ((n.name, names, "DBC node name"), (n.message_prefix, prefixes, "message prefix")):
            if key in seen:
                raise ValueError(f"nodes {seen[key]!r} and {n.name!r} get the same {what} {key!r}")
            seen[key] = n.name
        lay = n.layout
        for can_id in [lay.data_id(s) for s in range(lay.segments)] + [lay.status_id]:
            frame = (can_id, lay.extended_id)
            if frame in ids:
                raise ValueError(f"nodes {ids[frame]!r} and {n.name!r} both send ID {can_id:#x}: one DBC describes one "
                                 f"bus; give them different base_id")
            ids[frame] = n.name
    parts = [_node_parts(n) for n in nodes]
    lines = ['VERSION ""', "", "NS_ :", "", "BS_:", "", "BU_: " + " ".join(n.name for n in nodes), ""]
    for p in parts:
        lines += p.messages
    for p in parts:
        lines += p.comments
    lines.append('BA_DEF_ BO_ "GenMsgCycleTime" INT 0 65535;')
    lines.append(f'BA_DEF_ BO_ "GenMsgSendType" ENUM {_SEND_TYPES};')
    if any(p.fd for p in parts):
        lines.append(f'BA_DEF_ BO_ "VFrameFormat" ENUM {_FRAME_FORMATS};')
    lines.append('BA_DEF_DEF_ "GenMsgCycleTime" 0;')
    lines.append('BA_DEF_DEF_ "GenMsgSendType" "NoMsgSendType";')
    if any(p.fd for p in parts):
        lines.append('BA_DEF_DEF_ "VFrameFormat" "StandardCAN";')
    for p in parts:
        lines += p.attributes
    for p in parts:
        lines += p.values
    return "\n".join(lines) + "\n"


def dbc_text(profile: Profile, layout: CanLayout | None = None, node_name: str | None = None,
             rate_hz: float | None = None) -> str:
    """The DBC of one node.  Its DBC node is ``node_name`` (default ``NODE<node_id>``)
    and its messages are prefixed with ``node_name`` in capitals (default: the
    profile's name)."""
    lay = layout or CanLayout.from_profile(profile)
    if node_name is None:
        node = DbcNode(f"NODE{lay.node_id}", profile, lay, rate_hz or profile.sensor.rate_hz,
                       prefix=dbc_name(profile.name).upper())
    else:
        node = DbcNode(dbc_name(node_name), profile, lay, rate_hz or profile.sensor.rate_hz)
    return plant_dbc_text([node])
