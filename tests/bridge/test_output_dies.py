"""An output whose own thread dies is that output's failure, not the bridge's: one
error line (``output_failed``, the output named), the output closed and opened again
after its back-off (``output_restarted``), the bridge going on; with ``[supervision]
on_failure = "stop"`` the bridge stops with a failure (exit 1 from the command) and one
error line, as before supervision.  (Before either: paho's thread died of
``struct.error``, the Sparkplug output stopped, nothing was logged, exit 0.)  The
thread is paho's own, on a real broker; what kills it is an exception from its
message callback, which paho re-raises (a bug of ours would)."""

from __future__ import annotations

import subprocess
import threading

import pytest

from eskin_industrial.bridge.config import BridgeConfig, LogSettings, NodeConfig, SupervisionSettings, resolve
from eskin_industrial.bridge.logs import EventLog
from eskin_industrial.bridge.runtime import Bridge
from eskin_industrial.outputs.sparkplug.options import SparkplugOptions
from tests.helpers import sparkplug as spb
from tests.helpers.bridge import PAPER, LogCapture, wait_for
from tests.helpers.modbus import need


def _kill_paho(device: object, port: int) -> None:
    def bug(*_: object) -> None:
        raise RuntimeError("a bug in a callback")

    device.node.client.on_message = bug  # type: ignore[attr-defined]
    subprocess.run([need("mosquitto_pub"), "-h", "127.0.0.1", "-p", str(port), "-t", "spBv1.0/g/NCMD/e",
                    "-m", "x"], check=True, timeout=10)


@pytest.mark.parametrize("on_failure", ["restart", "stop"])
def test_a_dead_paho_thread_restarts_the_sparkplug_output_or_stops_the_bridge_as_configured(tmp_path, on_failure):
    node = NodeConfig.of("grip", PAPER, "scene", scene="case2")
    with spb.broker(tmp_path) as port:
        config = BridgeConfig((node,), {"sparkplug": SparkplugOptions(f"mqtt://127.0.0.1:{port}", "g", "e")},
                              LogSettings(format="json", status_every_s=0),
                              supervision=SupervisionSettings(on_failure=on_failure, backoff_s=0.2))
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
            first = device.inner
            _kill_paho(device, port)
            if on_failure == "stop":
                sup.join(10)
                assert not sup.is_alive(), "the bridge went on without its Sparkplug output"
            else:
                wait_for(lambda: capture.events("output_restarted"), timeout_s=10, what="restarted")
                wait_for(lambda: device.health().connected, timeout_s=10, what="connected again")
                assert device.inner is not first and sup.is_alive() and not bridge.failure
                assert bridge.counters()["grip"]["sparkplug_output_restarts"] == 1
        finally:
            bridge.stop()
            log.close()
    assert threading.excepthook is before
    if on_failure == "stop":
        assert "RuntimeError: a bug in a callback" in bridge.failure
        (failed,) = capture.events("thread_failed")
        assert failed["level"] == "error" and "paho" in failed["thread"]
        assert capture.events("stopped")[0]["reason"] == "failure"
        assert not capture.events("output_failed")
    else:
        (failed,) = capture.events("output_failed")
        assert failed["level"] == "error" and failed["output"] == "sparkplug" and "paho" in failed["call"]
        assert "RuntimeError: a bug in a callback" in failed["error"]
        assert not capture.events("thread_failed")
        assert capture.events("stopped")[0]["reason"] == "end"
