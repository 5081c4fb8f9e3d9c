"""What ``eskin-bus receive`` runs, for the CAN tests that drive it in-process."""

from __future__ import annotations

from eskin_industrial.bridge.loop import NodeLoop
from eskin_industrial.bus.can.group import CanGroup
from eskin_industrial.bus.can.layout import ScanAssembler
from eskin_industrial.bus.can.source import CanSource
from eskin_industrial.outputs.base import Sink


class Kept(Sink):
    """Every update as the loop hands it to a sink (``receive -o``'s rows)."""

    def __init__(self) -> None:
        super().__init__()
        self.updates: list = []

    def on_update(self, update) -> None:
        self.updates.append(update)


class Receiver:
    """What ``eskin-bus receive`` runs: a CAN source (reader, group, assembler) and the
    per-node loop, with every update kept: the detector's own (``updates``), and as
    ``receive -o`` writes them (``shown``: no verdict under a sensor fault)."""

    def __init__(self, profile, reader, layout, rate, log=None) -> None:
        group = CanGroup(reader, [layout], log, all_frames=True)
        self.source = CanSource(group, group.queues[0], ScanAssembler(layout, rate))
        self.updates: list = []
        kept = Kept()
        self.shown = kept.updates
        self.loop = NodeLoop(profile, self.source, [kept], rate_hz=rate, on_update=self.updates.append)
        self.pipeline, self.assembler, self.reader = self.loop.pipeline, self.source.assembler, reader

    def run(self, **until) -> None:
        """As the command: until a stop condition, then the reader stops and what it
        had queued is still decoded."""
        self.source.start()
        try:
            self.loop.run(**until)
        finally:
            self.source.end_reception(self.loop.step)
            self.source.close()

    def poll(self) -> None:
        """Decode whatever the reader has queued."""
        self.source.start()
        self.loop.step(0.0)
        while self.source.pending:
            self.loop.step(0.0)

    def counters(self) -> dict[str, int]:
        return self.source.counters()
