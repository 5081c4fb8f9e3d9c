"""The embedded default: the whole chain in one process, nothing to install or start.

A sensor node plays a scene onto python-can's in-process ``virtual`` bus (real-time
pacing, heartbeat); the bridge decodes the scans, detects, and writes the register
image over Modbus TCP on loopback into a PLC stand-in whose example gripper logic
raises the grip force when the slip bit comes.
"""

from __future__ import annotations

import os
import socket
import threading
import time
from collections.abc import Callable
from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from ..bridge.config import BridgeConfig, NodeConfig, ResolvedNode
from ..bridge.loop import NodeLoop
from ..bridge.runtime import SingleNode
from ..bus.can.layout import CanLayout
from ..bus.can.reader import open_bus
from ..calibration import Calibrator
from ..detect.updates import Update, UpdateTable
from ..evaluation.metrics import SceneScore, score_scene
from ..outputs.plc.image import STATUS_COUNT, TAIL_AT, TAIL_COUNT, read_back, status_names
from ..outputs.plc.options import PlcOptions
from ..outputs.web.sink import WebSink, web_sinks
from ..profile import Profile
from ..scenes import Rendered
from ..view.live import change_line
from .can_node import CanNode, Faults
from .plc import PlcSimulator

if TYPE_CHECKING:
    from ..outputs.plc.client import PlcWriter


@dataclass
class DemoResult:
    updates: list[Update] = field(default_factory=list)
    score: SceneScore | None = None
    latencies_s: list[float] = field(default_factory=list)
    counters: dict[str, int] = field(default_factory=dict)
    plc_status_changes: int = 0
    grip_raises: int = 0


@dataclass(frozen=True)
class DemoParts:
    """The running chain, for a live view that watches it (``run_demo(live=...)``)."""

    profile: Profile
    loop: NodeLoop
    plc: PlcSimulator
    channel: str
    started: float  #: ``time.monotonic()`` at the start


def show_the_scene(sink: WebSink, rec: Rendered, plc: PlcSimulator) -> None:
    """The web console's node page: the scene's own onsets (its detection delays) and
    the register block as the PLC stand-in holds it."""
    onsets = [(float(e.t_s), "slip" if e.kind in ("slide", "rotate") else "variable_force")
              for e in rec.spec.events if e.kind not in ("press", "release")]
    sink.set_truth(onsets)
    word_order = plc.settings.word_order

    def registers() -> tuple[dict[str, int], tuple[str, ...]]:
        regs = list(plc.memory.regs)
        values = read_back(regs[:STATUS_COUNT], regs[TAIL_AT:TAIL_AT + TAIL_COUNT], word_order)
        return values, tuple(status_names(values["STATUS"]))

    sink.set_registers(registers)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def run_demo(profile: Profile, rec: Rendered, say: Callable[[str], None], plc_echo: Callable[[str], None] | None,
             drain_s: float = 1.0,
             live: Callable[[DemoParts], AbstractContextManager[object]] | None = None,
             outputs: dict[str, Any] | None = None, ready: Callable[[], None] | None = None) -> DemoResult:
    """Run the chain until the node has played ``rec`` and ``drain_s`` more.

    The bridge side is the product's own: the CAN source and the PLC client sink of a
    one-node bridge configuration, and the per-node loop, on this thread.  ``live``,
    when given, is entered once the chain is up and left before it is torn down (also
    on Ctrl-C or an error): a live view that only reads the chain's newest values.
    ``outputs``: more output kinds beside the PLC (``--web``: the web console, shown
    the scene's own onsets and the registers the PLC stand-in received).  ``ready`` is
    called once the outputs listen, before the node sends its first scan (what
    announces the console's address: a browser sent there at once finds it up).
    """
    layout = CanLayout.from_profile(profile, fd=False)
    raw = np.rint(Calibrator.from_section(profile.calibration, profile.taxels).to_raw(rec.forces))
    port = free_port()
    channel = f"eskin-demo-{os.getpid()}-{port}"
    result = DemoResult()

    def observed(u: Update) -> None:
        if not result.updates or u.state != result.updates[-1].state:
            truth = rec.labels[min(int(np.searchsorted(rec.t, u.t)), len(rec.t) - 1)]
            say(f"{change_line(u)}   (truth: {truth})")
        result.updates.append(u)

    node = NodeConfig.of("demo", profile.source, "can", rate_hz=rec.rate_hz, interface="virtual", channel=channel,
                         fd=False)
    cfg = BridgeConfig(node=(node,), outputs={"plc": PlcOptions(mode="client", host="127.0.0.1", port=port),
                                              **(outputs or {})})
    plc = PlcSimulator(profile.modbus.plc, "127.0.0.1", port, echo=plc_echo).start()
    try:
        single = SingleNode(cfg, ResolvedNode(node, profile), on_update=observed)
    except BaseException:
        plc.stop()
        raise
    loop = single.loop
    writer = cast("PlcWriter", loop.sinks[0])  # the first output: the PLC in client mode
    for web in web_sinks(loop.sinks):
        show_the_scene(web, rec, plc)
    if ready is not None:
        ready()
    tx = open_bus("virtual", channel)
    sim = CanNode(layout, tx, raw, rec.rate_hz, profile.can.heartbeat_s, Faults(), False, 1, None)
    node_thread = threading.Thread(target=sim.run, name="demo-node", daemon=True)
    parts = DemoParts(profile, loop, plc, channel, time.monotonic())
    try:
        with single, live(parts) if live is not None else nullcontext():
            node_thread.start()
            while node_thread.is_alive():
                loop.step()
            end = time.monotonic() + drain_s
            while time.monotonic() < end:
                loop.step()
    finally:
        node_thread.join(timeout=5)
        tx.shutdown()
        single.close()
        plc.stop()
    result.counters = loop.counters()
    result.latencies_s = list(writer.stats.latencies_s)
    result.plc_status_changes = len(plc.status_changes)
    result.grip_raises = plc.gripper.raises
    if result.updates:
        result.score = score_scene(UpdateTable.from_updates(result.updates), rec.t, rec.labels)
    return result
