"""A DBC file that describes a node's frames, so that DBC tools decode them.

Each data segment is one message whose taxel signals are scaled straight to newtons:
the calibration is linear per taxel, ``F = raw * raw_scale / per_newton -
zero / per_newton``, which is a DBC factor and offset.  (The range checks and the
saturation clip of :mod:`~eskin_industrial.calibration` are not expressible in a DBC;
readings outside ``[valid_min, valid_max]`` decode to numbers a bridge would flag.)
The heartbeat is a message too, with its node states as a value table.
"""

from __future__ import annotations

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


def dbc_text(profile: Profile, layout: CanLayout | None = None) -> str:
    lay = layout or CanLayout.from_profile(profile)
    cal = Calibrator.from_section(profile.calibration, profile.taxels)
    factor = cal.raw_scale / cal.per_newton
    offset = -cal.zero / cal.per_newton
    node = f"NODE{lay.node_id}"
    ext = 0x80000000 if lay.extended_id else 0
    lines = ['VERSION ""', "", "NS_ :", "", "BS_:", "", f"BU_: {node}", ""]
    attrs = []
    name = profile.name.upper().replace("-", "_")
    for s in range(lay.segments):
        can_id = lay.data_id(s) | ext
        msg = f"{name}_SCAN" if lay.fd else f"{name}_SEG{s}"
        lines.append(f"BO_ {can_id} {msg}: {lay.frame_length(s)} {node}")
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
        if lay.fd:
            attrs.append(f'BA_ "VFrameFormat" BO_ {can_id} {15 if lay.extended_id else 14};')
    status_id = lay.status_id | ext
    lines.append(f"BO_ {status_id} {name}_STATUS: {STATUS_LENGTH} {node}")
    sgn = "1" if lay.byte_order == "little" else "0"
    for label, first, length, unit in (("NODE_ID", 0, 8, ""), ("STATE", 8, 8, ""), ("TX_ERRORS", 16, 8, ""),
                                       ("RX_ERRORS", 24, 8, ""), ("RATE", 32, 16, "Hz"), ("LAST_SEQ", 48, 16, "")):
        start, _ = _start_bit(lay, first, length)
        top = (1 << length) - 1
        lines.append(f' SG_ {label} : {start}|{length}@{sgn}+ (1,0) [0|{top}] "{unit}" Vector__XXX')
    lines.append("")
    lines.append(f'CM_ BU_ {node} "{profile.sensor.description or profile.name}";')
    for s in range(lay.segments):
        first = s * lay.per_segment
        lines.append(f'CM_ BO_ {lay.data_id(s) | ext} "taxels {first}..{first + lay.segment_taxels(s) - 1}, '
                     f'{lay.bits} bits, {profile.calibration.raw_unit} calibrated to newtons";')
    if lay.fd:
        lines.append('BA_DEF_ BO_ "VFrameFormat" ENUM "StandardCAN","ExtendedCAN","reserved","reserved",'
                     '"reserved","reserved","reserved","reserved","reserved","reserved","reserved",'
                     '"reserved","reserved","reserved","StandardCAN_FD","ExtendedCAN_FD";')
        lines.append('BA_DEF_DEF_ "VFrameFormat" "StandardCAN";')
        lines += attrs
    states = " ".join(f'{s.value} "{s.name.lower()}"' for s in NodeState)
    lines.append(f"VAL_ {status_id} STATE {states} ;")
    return "\n".join(lines) + "\n"
