"""An output whose own thread dies stops the bridge with a failure (exit 1 from the
command) and one error line, instead of leaving that output dead in silence (before:
paho's thread died of ``struct.error``, the Sparkplug output stopped, nothing was
logged, exit 0).  The thread is paho's own, on a real broker; what kills it is an
exception from its message callback, which paho re-raises (a bug of ours would)."""

from __future__ import annotations

import subprocess
import threading

from eskin_industrial.bridge.config import BridgeConfig, LogSettings, NodeConfig, resolve
from eskin_industrial.bridge.logs import EventLog
from eskin_industrial.bridge.runtime import Bridge
from eskin_industrial.outputs.sparkplug.options import SparkplugOptions
from tests.helpers import sparkplug as spb
from tests.helpers.bridge import PAPER, LogCapture, wait_for
from tests.helpers.modbus import need


def test_a_dead_paho_thread_stops_the_bridge_with_a_failure_and_one_error_line(tmp_path):
    node = NodeConfig.of("grip", PAPER, "scene", scene="case2")
    with spb.broker(tmp_path) as port:
        config = BridgeConfig((node,), {"sparkplug": SparkplugOptions(f"mqtt://127.0.0.1:{port}", "g", "e")},
                              LogSettings(format="json", status_every_s=0))
        capture = LogCapture()
        log = EventLog(capture, "json", "debug")
        bridge = Bridge(config, resolve(config), log)
        before = threading.excepthook
        try:
            bridge.open()
            bridge.start()
            sup = threading.Thread(target=bridge.wait, kwargs={"tick_s": 0.02}, daemon=True)
            sup.start()
            device = bridge.runs[0].sinks[0]
            wait_for(lambda: device.health().connected, timeout_s=10, what="connected")

            def bug(*_: object) -> None:
                raise RuntimeError("a bug in a callback")

            device.node.client.on_message = bug  # type: ignore[attr-defined]
            subprocess.run([need("mosquitto_pub"), "-h", "127.0.0.1", "-p", str(port), "-t", "spBv1.0/g/NCMD/e",
                            "-m", "x"], check=True, timeout=10)
            sup.join(10)
            assert not sup.is_alive(), "the bridge went on without its Sparkplug output"
        finally:
            bridge.stop()
            log.close()
    assert threading.excepthook is before
    assert "RuntimeError: a bug in a callback" in bridge.failure
    (failed,) = capture.events("thread_failed")
    assert failed["level"] == "error" and "paho" in failed["thread"]
    assert capture.events("stopped")[0]["reason"] == "failure"
