"""A loop that stops turning leaves no verdict standing (eskin_industrial/bridge/stall.py).

An essential output is called on the loop's thread; here the recorder, made essential,
hangs in ``publish``.  The PLC's server answers from its own thread all the while: its
block must stop claiming the grasp within ``loop_stall_s`` (and the 20 ms tick of the
supervision), and claim it again once the loop turns.  A PLC client polls the served
block every 4 ms throughout.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Any

from eskin_industrial.bridge.config import BridgeConfig, LogSettings, NodeConfig, SupervisionSettings
from eskin_industrial.outputs.plc.image import Status
from eskin_industrial.outputs.plc.options import PlcOptions
from eskin_industrial.outputs.recorder.kind import RecorderOptions
from tests.helpers.bridge import PAPER, BlockPoller, running_bridge, wait_for
from tests.helpers.modbus import free_port
from tests.helpers.paths import ROOT
from tests.helpers.stalls import StallMeter

STALL_S = 0.3
CASE2 = ROOT / "eskin_industrial" / "scenes" / "builtin" / "case2.toml"


def _config(tmp_path: Path, port: int) -> BridgeConfig:
    node = NodeConfig.of("grip", PAPER, "scene", scene=str(CASE2))
    outputs: dict[str, Any] = {"plc": PlcOptions(mode="server", host="127.0.0.1", port=port),
                               "recorder": RecorderOptions(path=str(tmp_path / "rec.csv"))}
    return BridgeConfig((node,), outputs, LogSettings(format="json", status_every_s=0),
                        supervision=SupervisionSettings(essential=("plc", "recorder"), loop_stall_s=STALL_S))


def test_a_hung_essential_output_withdraws_the_verdict_until_its_loop_turns(tmp_path: Path) -> None:
    port = free_port()
    release = threading.Event()
    with StallMeter() as stalls, running_bridge(_config(tmp_path, port)) as r, BlockPoller(port) as plc:
        wait_for(lambda: plc.reads and plc.reads[-1][1] & Status.DATA_VALID and plc.reads[-1][1] & Status.STABLE,
                 timeout_s=20, what="the grasp held and valid")
        sink = next(s for s in r.bridge.runs[0].sinks if s.kind == "recorder")
        sink.inner.publish = lambda *_: release.wait(30)  # type: ignore[method-assign]
        hung = time.perf_counter()
        wait_for(lambda: r.log.events("loop_stalled"), timeout_s=5, what="loop_stalled")
        time.sleep(0.3)
        released = time.perf_counter()
        release.set()
        wait_for(lambda: r.log.events("loop_resumed"), timeout_s=5, what="loop_resumed")
        wait_for(lambda: plc.reads[-1][1] & Status.DATA_VALID, timeout_s=5, what="valid again")
        time.sleep(0.1)
        reads = list(plc.reads)
    (stalled,) = r.log.events("loop_stalled")
    (resumed,) = r.log.events("loop_resumed")
    assert stalled["loop"] == "node-grip" and stalled["node"] == "grip" and stalled["level"] == "error", stalled
    assert STALL_S <= stalled["for_s"] and resumed["after_s"] >= STALL_S, (stalled, resumed)
    # The publish that hangs is the one due at the next scan (within 10 ms) or refresh:
    # past the limit, the tick, and any pause of this whole process, nothing is claimed.
    allowed = STALL_S + 0.1 + stalls.longest(hung, released)
    during = [(t, s) for t, s, _, _ in reads if hung + allowed < t < released]
    assert during, "no read while the loop was stuck"
    claimed = [(round(t - hung, 3), Status(s)) for t, s in during if s & (Status.DATA_VALID | Status.STABLE)]
    assert not claimed, claimed[:5]
    assert all(s & Status.BRIDGE_OFFLINE for _, s in during)
    after = [s for t, s, _, _ in reads if t > released]
    assert after and after[-1] & Status.DATA_VALID and after[-1] & Status.STABLE
    # the PLC was answered all along (by the server's own thread)
    assert max(b - a for a, b in zip([t for t, *_ in reads], [t for t, *_ in reads][1:])) < 0.25


def test_a_loop_that_turns_is_never_taken_for_stalled(tmp_path: Path) -> None:
    port = free_port()
    with running_bridge(_config(tmp_path, port)) as r, BlockPoller(port) as plc:
        wait_for(lambda: plc.reads and plc.reads[-1][1] & Status.DATA_VALID, timeout_s=20, what="valid")
        time.sleep(1.5)
    assert not r.log.events("loop_stalled")
