"""A PLC stand-in for commissioning: a Modbus server (TCP, or an RTU slave) whose
holding registers the bridge writes (client mode), which reports every change and
runs example gripper logic.

The logic is the one ``docs/plc.md`` gives in Structured Text: trust the state only
while DATA_VALID is set and the heartbeat moves; on a rising SLIP_LATCHED raise the
grip-force setpoint one step (up to a maximum) and acknowledge the latch through
COMMAND; without valid data, hold the setpoint and say so.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from ..detect.state import GraspState
from ..frames import FrameFlag
from ..modbus.exception_codes import ILLEGAL_ADDRESS
from ..modbus.pdu import Identity, Table
from ..modbus.pymodbus_io import RegisterServer
from ..modbus.rtu_server import RtuServer
from ..modbus.serial_line import SerialSettings
from ..outputs.plc.image import (
    CMD_ACK,
    IMAGE_COUNT,
    REG,
    STATUS_COUNT,
    TAIL_AT,
    TAIL_COUNT,
    Status,
    decode_registers,
    decode_tail,
)
from ..profile import ModbusPlcSection

#: What the stand-in answers, over RTU, to report server id and device identification.
IDENTITY = Identity(vendor_name="eskin-industrial", product_code="plc-sim", revision="simulator")


@dataclass
class PlcMemory:
    """Holding registers ``base .. base + IMAGE_COUNT - 1``: the PLC's receive area."""

    base: int
    regs: list[int] = field(default_factory=lambda: [0] * IMAGE_COUNT)
    writes: int = 0
    on_write: Callable[[float], None] | None = None

    def read(self, table: Table, address: int, count: int) -> list[int] | int:
        off = address - self.base
        if table != "holding" or off < 0 or off + count > IMAGE_COUNT:
            return ILLEGAL_ADDRESS
        return self.regs[off: off + count]

    def write(self, table: Table, address: int, values: list[int] | list[bool]) -> int | None:
        off = address - self.base
        if table != "holding" or off < 0 or off + len(values) > IMAGE_COUNT:
            return ILLEGAL_ADDRESS
        self.regs[off: off + len(values)] = [int(v) for v in values]
        self.writes += 1
        if self.on_write is not None:
            self.on_write(time.perf_counter())
        return None


def describe_status(status: int) -> str:
    # A single-bit flag member always has a name; the stubs allow None for combinations.
    return "|".join(b.name for b in Status if status & b) or "-"  # type: ignore[misc]


@dataclass
class Gripper:
    """The example logic: grip force setpoint in newtons."""

    force_n: float = 5.0
    step_n: float = 2.0
    max_n: float = 20.0
    heartbeat_timeout_s: float = 0.5
    raises: int = 0
    trusted: bool = False
    #: FLAGS TURN_UNSEEN, as ``FB_SlipGuard``'s ``bTurnUnseen``: a turn of the part would
    #: read stable, so "no slip" says nothing about twisting it
    turn_unseen: bool = False
    _last_hb: int = -1
    _hb_time: float = 0.0
    _latched_before: bool = False
    _acked: bool = False

    def cycle(self, v: dict[str, int], now: float) -> tuple[list[str], bool]:
        """One PLC scan; returns messages and whether to acknowledge the latch."""
        msgs: list[str] = []
        if v["HEARTBEAT"] != self._last_hb:
            self._last_hb, self._hb_time = v["HEARTBEAT"], now
        alive = now - self._hb_time <= self.heartbeat_timeout_s
        status = v["STATUS"]
        trusted = alive and bool(status & Status.DATA_VALID)
        if trusted != self.trusted:
            self.trusted = trusted
            why = "bridge silent" if not alive else describe_status(status & (
                Status.SENSOR_STALE | Status.BUS_FAULT | Status.ENABLED | Status.DATA_VALID | Status.BRIDGE_OFFLINE))
            msgs.append("data trusted" if trusted else f"NO VERDICT ({why}): holding grip force")
        latched = bool(status & Status.SLIP_LATCHED)
        ack = False
        if latched and not self._latched_before and alive:
            self.force_n = min(self.force_n + self.step_n, self.max_n)
            self.raises += 1
            msgs.append(f"SLIP: grip force raised to {self.force_n:g} N")
        if latched and alive and not status & Status.SLIP:
            # the latch stays set while the slip lasts: acknowledge once it is over
            ack = True
            if not self._acked:
                msgs.append("slip over: acknowledging the latch")
            self._acked = True
        if not latched:
            self._acked = False
        self._latched_before = latched
        unseen = trusted and bool(v.get("FLAGS", 0) & FrameFlag.TURN_UNSEEN)
        if unseen != self.turn_unseen:
            self.turn_unseen = unseen
            msgs.append("TURN UNSEEN: a turn would read stable, no twisting motion on 'no slip'" if unseen
                        else "turns seen again")
        return msgs, ack


class PlcSimulator:
    """Serve the PLC memory over TCP (or RTU); a scan thread prints changes and runs the logic.

    Over TCP the memory is served by pymodbus: the bridge's client mode writes with
    its own master and framing (``modbus/tcp_master.py``), so a Modbus stack we did not
    write decodes every request.  Over RTU the bridge's master is pymodbus', and the
    stand-in serves with our own RTU server: again two stacks, one of them not ours.
    """

    def __init__(self, settings: ModbusPlcSection, host: str, port: int, *, scan_s: float = 0.01,
                 echo: Callable[[str], None] | None = print, gripper: Gripper | None = None,
                 serial: SerialSettings | None = None) -> None:
        self.settings = settings
        self.memory = PlcMemory(settings.base_address, on_write=self._on_write)
        self.memory.regs[REG["ENABLE"].offset] = 1  # the PLC program enables detection
        self.server: RtuServer | RegisterServer
        if serial is not None:  # an RTU slave with the profile's unit id
            self.server = RtuServer(self.memory, serial, settings.unit_id, IDENTITY)
        else:
            self.server = RegisterServer(self.memory, tcp=(host, port))
        self.scan_s = scan_s
        self.echo = echo
        self.gripper = gripper or Gripper()
        #: (perf_counter of the write, STATUS) for every write that changed STATUS
        self.status_changes: list[tuple[float, int]] = []
        self._status: int | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def _on_write(self, t: float) -> None:
        status = self.memory.regs[REG["STATUS"].offset]
        if status != self._status:
            self._status = status
            self.status_changes.append((t, status))

    def first(self, bit: Status, after: float = 0.0) -> float | None:
        """perf_counter time of the first write that set ``bit``."""
        for t, status in list(self.status_changes):
            if t >= after and status & bit:
                return t
        return None

    def start(self) -> PlcSimulator:
        self.server.start()
        self._thread = threading.Thread(target=self._scan, name="plc-sim", daemon=True)
        self._thread.start()
        return self

    def _say(self, text: str) -> None:
        if self.echo is not None:
            self.echo(f"{time.strftime('%H:%M:%S')} {text}")

    def _scan(self) -> None:
        prev: dict[str, int] | None = None
        wo = self.settings.word_order
        while not self._stop.wait(self.scan_s):
            regs = list(self.memory.regs[:STATUS_COUNT]) + [0, 0]
            v = decode_registers(regs, wo)
            tail = decode_tail(self.memory.regs[TAIL_AT: TAIL_AT + TAIL_COUNT])
            if prev is not None:
                quiet = ~int(Status.BRIDGE_ALIVE)  # the life bit toggles at every write
                changes = [f"{k}={_show(k, v[k])}" for k in ("STATUS", "STATE")
                           if v[k] & quiet != prev[k] & quiet]
                if changes:
                    self._say(" ".join(changes) + f"  (R_COE={v['R_COE']} R_DW={v['R_DW']} SCORE_A={tail['SCORE_A']} "
                                                  f"SCORE_B={tail['SCORE_B']} F_SUM={v['F_SUM']} mN)")
            prev = v
            msgs, ack = self.gripper.cycle(v, time.monotonic())
            for m in msgs:
                self._say(m)
            if ack:
                self.memory.regs[REG["COMMAND"].offset] |= CMD_ACK

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2)
        self.server.stop()


def _show(name: str, value: int) -> str:
    if name == "STATUS":
        return describe_status(value)
    if name == "STATE":
        return GraspState(value).label if value in GraspState._value2member_map_ else str(value)
    return str(value)
