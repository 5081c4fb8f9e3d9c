"""The bridge's configuration file: a valid one loads and plans; every bad one is one
ProfileError line naming the file and the key, and the command exits 2 before it
opens anything."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from eskin_industrial.bridge.config import load_bridge_config, resolve
from eskin_industrial.errors import ProfileError
from eskin_industrial.profile import STALE_FLOOR_S, load_profile
from tests.helpers.bridge import PAPER
from tests.helpers.modbus import free_port

TWO_NODES = """
[log]
format = "json"

[plc]
mode = "server"
host = "127.0.0.1"
port = {port}

[[node]]
name = "left"
profile = "{profile}"
interface = "virtual"
channel = "shared"
[node.plc]
base_address = 0

[[node]]
name = "right"
profile = "{profile}"
interface = "virtual"
channel = "shared"
base_id = 0x210
node_id = 2
[node.plc]
base_address = 100
"""


def write(tmp_path: Path, text: str, name: str = "bridge.toml", port: int = 15999) -> Path:
    path = tmp_path / name
    path.write_text(text.format(profile=PAPER, port=port))
    return path


def bad(tmp_path: Path, old: str, new: str) -> Path:
    text = TWO_NODES.replace(old, new, 1)
    assert text != TWO_NODES, f"{old!r} not in the template"
    return write(tmp_path, text, "bad.toml")


def test_a_valid_two_node_file_loads_with_each_nodes_overrides(tmp_path):
    path = write(tmp_path, TWO_NODES)
    cfg = load_bridge_config(path)
    assert cfg.source == str(path) and cfg.log.format == "json" and cfg.outputs["plc"].mode == "server"
    nodes = resolve(cfg)
    assert [n.name for n in nodes] == ["left", "right"]
    assert [n.profile.can.base_id for n in nodes] == [0x200, 0x210]
    assert [n.profile.can.node_id for n in nodes] == [1, 2]
    assert [n.profile.modbus.plc.base_address for n in nodes] == [0, 100]
    assert nodes[0].share_key == nodes[1].share_key  # one bus, one reader
    # the profile keeps its own path through the overrides (messages name it)
    assert all(n.profile.source == PAPER for n in nodes)


def test_a_relative_profile_path_is_taken_from_the_files_folder(tmp_path):
    (tmp_path / "profiles").mkdir()
    (tmp_path / "profiles" / "p.toml").write_text(Path(PAPER).read_text())
    path = write(tmp_path, TWO_NODES.replace('"{profile}"', '"profiles/p.toml"'))
    nodes = resolve(load_bridge_config(path))
    assert nodes[0].profile.sensor.name == "paper-5x5"


def test_keys_that_moved_still_load_with_one_warning_naming_the_new_spelling(tmp_path):
    """``base_address`` in a ``[[node]]`` is the PLC's now (``[node.plc]``), and the
    profile's ``[modbus.plc] refresh_s`` / ``stale_s`` every output's (``[output]``):
    an older file still loads, the same, with one deprecation line per key."""
    from eskin_industrial.errors import DeprecatedKey

    old = TWO_NODES.replace("[node.plc]\nbase_address = 100", "base_address = 100")
    with pytest.warns(DeprecatedKey) as seen:
        nodes = resolve(load_bridge_config(write(tmp_path, old)))
    assert [n.profile.modbus.plc.base_address for n in nodes] == [0, 100]
    assert [str(w.message) for w in seen] == [
        f"{tmp_path / 'bridge.toml'}: [node[1]] base_address is deprecated: write [node.plc] base_address"]
    both = TWO_NODES.replace("[node.plc]\nbase_address = 100", "base_address = 100\n[node.plc]\nbase_address = 100")
    with pytest.raises(ProfileError, match=r"\[node\[1\]\] base_address: deprecated, and \[node.plc\] base_address is "
                                           r"given too; keep \[node.plc\] base_address only"):
        load_bridge_config(write(tmp_path, both, "both.toml"))
    profile = Path(PAPER).read_text().replace("\nrefresh_s = 0.05\n", "\n")
    profile = profile.replace("r_scale = 100.0\n", "r_scale = 100.0\nrefresh_s = 0.2\nstale_s = 0.5\n", 1)
    (tmp_path / "old.toml").write_text(profile)
    with pytest.warns(DeprecatedKey) as seen:
        loaded = load_profile(tmp_path / "old.toml")
    assert loaded.output.refresh_s == 0.2 and loaded.stale_s == 0.5
    assert sorted(str(w.message).split(": ", 1)[1] for w in seen) == [
        "[modbus.plc] refresh_s is deprecated: write [output] refresh_s",
        "[modbus.plc] stale_s is deprecated: write [output] stale_s"]


def test_a_slower_node_than_its_profile_gets_its_own_stale_limit(tmp_path):
    """A node's rate_hz override also moves the stale limit (2.5 periods of the node's
    rate): with the profile's 100 Hz limit (25 ms), a 20 Hz node would read stale
    between every two scans."""
    path = write(tmp_path, TWO_NODES.replace('node_id = 2', 'node_id = 2\nrate_hz = 20.0'))
    left, right = resolve(load_bridge_config(path))
    assert left.profile.stale_s == pytest.approx(0.025)
    assert right.rate_hz == 20.0 and right.profile.stale_s == pytest.approx(0.125)


def test_a_fast_node_is_not_stale_within_the_interpreters_switch_interval(tmp_path):
    """At 1 kHz 2.5 periods are 2.5 ms, less than the 5 ms for which the interpreter
    may run another of the bridge's threads: the default limit has a floor of 20 ms
    (from 125 Hz down the periods decide); a limit the profile sets is kept."""
    assert STALE_FLOOR_S >= 4 * sys.getswitchinterval()
    path = write(tmp_path, TWO_NODES.replace('node_id = 2', 'node_id = 2\nrate_hz = 1000.0'))
    left, right = resolve(load_bridge_config(path))
    assert left.profile.stale_s == pytest.approx(0.025)  # 100 Hz: 2.5 periods
    assert right.rate_hz == 1000.0 and right.profile.stale_s == pytest.approx(STALE_FLOOR_S)
    fast = Path(PAPER).read_text().replace("rate_hz = 100.0", "rate_hz = 1000.0", 1)
    assert "rate_hz = 1000.0" in fast
    (tmp_path / "fast.toml").write_text(fast)
    assert load_profile(tmp_path / "fast.toml").stale_s == pytest.approx(STALE_FLOOR_S)
    (tmp_path / "set.toml").write_text(fast.replace("[output]\n", "[output]\nstale_s = 0.004\n", 1))
    assert load_profile(tmp_path / "set.toml").stale_s == pytest.approx(0.004)


@pytest.mark.parametrize("old, new, expected", [
    ('channel = "shared"', 'chanel = "shared"', "bad.toml: [node[0]] chanel: unknown key; did you mean 'channel'?"),
    ('base_id = 0x210', 'base_id = 0x208',
     "bad.toml: [node 'right'] base_id: 0x208 overlaps node 'left' at 0x200 on the same bus"),
    ('base_address = 100', 'base_address = 10',
     "bad.toml: [node 'right'] plc.base_address: 10 overlaps the block of node 'left' at 0"),
    ('name = "right"', 'name = "left"', "bad.toml: [node] name: 'left' is used by two nodes"),
    ('interface = "virtual"\nchannel = "shared"\n[node.plc]', 'source = "can-log"\n[node.plc]',
     "bad.toml: [node[0]] path: missing key (source = 'can-log' needs it)"),
    ('profile = "{profile}"', 'profile = "no-such-profile.toml"',
     "bad.toml: [node 'left'] profile: "),
    ('port = {port}', 'port = 70000', "bad.toml: [plc] port:"),
    ('format = "json"', 'format = "xml"', "bad.toml: [log] format:"),
])
def test_each_bad_file_is_one_line_naming_file_and_key(tmp_path, old, new, expected):
    path = bad(tmp_path, old, new)
    with pytest.raises(ProfileError) as err:
        resolve(load_bridge_config(path))
    msg = str(err.value)
    assert "\n" not in msg and str(tmp_path / "bad.toml") in msg, msg
    assert expected.split("bad.toml", 1)[1] in msg, msg
    if "no-such-profile" in new:  # the node's line, then the profile's own message
        assert msg.endswith("no-such-profile.toml: cannot read profile: No such file or directory"), msg


def test_two_rtu_nodes_on_one_serial_port_are_refused(tmp_path):
    text = f"""
[plc]
mode = "server"
[[node]]
name = "a"
profile = "{PAPER}"
source = "modbus-rtu"
serial_port = "/dev/ttyS9"
[[node]]
name = "b"
profile = "{PAPER}"
source = "modbus-rtu"
serial_port = "/dev/ttyS9"
[node.plc]
base_address = 100
"""
    path = tmp_path / "rtu.toml"
    path.write_text(text)
    with pytest.raises(ProfileError, match=r"rtu\.toml: \[node\] serial_port: '/dev/ttyS9' is used by two nodes"):
        resolve(load_bridge_config(path))


def test_a_node_profile_that_does_not_validate_names_the_node(tmp_path):
    broken = tmp_path / "broken.toml"
    broken.write_text(Path(PAPER).read_text().replace("rate_hz = 100.0", "rate_hz = -5", 1))
    path = write(tmp_path, TWO_NODES.replace('"{profile}"', f'"{broken}"', 1), "bad.toml")
    with pytest.raises(ProfileError) as err:
        resolve(load_bridge_config(path))
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith(f"{path}: [node 'left'] profile: {broken}"), msg
    assert "rate_hz" in msg


def cli(*args: str, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "eskin_industrial", "bridge", *args], capture_output=True,
                          text=True, timeout=timeout, env=dict(os.environ, PYTHONUNBUFFERED="1"))


def test_the_command_refuses_a_bad_file_with_one_line_and_starts_nothing(tmp_path):
    port = free_port()
    path = write(tmp_path, TWO_NODES.replace('base_address = 100', 'base_address = 10'), "bad.toml", port=port)
    res = cli("--config", str(path), "--duration", "5")
    assert res.returncode == 2, res.stderr
    lines = res.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("eskin-bus: error: ") and str(path) in lines[0], res.stderr
    assert "base_address" in lines[0] and res.stdout == ""
    # nothing was started: no log line, and the configured port was never taken
    assert "start" not in res.stderr
    with socket.socket() as s:
        s.bind(("127.0.0.1", port))


def test_check_prints_the_plan_and_exits(tmp_path):
    port = free_port()
    path = write(tmp_path, TWO_NODES, port=port)
    res = cli("--config", str(path), "--check")
    assert res.returncode == 0, res.stderr
    lines = res.stdout.splitlines()
    assert len(lines) == 2 and res.stderr == ""
    assert lines[0].startswith("left: paper-5x5 (") and PAPER in lines[0]
    assert "100 Hz, can virtual shared ids 0x200+16 -> PLC server block at 0" in lines[0]
    assert "ids 0x210+16 -> PLC server block at 100" in lines[1]
    with socket.socket() as s:  # --check opens nothing
        s.bind(("127.0.0.1", port))


def test_command_line_errors(tmp_path):
    res = cli("-p", PAPER, "--source", "carrier-pigeon:x", "--check")
    assert res.returncode == 2 and "unknown source kind 'carrier-pigeon'" in res.stderr
    res = cli("-p", PAPER, "--plc", "udp:1.2.3.4:5", "--check")
    assert res.returncode == 2 and "unknown PLC kind 'udp'" in res.stderr
    res = cli("--check")
    assert res.returncode == 2 and "give --config FILE, or --profile P" in res.stderr
    res = cli("-p", PAPER, "--source", "scene:case2", "--plc", "serve:127.0.0.1:1502", "--check")
    assert res.returncode == 0 and "scene case2 -> PLC server block at 0" in res.stdout, res.stderr


def test_a_file_with_moved_keys_is_one_warning_line_each_and_runs(tmp_path):
    """From the command line: ``--check`` says each moved key in one line on stderr and
    passes; ``profile check`` too; a run logs it as an event in the log's own format."""
    old_profile = Path(PAPER).read_text().replace("\nrefresh_s = 0.05\n", "\n").replace(
        "r_scale = 100.0\n", "r_scale = 100.0\nrefresh_s = 0.05\n", 1)
    (tmp_path / "old.toml").write_text(old_profile)
    port = free_port()
    path = write(tmp_path, TWO_NODES.replace("[node.plc]\nbase_address = 100", "base_address = 100").replace(
        '"{profile}"', '"old.toml"'), port=port)
    res = cli("--config", str(path), "--check")
    assert res.returncode == 0, res.stderr
    assert res.stderr.splitlines() == [
        f"eskin-bus: warning: {path}: [node[1]] base_address is deprecated: write [node.plc] base_address",
        f"eskin-bus: warning: {tmp_path / 'old.toml'}: [modbus.plc] refresh_s is deprecated: write [output] refresh_s"]
    checked = subprocess.run([sys.executable, "-m", "eskin_industrial", "profile", "check", str(tmp_path / "old.toml")],
                             capture_output=True, text=True, timeout=60)
    assert checked.returncode == 0 and checked.stdout.startswith(f"{tmp_path / 'old.toml'}: ok")
    assert checked.stderr == (f"eskin-bus: warning: {tmp_path / 'old.toml'}: [modbus.plc] refresh_s is deprecated: "
                              "write [output] refresh_s\n")
    run = cli("--config", str(path), "--duration", "0.2")
    events = [json.loads(line) for line in run.stderr.splitlines() if line.startswith("{")]
    moved = [e for e in events if e["event"] == "deprecated_key"]
    assert len(moved) == 2 and moved[0]["level"] == "warning" and "[node.plc] base_address" in moved[0]["message"]
