"""Server mode: the bridge serves the PLC register image over Modbus TCP or RTU.

Holding registers ``base .. base + IMAGE_COUNT - 1`` (and the same words, read-only,
as input registers), coils ``base .. base + 2`` and discrete inputs ``base .. base + 9``
(see ``docs/plc.md``).  A write anywhere but COMMAND, ENABLE and the coils is refused
with ILLEGAL DATA ADDRESS; a read outside the image too.  A tare is refused at once
with SERVER DEVICE FAILURE (04) while the image says something is held, or cannot
say (:func:`~eskin_industrial.node.refusal`, the rule every output uses).  Accepted
commands are queued for the bridge loop, which applies them (the server thread never
changes the node's state).

The servers are our own, with one PDU handler (:mod:`..modbus.pdu`): over TCP
:mod:`..modbus.tcp_server` (connection cap, idle timeout, allow-lists, read-only
mode, unit ids), over RTU :mod:`..modbus.rtu_server` (our unit id, read-only
mode).
"""

from __future__ import annotations

import importlib.metadata
import ipaddress
import logging
import queue
import threading
import time
from collections.abc import Sequence

from ...errors import Refused
from ...identity import DeviceIdentity
from ...modbus.exception_codes import DEVICE_FAILURE, ILLEGAL_ADDRESS
from ...modbus.pdu import Identity, Table
from ...modbus.rtu_server import RtuServer
from ...modbus.serial_line import SerialSettings
from ...modbus.serving import RateLimitedLog
from ...modbus.tcp_server import PEER, Policy, TcpServer, networks
from ...node import Command, NodeSnapshot, refusal
from ...profile import ModbusPlcSection
from ..base import Sink
from .image import (
    BITS,
    COILS,
    IMAGE_COUNT,
    REG,
    STATUS_COUNT,
    TAIL_COUNT,
    PlcImage,
    bits_of,
    coil_values,
    parse_coil_write,
    parse_register_write,
)


class PlcRegisterHandler:
    """Answers the PLC from the newest published registers."""

    def __init__(self, settings: ModbusPlcSection) -> None:
        self.settings = settings
        self.base = settings.base_address
        self.registers: list[int] = [0] * STATUS_COUNT
        self.tail: list[int] = [0] * TAIL_COUNT  #: SCORE_A..SCORE_B, after COMMAND and ENABLE
        self.enabled = True
        self.command_pending = 0  #: COMMAND reads this until the bridge has acted
        self.commands: queue.SimpleQueue[Command] = queue.SimpleQueue()
        self.refused = 0
        self.tares_refused = 0
        self.reads = 0
        self.snapshot: NodeSnapshot | None = None  #: the newest published (for the tare rule)
        self.log = RateLimitedLog(logging.getLogger(__name__))
        self._lock = threading.Lock()

    def publish(self, registers: list[int], enabled: bool, snapshot: NodeSnapshot | None = None,
                tail: Sequence[int] = ()) -> None:
        self.registers = list(registers)
        if tail:
            self.tail = list(tail)
        self.enabled = enabled
        if snapshot is not None:
            self.snapshot = snapshot

    def done(self) -> None:
        """The bridge has applied the queued commands: COMMAND reads 0 again."""
        with self._lock:
            if self.commands.empty():
                self.command_pending = 0

    def _holding(self) -> list[int]:
        return [*self.registers, self.command_pending, int(self.enabled), *self.tail]

    def read(self, table: Table, address: int, count: int) -> list[int] | list[bool] | int:
        off = address - self.base
        if table in ("holding", "input"):  # input registers: a read-only mirror (FC4)
            size = IMAGE_COUNT
            values: list = self._holding()
        elif table == "coils":
            size, values = len(COILS), coil_values(self.enabled)
        elif table == "discrete":
            size, values = len(BITS), bits_of(self.registers[REG["STATUS"].offset])
        else:
            return ILLEGAL_ADDRESS
        if off < 0 or off + count > size:
            return ILLEGAL_ADDRESS
        self.reads += 1
        return values[off: off + count]

    def write(self, table: Table, address: int, values: list[int] | list[bool]) -> int | None:
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
        for cmd in cmds:
            if cmd.name != "tare":
                continue
            # The newest snapshot: replaced (never changed in place) by the loop's
            # thread, so this thread reads one whole snapshot.
            why = refusal(cmd, self.snapshot)
            if why is not None:
                # Refused as a whole, at once: nothing of this write is applied.
                self.tares_refused += 1
                self.log.event("plc_tare_refused", peer=PEER.get(), base_address=self.base, reason=why)
                return DEVICE_FAILURE
        with self._lock:
            for cmd in cmds:
                if cmd.name in ("enable", "disable"):
                    self.enabled = cmd.name == "enable"
                self.commands.put(cmd)
            if table == "holding" and off <= REG["COMMAND"].offset < off + len(values):
                self.command_pending = int(values[REG["COMMAND"].offset - off])
        return None


class PlcBlocks:
    """Several register blocks on one server, one per sensor node, each at its own
    ``base_address``; a request must fall inside one block."""

    SIZES = {"holding": IMAGE_COUNT, "input": IMAGE_COUNT, "coils": len(COILS), "discrete": len(BITS)}

    def __init__(self, handlers: list[PlcRegisterHandler]) -> None:
        bases = sorted(h.base for h in handlers)
        for lo, hi in zip(bases, bases[1:]):
            if hi - lo < IMAGE_COUNT:
                raise ValueError(f"register blocks at {lo} and {hi} overlap (a block takes {IMAGE_COUNT} registers)")
        self.handlers = handlers

    def _find(self, table: str, address: int, count: int) -> PlcRegisterHandler | None:
        size = self.SIZES.get(table)
        if size is None:
            return None
        for h in self.handlers:
            if h.base <= address and address + count <= h.base + size:
                return h
        return None

    def read(self, table: Table, address: int, count: int) -> list[int] | list[bool] | int:
        h = self._find(table, address, count)
        return ILLEGAL_ADDRESS if h is None else h.read(table, address, count)

    def write(self, table: Table, address: int, values: list[int] | list[bool]) -> int | None:
        h = self._find(table, address, len(values))
        return ILLEGAL_ADDRESS if h is None else h.write(table, address, values)


class PlcServer:
    """The register image served over TCP (``host:port``) or RTU (``serial``).

    ``blocks``: one register block per sensor node (each its own ``base_address``);
    :meth:`block` gives each node's loop its sink.  Default: one block, and the server
    answers for that block's sink itself (:meth:`take_commands`, ...).
    """

    def __init__(self, settings: ModbusPlcSection, *, tcp: tuple[str, int] | None = None,
                 serial: SerialSettings | None = None, blocks: list[ModbusPlcSection] | None = None,
                 linger_s: float = 0.0, policy: Policy | None = None, identity: Identity | None = None) -> None:
        self.handlers = [PlcRegisterHandler(b) for b in (blocks or [settings])]
        self.handler = self.handlers[0]
        served = self.handler if len(self.handlers) == 1 else PlcBlocks(self.handlers)
        self.server: TcpServer | RtuServer
        if tcp is not None:
            self.server = TcpServer(served, tcp[0], tcp[1], identity or identity_of(settings.identity),
                                    policy or policy_of(settings, blocks or [settings]), server_id=settings.unit_id)
        else:
            assert serial is not None
            self.server = RtuServer(served, serial, settings.unit_id, identity or identity_of(settings.identity),
                                    read_only=policy.read_only if policy is not None else settings.read_only)
        self.linger_s = linger_s
        self._lingered = False
        self._blocks = [PlcBlockSink(self, h) for h in self.handlers]  # built once: used at every scan

    def block(self, index: int) -> PlcBlockSink:
        return self._blocks[index]

    @property
    def where(self) -> str:
        return self.server.where

    def start(self) -> PlcServer:
        self.server.start()
        server = self.server
        if isinstance(server, TcpServer) and _every_interface(server.host) and not (
                server.policy.allow_read or server.policy.allow_write):
            # Modbus has no authentication: say so once, where the operator looks.
            logging.getLogger(__name__).warning("plc_server_exposed", extra={"fields": {
                "bind": server.host, "port": server.port,
                "advice": "bind to the cell interface, or set allow_read / allow_write"}})
        return self

    def linger(self) -> None:
        """On shutdown, once for all blocks: keep serving the offline image for
        ``linger_s``, so that a polling PLC reads it before the connection goes."""
        if not self._lingered:
            self._lingered = True
            time.sleep(self.linger_s)

    # One block: the server answers for its block's sink.
    def publish(self, snapshot: NodeSnapshot) -> None:
        self._blocks[0].publish(snapshot)

    def take_commands(self) -> list[Command]:
        return self._blocks[0].take_commands()

    def commands_done(self) -> None:
        self._blocks[0].commands_done()

    def counters(self) -> dict[str, int]:
        """The server's own counters (requests, refusals; over TCP, connections)."""
        return self.server.counters.as_dict()

    def stop(self) -> None:
        self.server.stop()


def _every_interface(host: str) -> bool:
    """``0.0.0.0``, ``::`` or an empty host: every interface of the machine."""
    try:
        return not host or ipaddress.ip_address(host).is_unspecified
    except ValueError:
        return False  # a host name: one interface


def policy_of(settings: ModbusPlcSection, blocks: Sequence[ModbusPlcSection] = ()) -> Policy:
    """The TCP server's policy from ``[modbus.plc]`` (or ``[plc]`` merged into it);
    no ``unit_ids``: each block's ``unit_id``, 0 and 255 (the ids a Modbus TCP client
    uses for "the device at this address")."""
    units = settings.unit_ids or (0, 255, *(b.unit_id for b in blocks or [settings]))
    return Policy(max_connections=settings.max_connections, idle_timeout_s=settings.idle_timeout_s,
                  allow_read=networks(settings.allow_read, "allow_read"),
                  allow_write=networks(settings.allow_write, "allow_write"),
                  read_only=settings.read_only, unit_ids=frozenset(units))


def identity_of(ident: DeviceIdentity, model_name: str = "") -> Identity:
    """The device identification of ``[identity]`` (:mod:`eskin_industrial.identity`),
    its blanks filled: the revision with the package's version, the model with ``model_name``."""
    try:
        version = importlib.metadata.version("eskin-industrial")
    except importlib.metadata.PackageNotFoundError:
        version = "unknown"
    return Identity(vendor_name=ident.vendor_name, product_code=ident.product_code,
                    revision=ident.revision or version, vendor_url=ident.vendor_url,
                    product_name=ident.product_name, model_name=ident.model_name or model_name)


class PlcBlockSink(Sink):
    """One node's block of a shared :class:`PlcServer`, as that node's sink."""


    def __init__(self, server: PlcServer, handler: PlcRegisterHandler) -> None:
        super().__init__()
        self.server = server
        self.handler = handler
        self.image = PlcImage(handler.settings)  #: this block's register image (its heartbeat)
        self.where = f"{server.where}, base address {handler.base}"

    def _publish(self, snapshot: NodeSnapshot) -> None:
        image = self.image
        self.handler.publish(image.render(snapshot), snapshot.enabled, snapshot, image.tail)

    def take_commands(self) -> list[Command]:
        if self.handler.commands.empty():  # every scan asks: no exception raised and caught for none
            return []
        out = []
        while True:
            try:
                out.append(self.handler.commands.get_nowait())
            except queue.Empty:
                return out

    def commands_done(self) -> None:
        self.handler.done()

    def counters(self) -> dict[str, int]:
        out = {"plc_reads": self.handler.reads, "plc_refused_writes": self.handler.refused,
               "plc_tares_refused": self.handler.tares_refused}
        if self.handler is self.server.handler:  # the server's own counters: once, with the first block
            out.update(self.server.counters())
        return out

    def flush(self, timeout_s: float = 1.0) -> bool:
        self.server.linger()
        return True
