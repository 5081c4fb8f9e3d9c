"""The gripper as a Modbus TCP device, in the style of common electric grippers: the
PLC writes an action and a force request, and reads back the force and whether it
holds an object (the object status says "stopped on contact", or "at position: no
object / object lost"; it is no slip detector).  The table is docs/cell.md's.

:data:`GRIPPER_REGISTERS` is the one description of the map; :class:`GripperRegisters`
answers a server's reads and writes from it (``modbus.pymodbus_io.RegisterServer``,
the pymodbus server the PLC stand-in uses over TCP).  The drive itself is ``actuator.py``: the device
hands every accepted request to ``on_request`` with its arrival time, and reads the
state it reports from :class:`GripperState`, which the world updates.
"""

from __future__ import annotations

import enum
import time
from collections.abc import Callable
from dataclasses import dataclass

from ...modbus.exception_codes import ILLEGAL_ADDRESS, ILLEGAL_VALUE
from ...modbus.pdu import Table

#: The force registers' unit: 0.01 N.
FORCE_SCALE = 100.0


class Action(enum.IntFlag):
    GO = 1 << 0  #: close and hold at FORCE_REQUEST (0: open)


class GripperStatus(enum.IntFlag):
    READY = 1 << 0
    GO = 1 << 1  #: ACTION's GO as taken
    MOVING = 1 << 2  #: the force is not yet at the request
    FAULT = 1 << 3  #: a request it refused


class ObjectStatus(enum.IntEnum):
    MOVING = 0  #: closing or changing the force, no object yet
    OPEN = 1
    HOLDING = 2  #: stopped on contact: holding an object
    NO_OBJECT = 3  #: closed at position: no object, or the object was lost


@dataclass(frozen=True)
class GripperRegister:
    name: str
    offset: int
    unit: str
    access: str
    doc: str


GRIPPER_REGISTERS: tuple[GripperRegister, ...] = (
    GripperRegister("ACTION", 0, "bits", "RW", "bit 0 GO: 1 close and hold at FORCE_REQUEST, 0 open"),
    GripperRegister("FORCE_REQUEST", 1, "0.01 N", "RW",
                    "grip force request; above the rated force: exception 03 ILLEGAL DATA VALUE"),
    GripperRegister("GRIPPER_STATUS", 2, "bits", "R",
                    "bit 0 READY, bit 1 GO (ACTION as taken), bit 2 MOVING (force not at the request), "
                    "bit 3 FAULT (a request refused)"),
    GripperRegister("OBJECT_STATUS", 3, "code", "R",
                    "0 moving, 1 open, 2 holding an object (stopped on contact), 3 no object or object lost"),
    GripperRegister("FORCE_ECHO", 4, "0.01 N", "R", "the request the drive works to (taken after its dead time)"),
    GripperRegister("ACTUAL_FORCE", 5, "0.01 N", "R", "the grip force now"),
)
GREG = {r.name: r for r in GRIPPER_REGISTERS}
GRIPPER_COUNT = len(GRIPPER_REGISTERS)


def to_register(force_n: float) -> int:
    return int(min(max(round(force_n * FORCE_SCALE), 0), 0xFFFF))


def from_register(value: int) -> float:
    return value / FORCE_SCALE


@dataclass
class GripperState:
    """What the device reports, kept current by whoever runs the drive (plain
    attributes: one writer, atomic reads)."""

    go: bool = False
    request_n: float = 0.0
    target_n: float = 0.0
    force_n: float = 0.0
    holding: bool = False  #: an object between the fingers, intact
    lost: bool = False  #: the object dropped out, or gave way
    fault: bool = False


class GripperRegisters:
    """The register map as a server handler (holding registers, also read as input
    registers); accepted requests go to ``on_request(t_monotonic, force_n)``."""

    def __init__(self, state: GripperState, rated_n: float,
                 on_request: Callable[[float, float], None], clock: Callable[[], float] = time.monotonic) -> None:
        self.state = state
        self.rated_n = rated_n
        self.on_request = on_request
        self.clock = clock
        self.writes = 0
        self.refused = 0

    def values(self) -> list[int]:
        s = self.state
        status = GripperStatus.READY
        if s.go:
            status |= GripperStatus.GO
        if abs(s.force_n - s.request_n) > 0.005 or s.target_n != s.request_n:
            status |= GripperStatus.MOVING
        if s.fault:
            status |= GripperStatus.FAULT
        if not s.go:
            obj = ObjectStatus.OPEN
        elif s.lost:
            obj = ObjectStatus.NO_OBJECT
        elif s.holding and not status & GripperStatus.MOVING:
            obj = ObjectStatus.HOLDING
        else:
            obj = ObjectStatus.MOVING
        return [int(Action.GO) if s.go else 0, to_register(s.request_n), int(status), int(obj),
                to_register(s.target_n), to_register(s.force_n)]

    def read(self, table: Table, address: int, count: int) -> list[int] | int:
        if table not in ("holding", "input") or address < 0 or address + count > GRIPPER_COUNT:
            return ILLEGAL_ADDRESS
        return self.values()[address: address + count]

    def write(self, table: Table, address: int, values: list[int] | list[bool]) -> int | None:
        writable = GREG["FORCE_REQUEST"].offset + 1
        if table != "holding" or address < 0 or address + len(values) > writable:
            return ILLEGAL_ADDRESS
        now = self.clock()
        new = dict(zip(range(address, address + len(values)), (int(v) for v in values)))
        action = new.get(GREG["ACTION"].offset)
        if action is not None and action & ~int(Action.GO):
            self.refused += 1
            return ILLEGAL_VALUE
        request = new.get(GREG["FORCE_REQUEST"].offset)
        if request is not None and from_register(request) > self.rated_n:
            self.state.fault = True
            self.refused += 1
            return ILLEGAL_VALUE
        s = self.state
        s.fault = False
        self.writes += 1
        if action is not None:
            s.go = bool(action & Action.GO)
        if request is not None:
            s.request_n = from_register(request)
        if action is not None or request is not None:
            self.on_request(now, s.request_n if s.go else 0.0)
        return None
