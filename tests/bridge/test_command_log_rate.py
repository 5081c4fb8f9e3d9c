"""A client that writes commands as fast as the link goes floods neither the bridge's
log nor its journal: one ``plc_command`` line per node and command per 10 s, every
command counted (``commands``).  (The DCMD lines of Sparkplug are limited the same
way, with the same Throttle: tests/outputs/sparkplug/test_sparkplug_commands.py; past ``command_rate`` a
DCMD is dropped before it is decoded, counted and logged the same way:
tests/outputs/sparkplug/test_sparkplug_floods.py.)"""

from __future__ import annotations

import struct
import subprocess
import time

from eskin_industrial.bridge.config import NodeConfig
from eskin_industrial.outputs.plc.image import REG
from tests.helpers.bridge import running_bridge, server_config, wait_for
from tests.helpers.paths import PROFILES
from tests.helpers.raw_modbus import ask, connect

ENABLE = REG["ENABLE"].offset


def test_a_flood_of_enable_writes_is_a_few_log_lines_and_every_one_counted():
    node = NodeConfig.of("grip", str(PROFILES / "paper-5x5.toml"), "scene", scene="case2")
    with running_bridge(server_config(node)) as run:
        port = run.bridge.server.server.port  # type: ignore[union-attr]
        with connect(port) as plc:
            t0 = time.monotonic()
            writes = 0
            while time.monotonic() - t0 < 1.5:  # ENABLE 0, 1, 0, 1, ...: each one a change
                value = writes % 2
                resp = ask(plc, struct.pack(">BHH", 6, ENABLE, value), tid=writes & 0xFFFF)
                assert resp[0] == 6, resp.hex()
                writes += 1
                wait_for(lambda v=value: run.bridge.runs[0].loop.status.enabled == bool(v), timeout_s=2)
        counted = run.counters("grip").get("commands")
        lines = run.log.events("plc_command")
    assert writes >= 20, "the flood was too slow to mean anything"
    assert sorted(e["command"] for e in lines) == ["disable", "enable"]
    assert all(e["held_back"] == 0 for e in lines)
    assert counted == writes, "every command counted"


def test_a_flood_of_dcmds_is_a_few_log_lines_and_every_one_counted(tmp_path):
    from eskin_industrial.bridge.config import BridgeConfig, LogSettings
    from eskin_industrial.outputs.sparkplug.options import SparkplugOptions
    from tests.helpers import sparkplug as spb
    from tests.helpers.modbus import need
    from tests.outputs.sparkplug.test_sparkplug_commands import _dcmd

    node = NodeConfig.of("grip", str(PROFILES / "paper-5x5.toml"), "scene", scene="case2")
    payload = tmp_path / "ack.bin"
    payload.write_bytes(_dcmd(Acknowledge_Slip=True))
    with spb.broker(tmp_path) as port:
        config = BridgeConfig((node,), {"sparkplug": SparkplugOptions(f"mqtt://127.0.0.1:{port}", "g", "e")},
                              LogSettings(format="json", status_every_s=0))
        with running_bridge(config) as run:
            wait_for(lambda: run.counters("grip")["sparkplug_connects"] >= 1, timeout_s=10, what="connected")
            subprocess.run([need("mosquitto_pub"), "-h", "127.0.0.1", "-p", str(port), "-q", "1", "-t",
                            "spBv1.0/g/DCMD/e/grip", "-f", str(payload), "--repeat", "300", "--repeat-delay", "0"],
                           check=True, timeout=30)
            # taken, or past command_rate dropped undecoded: each one counted
            wait_for(lambda: run.counters("grip")["sparkplug_commands"] + run.counters("grip")[
                "sparkplug_commands_shed"] == 300, timeout_s=10, what="all counted")
            lines = run.log.events("sparkplug_command")
            shed = run.log.events("sparkplug_commands_shed")
    assert len(lines) == 1 and lines[0]["held_back"] == 0
    assert len(shed) <= 1 and all(e["held_back"] == 0 for e in shed)
