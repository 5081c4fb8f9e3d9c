"""Server mode: the bridge serves the PLC register image over Modbus TCP or RTU.

Holding registers ``base .. base + IMAGE_COUNT - 1``, coils ``base .. base + 2`` and
discrete inputs ``base .. base + 9`` (see ``docs/plc.md``).  A write anywhere but
COMMAND, ENABLE and the coils is refused with ILLEGAL DATA ADDRESS; a read outside
the image too.  Accepted commands are queued for the bridge loop, which applies them
to the image (the server thread never touches it).
"""

from __future__ import annotations

import queue
import threading

from ..profile import ModbusPlcSection
from .modbus_io import ILLEGAL_ADDRESS, RegisterServer, SerialSettings
from .plc_image import (
    BITS, COILS, IMAGE_COUNT, REG, STATUS_COUNT, Command, PlcImage, Refused, bits_of, parse_coil_write,
    parse_register_write,
)


class PlcRegisterHandler:
    """Answers the PLC from the newest published registers."""

    def __init__(self, settings: ModbusPlcSection) -> None:
        self.settings = settings
        self.base = settings.base_address
        self.registers: list[int] = [0] * STATUS_COUNT
        self.enabled = True
        self.command_pending = 0  #: COMMAND reads this until the bridge has acted
        self.commands: queue.SimpleQueue[Command] = queue.SimpleQueue()
        self.refused = 0
        self.reads = 0
        self._lock = threading.Lock()

    def publish(self, registers: list[int], enabled: bool) -> None:
        self.registers = list(registers)
        self.enabled = enabled

    def done(self) -> None:
        """The bridge has applied the queued commands: COMMAND reads 0 again."""
        with self._lock:
            if self.commands.empty():
                self.command_pending = 0

    def _holding(self) -> list[int]:
        return [*self.registers, self.command_pending, int(self.enabled)]

    def read(self, table, address, count):
        off = address - self.base
        if table == "holding":
            size = IMAGE_COUNT
            values: list = self._holding()
        elif table == "coils":
            size, values = len(COILS), [False, False, self.enabled]
        elif table == "discrete":
            size, values = len(BITS), bits_of(self.registers[REG["STATUS"].offset])
        else:
            return ILLEGAL_ADDRESS
        if off < 0 or off + count > size:
            return ILLEGAL_ADDRESS
        self.reads += 1
        return values[off: off + count]

    def write(self, table, address, values):
        off = address - self.base
        try:
            if table == "holding":
                cmds = parse_register_write(off, [int(v) for v in values])
            elif table == "coils":
                cmds = parse_coil_write(off, [bool(v) for v in values])
            else:
                return ILLEGAL_ADDRESS
        except Refused as exc:
            self.refused += 1
            return exc.code
        with self._lock:
            for cmd in cmds:
                if cmd.name in ("enable", "disable"):
                    self.enabled = cmd.name == "enable"
                self.commands.put(cmd)
            if table == "holding" and off <= REG["COMMAND"].offset < off + len(values):
                self.command_pending = int(values[REG["COMMAND"].offset - off])
        return None


class PlcServer:
    """The register image served over TCP (``host:port``) or RTU (``serial``)."""

    def __init__(self, settings: ModbusPlcSection, *, tcp: tuple[str, int] | None = None,
                 serial: SerialSettings | None = None) -> None:
        self.handler = PlcRegisterHandler(settings)
        units = None if tcp is not None else [settings.unit_id]
        self.server = RegisterServer(self.handler, tcp=tcp, serial=serial, unit_ids=units)

    @property
    def where(self) -> str:
        return self.server.where

    def start(self) -> "PlcServer":
        self.server.start()
        return self

    def publish(self, registers: list[int], image: PlcImage, urgent: bool = False,
                t_event: float | None = None) -> None:
        self.handler.publish(registers, image.enabled)

    def take_commands(self) -> list[Command]:
        out = []
        while True:
            try:
                out.append(self.handler.commands.get_nowait())
            except queue.Empty:
                return out

    def commands_done(self) -> None:
        self.handler.done()

    def stats_dict(self) -> dict[str, int]:
        return {"plc_reads": self.handler.reads, "plc_refused_writes": self.handler.refused}

    def stop(self) -> None:
        self.server.stop()
