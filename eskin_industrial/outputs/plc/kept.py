"""The register image a node would publish, kept instead of sent: what ``monitor``
shows beside the node's snapshot when no PLC is connected."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from ...node import NodeSnapshot
from ...profile import ModbusPlcSection
from ..base import Sink
from .image import PlcImage, read_back, status_names


class KeptRegisters(Sink):
    """Renders every snapshot into the node's register image, as the PLC output
    would, and keeps the newest (read by a view's redraw thread)."""


    def __init__(self, settings: ModbusPlcSection) -> None:
        super().__init__()
        self.where = "the live view"
        self.image = PlcImage(settings)
        self.registers: list[int] | None = None
        self.tail: tuple[int, ...] = ()

    def _publish(self, snapshot: NodeSnapshot) -> None:
        self.registers = self.image.render(snapshot)
        self.tail = tuple(self.image.tail)

    def table(self) -> tuple[dict[str, int], tuple[str, ...]] | None:
        """The newest registers by name, and the STATUS bits set (None before the first)."""
        regs = self.registers
        if regs is None:
            return None
        values = read_back(regs, self.tail, self.image.settings.word_order)
        return values, status_names(values["STATUS"])


def served_table(sink: Sink) -> Callable[[], tuple[dict[str, int], tuple[str, ...]]] | None:
    """A reader of the block a PLC reads from this sink (server mode: the served
    registers, by name, and the STATUS bits set), for a view beside the PLC (the web
    console's register block); None for a sink that serves no block (client mode
    writes, and its image is the writer's own)."""
    from .server import PlcBlockSink

    if not isinstance(sink, PlcBlockSink):
        return None
    handler = sink.handler
    word_order = handler.settings.word_order

    def table() -> tuple[dict[str, int], tuple[str, ...]]:
        values = read_back(list(handler.registers), list(handler.tail), word_order)
        return values, status_names(values["STATUS"])

    return table


def written_table(sink: Sink) -> Callable[[], tuple[dict[str, int], tuple[str, ...], dict[str, Any]] | None] | None:
    """A reader of the image a client-mode PLC output last wrote to the PLC (by name,
    the STATUS bits set, and ``{"source": "written", "acknowledged": bool}``), for a view
    beside the PLC (the web console's register block); None for a sink that writes
    none (server mode serves its block: :func:`served_table`).  A supervised sink is
    read through to its instance at each call: a restarted writer's image is shown,
    none while the output is down."""
    from .client import PlcWriter

    if not isinstance(getattr(sink, "inner", sink), PlcWriter):
        return None

    def table() -> tuple[dict[str, int], tuple[str, ...], dict[str, Any]] | None:
        writer = getattr(sink, "inner", sink)
        if not isinstance(writer, PlcWriter):
            return None  # the output is down
        word_order = writer.settings.word_order
        written = writer.last_written()
        if written is None:
            return None
        registers, tail, acknowledged = written
        values = read_back(list(registers), list(tail), word_order)
        return values, status_names(values["STATUS"]), {"source": "written", "acknowledged": acknowledged}

    return table
