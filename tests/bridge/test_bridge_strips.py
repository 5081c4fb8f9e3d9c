"""The hand wired strip by strip: four 1 x 5 nodes on one CAN bus, one bridge, four
register blocks. Each block must say what its strip alone says offline."""
from __future__ import annotations

import io
import threading
import uuid

import numpy as np
import pytest

from eskin_industrial import load_profile
from eskin_industrial.bridge.config import load_bridge_config, resolve
from eskin_industrial.bridge.logs import EventLog
from eskin_industrial.bridge.runtime import Bridge
from eskin_industrial.bus.can.layout import CanLayout
from eskin_industrial.bus.can.reader import open_bus
from eskin_industrial.calibration import Calibrator
from eskin_industrial.detect.state import GraspState
from eskin_industrial.frames import RawScan
from eskin_industrial.modbus.pymodbus_io import TcpMaster
from eskin_industrial.outputs.plc.image import REG, join32
from eskin_industrial.pipeline import Pipeline
from eskin_industrial.scenes import render
from eskin_industrial.sim.can_node import CanNode, Faults
from tests.helpers.bridge import wait_for
from tests.helpers.modbus import free_port
from tests.helpers.paths import ROOT

EXAMPLE = ROOT / "examples" / "deploy" / "hand-strips.toml"


def offline_slips(profile, raw: np.ndarray, rate: float) -> int:
    """Entries into slip for one strip, through the pipeline offline (the batch answer)."""
    pipe, state, entries = Pipeline(profile, rate), None, 0
    for k, row in enumerate(raw):
        for u in pipe.push(RawScan(k, k / rate, row)):
            entries += u.state == GraspState.SLIP and state != GraspState.SLIP
            state = u.state
    return entries


@pytest.mark.slow
def test_four_strips_on_one_bus_each_to_its_own_block(tmp_path):
    # The shipped example, moved onto a virtual bus and a free loopback port.
    ch, port = f"strips-{uuid.uuid4().hex[:8]}", free_port()
    text = EXAMPLE.read_text().replace('"socketcan"', '"virtual"').replace('"can0"', f'"{ch}"')
    text = text.replace('"192.168.10.5"', '"127.0.0.1"').replace("port = 1502", f"port = {port}")
    text = text.replace('"192.168.10.0/24"', '"127.0.0.1"').replace('"192.168.10.20"', '"127.0.0.1"')
    assert "192.168." not in text
    text = text.replace("../../profiles/", f"{ROOT / 'profiles'}/")
    (tmp_path / "strips.toml").write_text(text)
    cfg = load_bridge_config(tmp_path / "strips.toml")
    nodes = resolve(cfg)
    assert [n.name for n in nodes] == ["index", "middle", "ring", "little"]

    rate = 100.0
    strip = load_profile(ROOT / "profiles" / "strip-1x5.toml")
    rec = render("hand", rate, 3)  # the hand sequence on the 4 x 5 array: row = finger
    cal = Calibrator.from_section(strip.calibration, 5)
    raws = [np.rint(cal.to_raw(rec.forces[:, 5 * i: 5 * i + 5])) for i in range(4)]
    expected = [offline_slips(strip, raw, rate) for raw in raws]
    assert sum(expected) >= 4  # the final slip shows on every finger

    log_text = io.StringIO()
    log = EventLog(log_text, "json")
    bridge = Bridge(cfg, nodes, log).open()
    bridge.start()
    senders = []
    try:
        for n, raw in zip(nodes, raws):
            layout = CanLayout.from_profile(n.profile, fd=False)
            tx = open_bus("virtual", ch)
            # Burst: as fast as the bus takes them; scan times come from the sequence
            # counters, so the detector sees the same signal as at 100 Hz.
            node = CanNode(layout, tx, raw, rate, n.profile.can.heartbeat_s, Faults(), True, 1, None)
            t = threading.Thread(target=node.run, daemon=True)
            t.start()
            senders.append((t, tx))
        for t, _ in senders:
            t.join(timeout=60)
        wait_for(lambda: all(c["scans"] == len(rec.t) for c in bridge.counters().values()), 60.0,
                 "every strip's scans through the bridge")
        master = TcpMaster("127.0.0.1", port, 1, 1.0)
        master.connect()
        try:
            for n, want in zip(nodes, expected):
                base = n.profile.modbus.plc.base_address
                regs = master.read_holding(base, REG["FLAGS"].offset)
                at = REG["SLIP_EVENTS"].offset
                assert join32(regs[at: at + 2], "big") == want, n.name
        finally:
            master.close()
        counters = bridge.counters()
        for name in ("index", "middle", "ring", "little"):
            c = counters[name]
            assert c["lost_scans"] == 0 and c["malformed_frames"] == 0 and c["torn_scans"] == 0
            assert c["unrouted_frames"] == 0
    finally:
        for _, tx in senders:
            tx.shutdown()
        bridge.stop()
        log.close()
