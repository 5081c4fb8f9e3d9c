"""PLC outages in the bridge's log: the writer's own start and end events, routed to
the structured log (not guessed by a periodic look at "connected"); and the client
timeout and back-off as settings of ``[plc]``, the profile and the command line."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import pytest

from eskin_industrial.bridge.config import BridgeConfig, LogSettings, NodeConfig, load_bridge_config, resolve
from eskin_industrial.errors import DeprecatedKey, ProfileError
from eskin_industrial.outputs.plc.client import PlcWriter
from eskin_industrial.outputs.plc.legacy import block_settings
from eskin_industrial.outputs.plc.options import PlcOptions
from eskin_industrial.profile import parse_profile
from tests.helpers.bridge import PAPER, running_bridge, wait_for
from tests.helpers.plc_standin import PlcStandIn


def scene_client(port: int, **plc) -> BridgeConfig:
    node = NodeConfig.of("grip", PAPER, "scene", scene="case2")
    return BridgeConfig(node=(node,), outputs={"plc": PlcOptions(mode="client", host="127.0.0.1", port=port, **plc)},
                        log=LogSettings(format="json", status_every_s=0))


def test_a_plc_that_refuses_every_write_is_an_outage_in_the_log_with_its_end(paper_profile):
    """Once a PLC answering exception 02 to everything (a wrong base_address) logged
    only plc_connected, with thousands of failures and no warning."""
    with PlcStandIn("exception", code=2) as plc:
        with running_bridge(scene_client(plc.port)) as run:
            wait_for(lambda: run.log.events("plc_unreachable"), what="plc_unreachable")
            time.sleep(1.0)
            plc.mode = "ok"
            wait_for(lambda: run.log.events("plc_connected"), what="plc_connected")
            c = run.counters("grip")
    (start,), (end,) = run.log.events("plc_unreachable"), run.log.events("plc_connected")
    assert start["level"] == "warning" and start["node"] == "grip" and str(plc.port) in start["plc"]
    assert start["cause"] == "exception" and start["exception"] == 2 and "illegal data address" in start["error"]
    assert end["level"] == "info" and end["node"] == "grip" and end["outage_s"] >= 1.0
    assert end["exceptions"].startswith("02:") and end["superseded"] > 0
    assert c["plc_exception_02"] >= 2 and c["plc_outages"] == 1


def test_timeout_and_back_off_from_plc_section_over_the_profile(paper_profile):
    config = scene_client(1502, timeout_s=1.5, backoff_s=0.2, backoff_max_s=5.0)
    nodes = resolve(config)
    settings = block_settings(config.outputs["plc"], nodes[0].profile.modbus.plc, "client")
    assert (settings.timeout_s, settings.backoff_s, settings.backoff_max_s) == (1.5, 0.2, 5.0)
    writer = PlcWriter(settings, "127.0.0.1", 1502)
    assert writer.timeout_s == 1.5 and writer.master.timeout_s == 1.5 and writer.master.late_s == 1.5
    # unset: the defaults
    plain = block_settings(PlcOptions(mode="client"), nodes[0].profile.modbus.plc, "client")
    assert plain == replace(nodes[0].profile.modbus.plc, mode="client") and plain.timeout_s == 0.5


@pytest.mark.parametrize("key, value, expected", [
    ("timeout_s", "0", "timeout_s: expected a value in [0.01, 30]"),
    ("backoff_s", "100", "backoff_s: expected a value in [0.01, 60]"),
    ("backoff_max_s", "0.05", "[plc] backoff_max_s: expected at least backoff_s"),  # below the profile's 0.1
])
def test_bad_plc_timing_in_the_file_is_one_line(tmp_path, key, value, expected):
    path = tmp_path / "bridge.toml"
    path.write_text(f'[plc]\nmode = "client"\n{key} = {value}\n[[node]]\nname = "grip"\nprofile = "{PAPER}"\n'
                    f'source = "scene"\nscene = "case2"\n')
    with pytest.raises(ProfileError) as err:
        resolve(load_bridge_config(path))
    assert "\n" not in str(err.value) and expected in str(err.value), str(err.value)


def test_bad_timeout_in_the_profile_is_refused():
    text = Path(PAPER).read_text().replace("[modbus.plc]\n", "[modbus.plc]\ntimeout_s = 31\n")
    with pytest.warns(DeprecatedKey, match=r"\[plc\] timeout_s"), \
            pytest.raises(ProfileError, match=r"timeout_s: expected a value in \[0.01, 30\]"):
        parse_profile(text, "p.toml")


def cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "eskin_industrial", "bridge", "-p", PAPER, "--source", "scene:case2",
                           *args], capture_output=True, text=True, timeout=60,
                          env=dict(os.environ, PYTHONUNBUFFERED="1"))


def test_plc_timeout_on_the_command_line():
    ok = cli("--plc", "tcp:127.0.0.1:1502", "--plc-timeout", "2", "--check", "--explain")
    assert ok.returncode == 0, ok.stderr
    assert any("plc.timeout_s" in line and "2" in line and "command line" in line for line in ok.stdout.splitlines())
    bad = cli("--plc-timeout", "0", "--check")
    assert bad.returncode == 2 and "--plc-timeout" in bad.stderr and "0.01 to 30" in bad.stderr, bad.stderr
