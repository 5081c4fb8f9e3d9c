"""The PLC's view of the bridge: one register image, the same in client and server mode.

Pure code, no I/O and no clock: :class:`PlcImage` takes detector updates, health
(age of the newest frame, bus fault, counters) and the PLC's commands, and renders
the holding registers and the status bits.  Transports (``plc_client``,
``plc_server``) only move the rendered values.  The table in ``docs/plc.md`` is
generated from :data:`REGISTERS` and :data:`BITS` (``eskin-bus plc map``).
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import Literal

from ..bus.modbus.codec import ILLEGAL_ADDRESS, ILLEGAL_VALUE
from ..detect.state import GraspState
from ..detect.updates import Update
from ..errors import Refused
from ..profile import ModbusPlcSection


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


BIT_DOC: dict[Status, str] = {
    Status.CONTACT: "total force at or above the contact threshold",
    Status.STABLE: "state code 1: stable grasp",
    Status.VARIABLE_FORCE: "state code 2: force varying, no slip",
    Status.SLIP: "state code 3: slip now",
    Status.SLIP_LATCHED: "a slip was seen since the last acknowledge (stays set while slip lasts)",
    Status.DATA_VALID: "the state is a verdict: indicators valid, sensor fresh, no bus fault, enabled",
    Status.SENSOR_STALE: "no scan from the sensor for longer than stale_s (default 2.5 scan periods)",
    Status.BUS_FAULT: "the sensor bus fails (consecutive polls failed, or the node is unreachable)",
    Status.BRIDGE_ALIVE: "toggles at every publication (life bit; HEARTBEAT counts the same)",
    Status.ENABLED: "detection enabled by the PLC (ENABLE register)",
    Status.BRIDGE_OFFLINE: "the bridge has shut down (last image it wrote); no state is claimed",
}

Kind = Literal["bits", "u16", "i16", "u32"]


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
    Register("R_COE", 2, "u16", "x r_scale", "decorrelation indicator x r_scale, saturated at 65535"),
    Register("R_DW", 3, "u16", "x r_scale", "wavelet indicator x r_scale, saturated at 65535"),
    Register("F_SUM", 4, "u32", "mN", "total force of the newest frame"),
    Register("XC", 6, "i16", "0.01 mm", "centre of force, x (held while out of contact)"),
    Register("YC", 7, "i16", "0.01 mm", "centre of force, y"),
    Register("HEARTBEAT", 8, "u16", "count", "+1 at every publication, wraps at 65535"),
    Register("FRAME_AGE", 9, "u16", "ms", "age of the newest frame at publication, 65535 = none or older"),
    Register("SLIP_EVENTS", 10, "u32", "count", "entries into slip since start"),
    Register("STATE_CHANGES", 12, "u32", "count", "state changes since start"),
    Register("LOST_SCANS", 14, "u32", "count", "scans lost: failed polls and sequence gaps"),
    Register("BUS_ERRORS", 16, "u32", "count", "timeouts + CRC/framing errors + exception responses"),
    Register("FLAGS", 18, "u16", "bits", "frame/update flags of the newest update (FrameFlag, low 16 bits)"),
    Register("RESERVED", 19, "u16", "-", "reads 0 (room for a later value)"),
    Register("COMMAND", 20, "bits", "-", "write: bit 0 acknowledge slip latch, bit 1 tare; reads 0 once done",
             "RW"),
    Register("ENABLE", 21, "u16", "0/1", "write 1 to enable detection, 0 to disable; reads the current value",
             "RW"),
)
REG = {r.name: r for r in REGISTERS}
#: Registers the bridge publishes (client mode writes these in one request).
STATUS_COUNT = REG["COMMAND"].offset
#: All registers, including the command registers.
IMAGE_COUNT = REG["ENABLE"].offset + 1

CMD_ACK = 1 << 0
CMD_TARE = 1 << 1

#: Coils (offsets from the base address): write 1 to act.
COILS: tuple[tuple[str, str], ...] = (
    ("ACK_SLIP", "write 1: acknowledge the slip latch (reads 0)"),
    ("TARE", "write 1: tare with the sensor unloaded (reads 0)"),
    ("ENABLE", "1 enabled, 0 disabled (reads the current value)"),
)
#: Discrete inputs: bit i = Status bit i.
BITS: tuple[Status, ...] = tuple(Status)



@dataclass(frozen=True)
class Health:
    """What the transport side knows, at publication time."""

    frame_age_s: float | None = None  #: None: no frame yet
    bus_fault: bool = False
    lost_scans: int = 0
    bus_errors: int = 0


@dataclass(frozen=True)
class Command:
    name: Literal["ack", "tare", "enable", "disable"]


def _u16(v: float) -> int:
    if not math.isfinite(v):
        return 0xFFFF
    return int(min(max(round(v), 0), 0xFFFF))


def _i16(v: float) -> int:
    v = int(min(max(round(v), -0x8000), 0x7FFF)) if math.isfinite(v) else 0
    return v & 0xFFFF


def split32(value: int, word_order: str) -> list[int]:
    value &= 0xFFFFFFFF
    hi, lo = value >> 16, value & 0xFFFF
    return [hi, lo] if word_order == "big" else [lo, hi]


def join32(words: list[int], word_order: str) -> int:
    hi, lo = (words[0], words[1]) if word_order == "big" else (words[1], words[0])
    return (hi << 16) | lo


def decode_registers(registers, word_order: str) -> dict[str, int]:
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
            out[r.name] = words[0] - 0x10000 if words[0] >= 0x8000 else words[0]
        else:
            out[r.name] = words[0]
    return out


@dataclass
class PlcImage:
    """State, latch, enable and counters as the PLC sees them."""

    settings: ModbusPlcSection
    enabled: bool = True
    latched: bool = False
    heartbeat: int = 0
    slip_events: int = 0
    state_changes: int = 0
    update: Update | None = None

    # -- input side -------------------------------------------------------------
    def observe(self, update: Update) -> bool:
        """Take a detector update; True when the PLC must hear of it at once
        (the state or the slip bit changed)."""
        before = self.update
        self.update = update
        changed = before is None or before.state != update.state or before.valid != update.valid
        if changed and before is not None:
            self.state_changes += 1
        if update.state == GraspState.SLIP and (before is None or before.state != GraspState.SLIP):
            self.slip_events += 1
            if self.enabled and not self.latched:
                self.latched = True
                changed = True
        return changed

    def apply(self, command: Command) -> None:
        if command.name == "ack":
            # The latch stays set while the slip lasts: an acknowledge cannot hide it.
            self.latched = self.enabled and self.update is not None and self.update.state == GraspState.SLIP
        elif command.name == "enable":
            self.enabled = True
        elif command.name == "disable":
            self.enabled = False
            self.latched = False
        # "tare" acts on the calibration: the bridge does it, the image has no part in it.

    # -- output side ------------------------------------------------------------
    @property
    def stale_limit_s(self) -> float:
        """Frame age beyond which the sensor is stale (a profile resolves ``stale_s``
        from its rate; a bare section, with no rate to derive it from, takes 0.2 s)."""
        return self.settings.stale_s if self.settings.stale_s is not None else 0.2

    def status(self, health: Health) -> int:
        u = self.update
        bits = Status(0)
        # written so that a NaN age (a broken clock) reads as stale, never as fresh
        stale = health.frame_age_s is None or not health.frame_age_s <= self.stale_limit_s
        if stale:
            bits |= Status.SENSOR_STALE
        if health.bus_fault:
            bits |= Status.BUS_FAULT
        if self.enabled:
            bits |= Status.ENABLED
        if self.heartbeat & 1:
            bits |= Status.BRIDGE_ALIVE
        if self.latched:
            bits |= Status.SLIP_LATCHED
        if u is not None and self.enabled and not stale:
            state = u.state
            if state != GraspState.NO_CONTACT:
                bits |= Status.CONTACT
            bits |= {GraspState.STABLE: Status.STABLE, GraspState.VARIABLE_FORCE: Status.VARIABLE_FORCE,
                     GraspState.SLIP: Status.SLIP}.get(GraspState(state), Status(0))
            if u.valid and not health.bus_fault:
                bits |= Status.DATA_VALID
        return int(bits)

    def render(self, health: Health) -> list[int]:
        """The STATUS..FLAGS registers (``STATUS_COUNT`` values); one publication:
        the heartbeat advances."""
        self.heartbeat = (self.heartbeat + 1) & 0xFFFF
        cfg = self.settings
        wo = cfg.word_order
        status = self.status(health)
        u = self.update
        # Disabled or stale: no state is claimed (0, with DATA_VALID clear).
        shown = u is not None and self.enabled and not status & Status.SENSOR_STALE
        state = u.state if shown else 0
        r_coe = _u16(u.r_coe * cfg.r_scale) if shown else 0
        r_dw = _u16(u.r_dw * cfg.r_scale) if shown else 0
        # Clip before rounding: a finite f_sum above ~1.8e305 N is infinite in mN, and
        # round(inf) raises (the register saturates instead).
        f_sum = int(round(min(max(u.f_sum * 1000.0, 0.0), 0xFFFFFFFF))) if u is not None and math.isfinite(u.f_sum) else 0
        xc = _i16(u.xc * 100.0) if u is not None else 0
        yc = _i16(u.yc * 100.0) if u is not None else 0
        age = 0xFFFF if health.frame_age_s is None else _u16(health.frame_age_s * 1000.0)
        flags = (u.flags & 0xFFFF) if u is not None else 0
        return [
            status, state, r_coe, r_dw, *split32(f_sum, wo), xc, yc, self.heartbeat, age,
            *split32(self.slip_events, wo), *split32(self.state_changes, wo),
            *split32(health.lost_scans, wo), *split32(health.bus_errors, wo), flags, 0,
        ]

    def render_offline(self, health: Health) -> list[int]:
        """The last image of a bridge that stops: BRIDGE_OFFLINE and nothing else in
        STATUS (no state bit, DATA_VALID clear), STATE 0, FRAME_AGE 65535, counters kept.
        A client-mode PLC keeps what was written last, so this is what it must read,
        never the last "stable"."""
        regs = self.render(health)
        wo = self.settings.word_order
        regs[REG["STATUS"].offset] = int(Status.BRIDGE_OFFLINE)
        for name in ("STATE", "R_COE", "R_DW", "FLAGS"):
            regs[REG[name].offset] = 0
        regs[REG["FRAME_AGE"].offset] = 0xFFFF
        at = REG["F_SUM"].offset
        regs[at: at + 2] = split32(0, wo)
        return regs

    def coils(self) -> list[bool]:
        return [False, False, self.enabled]


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
    out: list[Command] = []
    for i, v in enumerate(values):
        at = offset + i
        if at == 0:
            out += [Command("ack")] if v else []
        elif at == 1:
            out += [Command("tare")] if v else []
        elif at == 2:
            out.append(Command("enable" if v else "disable"))
        else:
            raise Refused(ILLEGAL_ADDRESS, f"coil offset {at} does not exist")
    return out


def bits_of(status: int) -> list[bool]:
    """The discrete inputs for a STATUS value."""
    return [bool(status & b) for b in BITS]


# -- the documented table ---------------------------------------------------------

def map_rows(settings: ModbusPlcSection) -> list[dict[str, str]]:
    """One row per register, coil and discrete input, with both numberings."""
    base = settings.base_address
    rows = []
    for r in REGISTERS:
        addr = base + r.offset
        span = f"{addr}" if r.words == 1 else f"{addr}-{addr + 1}"
        ref = _ref(4, addr) if r.words == 1 else f"{_ref(4, addr)}-{_ref(4, addr + 1)}"
        kind = r.kind if r.kind != "u32" else f"u32 ({settings.word_order} word order)"
        doc = r.doc.replace("x r_scale", f"x {settings.r_scale:g}")
        unit = r.unit.replace("x r_scale", f"x {settings.r_scale:g}")
        rows.append({"table": "holding register", "name": r.name, "address": span, "ref": ref, "type": kind,
                     "unit": unit, "access": r.access, "description": doc})
    for i, (name, doc) in enumerate(COILS):
        addr = base + i
        rows.append({"table": "coil", "name": name, "address": str(addr), "ref": _ref(0, addr),
                     "type": "bit", "unit": "-", "access": "RW", "description": doc})
    for i, bit in enumerate(BITS):
        addr = base + i
        rows.append({"table": "discrete input", "name": bit.name, "address": str(addr), "ref": _ref(1, addr),
                     "type": "bit", "unit": "-", "access": "R",
                     "description": f"STATUS bit {i}: {BIT_DOC[bit]}"})
    return rows


def _ref(prefix: int, address: int) -> str:
    """The 1-based reference: 40001 for holding address 0 (six digits, 400001 form,
    beyond 9999)."""
    n = address + 1
    return f"{prefix}{n:04d}" if n <= 9999 else f"{prefix}{n:05d}"
