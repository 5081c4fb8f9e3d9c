"""The PLC's view of the bridge: one register image, the same in client and server mode.

Pure code, no I/O and no clock: :class:`PlcImage` takes detector updates, health
(age of the newest frame, bus fault, counters) and the PLC's commands, and renders
the holding registers and the status bits.  Transports (``plc_client``,
``plc_server``) only move the rendered values.  The table in ``docs/plc.md`` is
generated from :data:`REGISTERS`, :data:`COILS` and :data:`BITS` (``eskin-bus plc map``).

:data:`REGISTERS` is the one description of the image: a publication is a dict of
named values (:meth:`PlcImage.values`), laid out into words by the table
(:func:`encode_registers`) and read back by :func:`decode_registers`, its inverse.

R_COE and R_DW are the paper's indicators whatever method decides; the deciding
method's own scores are SCORE_A and SCORE_B, appended after the PLC's command
registers (so that no address of an older image moved), and METHOD_ID says which method
that is.  The published registers are thus two runs of the block: STATUS..METHOD_ID
(``STATUS_COUNT`` words from the base) and SCORE_A..SCORE_B (``TAIL_COUNT`` words from
``TAIL_AT``); COMMAND and ENABLE lie between them.
"""

from __future__ import annotations

import dataclasses
import enum
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Literal

from ...detect.methods import METHODS
from ...detect.state import GraspState
from ...errors import Refused
from ...methods import get_method
from ...modbus.exception_codes import ILLEGAL_ADDRESS, ILLEGAL_VALUE
from ...modbus.words import WordOrder, join32, split32
from ...node import Command, NodeSnapshot
from ...profile import ModbusPlcSection


class Status(enum.IntFlag):
    """Bits of the STATUS register; the same numbers as the discrete inputs."""

    CONTACT = 1 << 0
    STABLE = 1 << 1
    VARIABLE_FORCE = 1 << 2
    SLIP = 1 << 3
    SLIP_LATCHED = 1 << 4
    DATA_VALID = 1 << 5
    SENSOR_STALE = 1 << 6
    BUS_FAULT = 1 << 7
    BRIDGE_ALIVE = 1 << 8
    ENABLED = 1 << 9
    BRIDGE_OFFLINE = 1 << 10


_SENSOR_STALE, _BUS_FAULT, _ENABLED = int(Status.SENSOR_STALE), int(Status.BUS_FAULT), int(Status.ENABLED)
_BRIDGE_ALIVE, _SLIP_LATCHED, _DATA_VALID = int(Status.BRIDGE_ALIVE), int(Status.SLIP_LATCHED), int(Status.DATA_VALID)
_BRIDGE_OFFLINE = int(Status.BRIDGE_OFFLINE)

#: The STATUS bits of each state code (CONTACT with every state but no contact).
_STATE_BITS: dict[int, int] = {
    int(GraspState.STABLE): int(Status.CONTACT | Status.STABLE),
    int(GraspState.VARIABLE_FORCE): int(Status.CONTACT | Status.VARIABLE_FORCE),
    int(GraspState.SLIP): int(Status.CONTACT | Status.SLIP),
}

BIT_DOC: dict[Status, str] = {
    Status.CONTACT: "total force at or above the contact threshold",
    Status.STABLE: "state code 1: stable grasp",
    Status.VARIABLE_FORCE: "state code 2: force varying, no slip",
    Status.SLIP: "state code 3: slip now",
    Status.SLIP_LATCHED: "a slip was seen since the last acknowledge (stays set while slip lasts)",
    Status.DATA_VALID: "the state is a verdict: indicators valid, sensor fresh and free of a sensor fault "
                       "(FLAGS bits 10-12), no bus fault, enabled",
    Status.SENSOR_STALE: "no scan from the sensor for longer than the stale limit: stale_s (default 2.5 scan "
                         "periods, at least 20 ms), learnt up to stale_max_s (4 x stale_s) from the sensor's arrivals",
    Status.BUS_FAULT: "the sensor bus fails: consecutive polls failed (RTU); reads fail, or bus-off or a run of "
                      "error frames with nothing of the node since (CAN)",
    Status.BRIDGE_ALIVE: "toggles at every publication (life bit; HEARTBEAT counts the same)",
    Status.ENABLED: "detection enabled by the PLC (ENABLE register)",
    Status.BRIDGE_OFFLINE: "the bridge has shut down, or this node's source ended (last image it wrote; the "
                           "heartbeat stops); no state is claimed",
}

Kind = Literal["bits", "u16", "i16", "u32"]

#: METHOD_ID's values, for the register table.
METHOD_CODES = ", ".join(f"{m.code} {m.name}" for m in sorted(METHODS.values(), key=lambda m: m.code)) + \
    "; 0 no method (a bridge that has stopped)"


@dataclass(frozen=True)
class Register:
    name: str
    offset: int  #: from the base address
    kind: Kind
    unit: str
    doc: str
    access: Literal["R", "RW"] = "R"

    @property
    def words(self) -> int:
        return 2 if self.kind == "u32" else 1


REGISTERS: tuple[Register, ...] = (
    Register("STATUS", 0, "bits", "-", "status bits, see the bit table"),
    Register("STATE", 1, "u16", "code", "0 no_contact, 1 stable, 2 variable_force, 3 slip"),
    Register("R_COE", 2, "u16", "x r_scale",
             "the paper's decorrelation indicator R_coe x r_scale, saturated at 65535, whatever METHOD_ID decides"),
    Register("R_DW", 3, "u16", "x r_scale",
             "the paper's wavelet indicator R_dw x r_scale, saturated at 65535, whatever METHOD_ID decides"),
    Register("F_SUM", 4, "u32", "mN", "total force of the newest frame"),
    Register("XC", 6, "i16", "0.01 mm", "centre of force, x (held while out of contact)"),
    Register("YC", 7, "i16", "0.01 mm", "centre of force, y"),
    Register("HEARTBEAT", 8, "u16", "count", "+1 at every publication, wraps at 65535"),
    Register("FRAME_AGE", 9, "u16", "ms", "age of the newest frame at publication, 65535 = none or older"),
    Register("SLIP_EVENTS", 10, "u32", "count", "entries into slip since start"),
    Register("STATE_CHANGES", 12, "u32", "count", "changes of STATE since start (not of validity; the first state is none)"),
    Register("LOST_SCANS", 14, "u32", "count", "scans lost: failed polls and sequence gaps"),
    Register("BUS_ERRORS", 16, "u32", "count",
             "RTU: timeouts + CRC/framing errors + exception responses; CAN: failed reads + error frames"),
    Register("FLAGS", 18, "u16", "bits",
             "frame/update flags of the newest update (FrameFlag, low 16 bits), see the FLAGS bit table"),
    Register("METHOD_ID", 19, "u16", "code", "the deciding method: " + METHOD_CODES),
    Register("COMMAND", 20, "bits", "-", "write: bit 0 acknowledge slip latch, bit 1 tare; reads 0 once done",
             "RW"),
    Register("ENABLE", 21, "u16", "0/1", "write 1 to enable detection, 0 to disable; reads the current value",
             "RW"),
    Register("SCORE_A", 22, "u16", "x r_scale",
             "the deciding method's first score x r_scale, saturated at 65535 (`eskin-bus plc map` names it)"),
    Register("SCORE_B", 23, "u16", "x r_scale", "the deciding method's second score x r_scale, likewise"),
)
REG = {r.name: r for r in REGISTERS}
#: The registers the bridge publishes: the read-only ones (the PLC writes the rest).
PUBLISHED: tuple[Register, ...] = tuple(r for r in REGISTERS if r.access == "R")
_FIRST_RW = min(r.offset for r in REGISTERS if r.access == "RW")
_LAST_RW = max(r.offset + r.words for r in REGISTERS if r.access == "RW")
#: The first run of published registers, from the base: STATUS..METHOD_ID (client mode
#: writes these in one request).
MAIN: tuple[Register, ...] = tuple(r for r in PUBLISHED if r.offset < _FIRST_RW)
STATUS_COUNT = max(r.offset + r.words for r in MAIN)
#: The second run, after the command registers: the method's scores (client mode
#: writes them in a request of their own, at each refresh: see ``outputs/plc/client.py``).
TAIL: tuple[Register, ...] = tuple(r for r in PUBLISHED if r.offset >= _LAST_RW)
TAIL_AT = min(r.offset for r in TAIL)
TAIL_COUNT = max(r.offset + r.words for r in TAIL) - TAIL_AT
#: All registers, including the command registers.
IMAGE_COUNT = max(r.offset + r.words for r in REGISTERS)

CMD_ACK = 1 << 0
CMD_TARE = 1 << 1
#: Client mode: what the bridge writes back into a COMMAND it refused (unknown bits),
#: instead of 0 (done); the PLC's handshake waits for 0 or this.
CMD_REFUSED = 1 << 15

@dataclass(frozen=True)
class Coil:
    name: str
    offset: int  #: from the base address
    on: Literal["ack", "tare", "enable"]  #: the command a write of 1 gives
    off: Literal["disable"] | None  #: the command a write of 0 gives (None: nothing)
    doc: str


#: Coils: ACK_SLIP and TARE act on a write of 1 and read 0; ENABLE reads its state.
COILS: tuple[Coil, ...] = (
    Coil("ACK_SLIP", 0, "ack", None, "write 1: acknowledge the slip latch (reads 0)"),
    Coil("TARE", 1, "tare", None, "write 1: tare with the sensor unloaded (reads 0)"),
    Coil("ENABLE", 2, "enable", "disable", "1 enabled, 0 disabled (reads the current value)"),
)
COIL = {c.name: c for c in COILS}
_COIL_AT = {c.offset: c for c in COILS}
#: Coils from the base address (no gaps: the server sizes the table with ``len(COILS)``).
COIL_COUNT = max(c.offset for c in COILS) + 1
#: Discrete inputs: bit i = Status bit i.
BITS: tuple[Status, ...] = tuple(Status)



# -- the kinds: a named value (what the PLC reads) <-> its words -------------------
#
# A named value is an int in its kind's range: "bits" and "u16" 0..65535, "i16"
# -32768..32767, "u32" 0..2**32-1.  The saturating conversions bring a physical value
# into that range; encode_registers / decode_registers turn named values into words
# and back, exactly.

#: The range of a named value of each kind.
KIND_RANGE: dict[Kind, tuple[int, int]] = {
    "bits": (0, 0xFFFF), "u16": (0, 0xFFFF), "i16": (-0x8000, 0x7FFF), "u32": (0, 0xFFFFFFFF)}


def saturate_u16(v: float) -> int:
    """Rounded and saturated; not finite reads 65535, the "saturated / none" value
    (a NaN indicator must not read as a quiet 0)."""
    if not math.isfinite(v):
        return 0xFFFF
    return int(min(max(round(v), 0), 0xFFFF))


def saturate_i16(v: float) -> int:
    """Rounded and clipped to -32768..32767; not finite reads 0."""
    return int(min(max(round(v), -0x8000), 0x7FFF)) if math.isfinite(v) else 0


def saturate_u32(v: float) -> int:
    """Clipped, then rounded (``round(inf)`` raises: an overflow saturates instead); NaN reads 0."""
    return 0 if math.isnan(v) else round(min(max(v, 0.0), 0xFFFFFFFF))


def _signed16(word: int) -> int:
    return word - 0x10000 if word >= 0x8000 else word


@dataclass(frozen=True)
class Layout:
    """Where each named value of a register table goes, for one word order, worked
    out once: :meth:`PlcImage.render` runs at every publication (up to 1 kHz)."""

    size: int  #: registers from the base address
    one_word: tuple[tuple[str, int], ...]  #: (name, offset) of the u16, i16 and bits values
    two_words: tuple[tuple[str, int], ...]  #: (name, offset) of the u32 values
    word_order: WordOrder

    @classmethod
    def of(cls, registers: Sequence[Register], word_order: WordOrder) -> Layout:
        return cls(size=max(r.offset + r.words for r in registers),
                   one_word=tuple((r.name, r.offset) for r in registers if r.words == 1),
                   two_words=tuple((r.name, r.offset) for r in registers if r.words == 2),
                   word_order=word_order)

    def encode(self, values: Mapping[str, int]) -> list[int]:
        """The words for named values (each in its kind's range; a missing name raises)."""
        regs = [0] * self.size  # a gap in the table reads 0
        for name, at in self.one_word:
            # u16 and bits as they are, i16 as two's complement: one mask serves all three
            regs[at] = values[name] & 0xFFFF
        wo = self.word_order
        for name, at in self.two_words:
            regs[at: at + 2] = split32(values[name], wo)
        return regs


_LAYOUTS: dict[WordOrder, Layout] = {wo: Layout.of(MAIN, wo) for wo in ("big", "little")}
#: The tail's layout, from TAIL_AT (one-word values only: no word order).
_TAIL = Layout.of([dataclasses.replace(r, offset=r.offset - TAIL_AT) for r in TAIL], "big")


def encode_registers(values: Mapping[str, int], word_order: WordOrder) -> list[int]:
    """The ``STATUS_COUNT`` registers of the first published run for named values (the
    inverse of :func:`decode_registers`)."""
    return _LAYOUTS[word_order].encode(values)


def encode_tail(values: Mapping[str, int]) -> list[int]:
    """The ``TAIL_COUNT`` registers of the second published run (from ``TAIL_AT``)."""
    return _TAIL.encode(values)


def decode_tail(tail: Sequence[int]) -> dict[str, int]:
    """Named values of the second published run (``TAIL_COUNT`` words from
    ``TAIL_AT``, :attr:`PlcImage.tail`); none for an empty one."""
    return {r.name: tail[r.offset - TAIL_AT] for r in TAIL} if len(tail) >= TAIL_COUNT else {}


def decode_registers(registers: Sequence[int], word_order: WordOrder) -> dict[str, int]:
    """Named values of registers read from the base address (the inverse of
    :meth:`PlcImage.render`): 32-bit values joined in ``word_order``, i16 values
    signed; registers past the end of ``registers`` are left out."""
    out: dict[str, int] = {}
    for r in REGISTERS:
        words = list(registers[r.offset: r.offset + r.words])
        if len(words) < r.words:
            continue  # e.g. COMMAND and ENABLE are not part of a publication
        if r.kind == "u32":
            out[r.name] = join32(words, word_order)
        elif r.kind == "i16":
            out[r.name] = _signed16(words[0])
        else:
            out[r.name] = words[0]
    return out


@dataclass
class PlcImage:
    """The PLC's register image of a node, rendered from its snapshots: the heartbeat
    and the rendered scores are the image's own; everything else comes from the
    :class:`~eskin_industrial.node.NodeSnapshot`."""

    settings: ModbusPlcSection
    heartbeat: int = 0
    #: The second published run of the newest :meth:`render` (SCORE_A, SCORE_B).
    tail: list[int] = dataclasses.field(default_factory=lambda: [0] * TAIL_COUNT)

    def status(self, s: NodeSnapshot) -> int:
        """STATUS for a snapshot, with the heartbeat as it stands."""
        if s.offline:
            return _BRIDGE_OFFLINE
        # plain ints: IntFlag arithmetic costs microseconds a bit, at every publication
        bits = 0
        if s.stale:
            bits |= _SENSOR_STALE
        if s.bus_fault:
            bits |= _BUS_FAULT
        if s.enabled:
            bits |= _ENABLED
        if self.heartbeat & 1:
            bits |= _BRIDGE_ALIVE
        if s.slip_latched:
            bits |= _SLIP_LATCHED
        if s.state is not None:
            bits |= _STATE_BITS.get(s.state, 0)
            if s.valid:
                bits |= _DATA_VALID
        return bits

    def values(self, s: NodeSnapshot) -> dict[str, int]:
        """The named values of the published registers, as the PLC reads them
        (:func:`decode_registers` of :meth:`render`), for the heartbeat as it stands.
        Disabled or stale, no state is claimed: STATE, R_COE, R_DW and the scores read
        0, with DATA_VALID clear.  Offline (the bridge's last image): BRIDGE_OFFLINE
        alone in STATUS, no state, force or flags, FRAME_AGE 65535; the heartbeat,
        counters and centre of force are kept."""
        r = self.settings.r_scale
        claimed = s.state is not None
        f, x, y, age = s.f_sum_n, s.xc_mm, s.yc_mm, s.frame_age_s
        return {
            "STATUS": self.status(s),
            "STATE": s.state if claimed else 0,  # type: ignore[dict-item]  # (claimed: an int)
            "R_COE": saturate_u16(s.r_coe * r) if s.r_coe is not None else 0,
            "R_DW": saturate_u16(s.r_dw * r) if s.r_dw is not None else 0,
            # a non-finite total reads 0; a finite one that overflows once in mN saturates
            "F_SUM": saturate_u32(f * 1000.0) if f is not None and math.isfinite(f) else 0,
            "XC": saturate_i16(x * 100.0) if x is not None else 0,
            "YC": saturate_i16(y * 100.0) if y is not None else 0,
            "HEARTBEAT": self.heartbeat,
            "FRAME_AGE": 0xFFFF if age is None else saturate_u16(age * 1000.0),
            # counters wrap, like the heartbeat: a PLC takes differences
            "SLIP_EVENTS": s.slip_events & 0xFFFFFFFF,
            "STATE_CHANGES": s.state_changes & 0xFFFFFFFF,
            "LOST_SCANS": s.lost_scans & 0xFFFFFFFF,
            "BUS_ERRORS": s.bus_errors & 0xFFFFFFFF,
            "FLAGS": s.flags & 0xFFFF,
            "METHOD_ID": s.method_code,
            "SCORE_A": saturate_u16(s.score_a * r) if s.score_a is not None else 0,
            "SCORE_B": saturate_u16(s.score_b * r) if s.score_b is not None else 0,
        }

    def render(self, s: NodeSnapshot) -> list[int]:
        """The STATUS..METHOD_ID registers (``STATUS_COUNT`` values), and the scores in
        :attr:`tail`; one publication: the heartbeat advances.  A client-mode PLC keeps
        what was written last, so the offline snapshot renders what it must read then,
        never the last "stable".

        The words of :meth:`values` encoded (``tests/outputs/plc/test_plc_image.py`` holds them
        equal), written straight into the list: this runs on the urgent path, between
        the deciding scan and the PLC's write, where building the named values and
        encoding them took three times as long."""
        self.heartbeat = hb = (self.heartbeat + 1) & 0xFFFF
        r = self.settings.r_scale
        isfinite = math.isfinite
        regs = [0] * STATUS_COUNT
        regs[_AT_STATUS] = self.status(s) & 0xFFFF
        state = s.state
        if state is not None:
            regs[_AT_STATE] = state & 0xFFFF
        v = s.r_coe
        if v is not None:
            v *= r
            regs[_AT_R_COE] = int(min(max(round(v), 0), 0xFFFF)) if isfinite(v) else 0xFFFF
        v = s.r_dw
        if v is not None:
            v *= r
            regs[_AT_R_DW] = int(min(max(round(v), 0), 0xFFFF)) if isfinite(v) else 0xFFFF
        v = s.f_sum_n
        big = self.settings.word_order == "big"
        if v is not None and isfinite(v):
            _put32(regs, _AT_F_SUM, saturate_u32(v * 1000.0), big)
        v = s.xc_mm
        if v is not None:
            v *= 100.0
            regs[_AT_XC] = int(min(max(round(v), -0x8000), 0x7FFF)) & 0xFFFF if isfinite(v) else 0
        v = s.yc_mm
        if v is not None:
            v *= 100.0
            regs[_AT_YC] = int(min(max(round(v), -0x8000), 0x7FFF)) & 0xFFFF if isfinite(v) else 0
        regs[_AT_HEARTBEAT] = hb
        v = s.frame_age_s
        if v is None:
            regs[_AT_FRAME_AGE] = 0xFFFF
        else:
            v *= 1000.0
            regs[_AT_FRAME_AGE] = int(min(max(round(v), 0), 0xFFFF)) if isfinite(v) else 0xFFFF
        _put32(regs, _AT_SLIP_EVENTS, s.slip_events, big)
        _put32(regs, _AT_STATE_CHANGES, s.state_changes, big)
        _put32(regs, _AT_LOST_SCANS, s.lost_scans, big)
        _put32(regs, _AT_BUS_ERRORS, s.bus_errors, big)
        regs[_AT_FLAGS] = s.flags & 0xFFFF
        regs[_AT_METHOD_ID] = s.method_code & 0xFFFF
        self.tail = [saturate_u16(s.score_a * r) if s.score_a is not None else 0,
                     saturate_u16(s.score_b * r) if s.score_b is not None else 0]
        return regs


def _put32(regs: list[int], at: int, value: int, big: bool) -> None:
    """A u32 named value's two words at ``at`` (:func:`split32`, inlined)."""
    value &= 0xFFFFFFFF
    if big:
        regs[at], regs[at + 1] = value >> 16, value & 0xFFFF
    else:
        regs[at], regs[at + 1] = value & 0xFFFF, value >> 16


# The offsets :meth:`PlcImage.render` writes, from the register table; a register added
# to the published runs, or one whose kind changes, must be rendered there too.
_AT_STATUS, _AT_STATE, _AT_R_COE, _AT_R_DW, _AT_F_SUM, _AT_XC, _AT_YC, _AT_HEARTBEAT, _AT_FRAME_AGE, \
    _AT_SLIP_EVENTS, _AT_STATE_CHANGES, _AT_LOST_SCANS, _AT_BUS_ERRORS, _AT_FLAGS, _AT_METHOD_ID = (
        REG[n].offset for n in ("STATUS", "STATE", "R_COE", "R_DW", "F_SUM", "XC", "YC", "HEARTBEAT", "FRAME_AGE",
                                "SLIP_EVENTS", "STATE_CHANGES", "LOST_SCANS", "BUS_ERRORS", "FLAGS", "METHOD_ID"))
assert [(r.name, r.kind) for r in MAIN] == [
    ("STATUS", "bits"), ("STATE", "u16"), ("R_COE", "u16"), ("R_DW", "u16"), ("F_SUM", "u32"), ("XC", "i16"),
    ("YC", "i16"), ("HEARTBEAT", "u16"), ("FRAME_AGE", "u16"), ("SLIP_EVENTS", "u32"), ("STATE_CHANGES", "u32"),
    ("LOST_SCANS", "u32"), ("BUS_ERRORS", "u32"), ("FLAGS", "u16"), ("METHOD_ID", "u16")], \
    "outputs/plc/image.py: the published registers changed: PlcImage.render writes each one by hand"
assert [(r.name, r.offset - TAIL_AT) for r in TAIL] == [("SCORE_A", 0), ("SCORE_B", 1)], \
    "outputs/plc/image.py: the published tail changed: PlcImage.render writes each one by hand"


def coil_values(enabled: bool) -> list[bool]:
    """What the coils read: ENABLE its state, the act-on-1 coils 0."""
    values = [False] * COIL_COUNT
    values[COIL["ENABLE"].offset] = enabled
    return values


# -- PLC writes: pure checks, shared by server mode (writes) and client mode (reads) ---

def parse_register_write(offset: int, values: list[int]) -> list[Command]:
    """Commands for a write of holding registers starting at ``offset`` (from the
    base); :class:`Refused` for anything outside COMMAND/ENABLE or a bad value."""
    cmd_at, en_at = REG["COMMAND"].offset, REG["ENABLE"].offset
    out: list[Command] = []
    for i, v in enumerate(values):
        at = offset + i
        if at == cmd_at:
            if v & ~(CMD_ACK | CMD_TARE):
                raise Refused(ILLEGAL_VALUE, f"COMMAND: unknown bits {v:#06x}")
            if v & CMD_ACK:
                out.append(Command("ack"))
            if v & CMD_TARE:
                out.append(Command("tare"))
        elif at == en_at:
            if v not in (0, 1):
                raise Refused(ILLEGAL_VALUE, f"ENABLE: expected 0 or 1, got {v}")
            out.append(Command("enable" if v else "disable"))
        else:
            raise Refused(ILLEGAL_ADDRESS, f"register offset {at} is read-only or does not exist")
    return out


def parse_coil_write(offset: int, values: list[bool]) -> list[Command]:
    """Commands for a write of coils starting at ``offset`` (from the base);
    :class:`Refused` for a coil that does not exist."""
    out: list[Command] = []
    for i, v in enumerate(values):
        coil = _COIL_AT.get(offset + i)
        if coil is None:
            raise Refused(ILLEGAL_ADDRESS, f"coil offset {offset + i} does not exist")
        name = coil.on if v else coil.off
        if name is not None:
            out.append(Command(name))
    return out


def bits_of(status: int) -> list[bool]:
    """The discrete inputs for a STATUS value."""
    return [bool(status & b) for b in BITS]


# -- the documented table ---------------------------------------------------------

def register_docs(method: str | None) -> dict[str, str]:
    """The descriptions of METHOD_ID, SCORE_A and SCORE_B when ``method`` decides: its
    code and what its two scores are (the table's generic words with None)."""
    if method is None:
        return {}
    m = get_method(method)
    a, b = m.scores
    return {"METHOD_ID": f"the deciding method: {m.code} = {m.name} here ({METHOD_CODES})",
            "SCORE_A": f"{m.name}'s {a.name} x r_scale, saturated at 65535: {a.doc}",
            "SCORE_B": f"{m.name}'s {b.name} x r_scale, saturated at 65535: {b.doc}"}


def map_rows(settings: ModbusPlcSection, method: str | None = None) -> list[dict[str, str]]:
    """One row per register, coil and discrete input, with both numberings; with
    ``method``, what METHOD_ID reads and what SCORE_A and SCORE_B hold when it decides."""
    base = settings.base_address
    docs = register_docs(method)
    rows = []
    for r in REGISTERS:
        addr = base + r.offset
        span = f"{addr}" if r.words == 1 else f"{addr}-{addr + 1}"
        ref = _ref(4, addr) if r.words == 1 else f"{_ref(4, addr)}-{_ref(4, addr + 1)}"
        kind = r.kind if r.kind != "u32" else f"u32 ({settings.word_order} word order)"
        doc = docs.get(r.name, r.doc).replace("x r_scale", f"x {settings.r_scale:g}")
        unit = r.unit.replace("x r_scale", f"x {settings.r_scale:g}")
        rows.append({"table": "holding register", "name": r.name, "address": span, "ref": ref, "type": kind,
                     "unit": unit, "access": r.access, "description": doc})
    for c in COILS:
        addr = base + c.offset
        rows.append({"table": "coil", "name": c.name, "address": str(addr), "ref": _ref(0, addr),
                     "type": "bit", "unit": "-", "access": "RW", "description": c.doc})
    for i, bit in enumerate(BITS):
        addr = base + i
        # A single-bit flag member always has a name; the stubs allow None for combinations.
        rows.append({"table": "discrete input", "name": bit.name, "address": str(addr), "ref": _ref(1, addr),  # type: ignore[dict-item]
                     "type": "bit", "unit": "-", "access": "R",
                     "description": f"STATUS bit {i}: {BIT_DOC[bit]}"})
    return rows


def _ref(prefix: int, address: int) -> str:
    """The 1-based reference: 40001 for holding address 0 (six digits, 400001 form,
    beyond 9999)."""
    n = address + 1
    return f"{prefix}{n:04d}" if n <= 9999 else f"{prefix}{n:05d}"


def status_names(status: int) -> tuple[str, ...]:
    """The STATUS bits that are set, by name, in bit order."""
    return tuple(str(b.name) for b in Status if status & b)


def read_back(registers: Sequence[int], tail: Sequence[int], word_order: WordOrder) -> dict[str, int]:
    """Named values of both published runs as a PLC reads them: STATUS..METHOD_ID from
    the base (``registers``) and SCORE_A..SCORE_B (``tail``, from ``TAIL_AT``)."""
    values = decode_registers(registers, word_order)
    values.update(decode_tail(tail))
    return values
