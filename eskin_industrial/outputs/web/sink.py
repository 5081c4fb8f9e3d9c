"""The web console's sink: one node's pages on the bridge's console, opened by
:class:`.kind.WebKind` (one server for the bridge, :mod:`.server`); it leaves the
node's snapshots, updates and frames in the node's feed (:mod:`.hub`) and takes back
the commands the operator's page queued.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from ..base import Sink, SinkHealth
from .hub import Truth

if TYPE_CHECKING:
    from ...detect.updates import Update
    from ...frames import Frame
    from ...node import Command, NodeSnapshot
    from .server import RegisterReader, WebServer


def web_sinks(sinks: Sequence[Sink]) -> list[WebSink]:
    """The web console's sinks among a loop's (each as the kind opened it: a supervised
    output's sink holds its instance as ``inner``), for whoever wires the console's
    truth and register block.  (What they are given is kept by the output: a restart's
    fresh instance has it too, :class:`.server.Wiring`.)"""
    out = []
    for sink in sinks:
        inner = getattr(sink, "inner", sink)
        if isinstance(inner, WebSink):
            out.append(inner)
    return out


class WebSink(Sink):
    """One node's pages on the bridge's console (opened by :class:`.kind.WebKind`)."""

    def __init__(self, server: WebServer, index: int, name: str) -> None:
        super().__init__()
        self.server = server
        self.index = index
        self.feed = server.feeds[index]
        self.where = f"{server.options.url}node/{index} ({name})"
        o = server.options
        # every scan when a capture window is kept (its raw scans), else the heat map's interval
        self.frame_every_s = 0.0 if o.capture_pre_s + o.capture_post_s > 0 else o.frame_interval_s

    def on_update(self, update: Update) -> None:
        self.feed.update(update)

    def on_frame(self, frame: Frame) -> None:
        self.feed.frame(frame)

    def _publish(self, snapshot: NodeSnapshot) -> None:
        self.feed.publish(snapshot)

    def take_commands(self) -> list[Command]:
        return self.feed.take_commands()

    def health(self) -> SinkHealth:
        return SinkHealth()  # a server: no connection of its own to lose

    def counters(self) -> dict[str, int]:
        return self.server.counters()

    def set_truth(self, onsets: list[tuple[float, str]], period_s: float | None = None) -> None:
        """The onsets of what the node plays (a demo's scene), for the detection delays."""
        truth = Truth(onsets, period_s)
        self.server.wiring.truths[self.index] = truth
        self.feed.truth = truth

    def set_registers(self, read: RegisterReader) -> None:
        """Where the page's register block comes from: the PLC's registers as the PLC
        reads them (names -> values, the STATUS bits set) or as the bridge last wrote
        them to the PLC (a third element says so: ``{"source": "written",
        "acknowledged": bool}``), handed by whoever wires the PLC beside; without it the
        page has no register block."""
        self.server.registers[self.index] = read
