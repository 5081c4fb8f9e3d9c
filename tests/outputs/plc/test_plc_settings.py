"""The PLC's settings live with the PLC output: ``[plc]`` of the bridge configuration.
A profile's ``[modbus.plc]`` of earlier releases that still gives them loads, with
exactly one deprecation line per key naming its new place, and its value is used as
before where ``[plc]`` leaves the key unset: the served registers, read by pymodbus'
client with functions 3 and 4, are the same byte for byte either way.  ``profile
show``, ``profile check`` and the bridge's ``--check`` name the new places."""

from __future__ import annotations

import os
import subprocess
import sys
import warnings
from dataclasses import replace
from pathlib import Path

import pytest
from pymodbus.client import ModbusTcpClient

from eskin_industrial.bridge.config import BridgeConfig, LogSettings, NodeConfig
from eskin_industrial.errors import DeprecatedKey
from eskin_industrial.outputs.plc.image import IMAGE_COUNT, REG, Status
from eskin_industrial.outputs.plc.options import PlcOptions
from eskin_industrial.profile import PLC_MOVED_OUT, parse_profile
from tests.helpers.bridge import PAPER, running_bridge, wait_for
from tests.helpers.modbus import free_port

#: A value for every key that moved (valid, and none of them the default).
MOVED_VALUES = {"mode": '"client"', "unit_id": "7", "host": '"127.0.0.2"', "port": "1503", "bind": '"127.0.0.3"',
                "timeout_s": "0.7", "backoff_s": "0.2", "backoff_max_s": "3.0", "max_connections": "4",
                "idle_timeout_s": "30.0", "allow_read": '["127.0.0.0/8"]', "allow_write": '["127.0.0.1"]',
                "read_only": "true", "unit_ids": "[7, 8]"}
#: The registers that move on their own while nothing else does (the heartbeat, the scan's age).
MOVING = {REG["HEARTBEAT"].offset, REG["FRAME_AGE"].offset}


def _with_plc_keys(lines: str) -> str:
    return Path(PAPER).read_text().replace("[modbus.plc]\n", f"[modbus.plc]\n{lines}\n", 1)


def test_every_moved_key_warns_once_naming_its_place_in_plc_and_still_applies() -> None:
    assert set(MOVED_VALUES) == set(PLC_MOVED_OUT)
    text = _with_plc_keys("\n".join(f"{k} = {v}" for k, v in MOVED_VALUES.items()))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        prof = parse_profile(text, "old.toml")
    lines = [str(w.message) for w in caught]
    assert all(issubclass(w.category, DeprecatedKey) for w in caught)
    assert lines == [f"old.toml: [modbus.plc] {k} is deprecated: write [plc] {PLC_MOVED_OUT[k]} in the bridge "
                     f"configuration (bridge.toml)" for k in MOVED_VALUES]
    assert "write [plc] host" in lines[list(MOVED_VALUES).index("bind")]  # where server mode listens
    plc = prof.modbus.plc
    assert (plc.mode, plc.unit_id, plc.port, plc.bind, plc.read_only, plc.unit_ids) == \
        ("client", 7, 1503, "127.0.0.3", True, (7, 8))


def test_the_register_image_keys_stay_the_profile_s_without_a_warning() -> None:
    text = _with_plc_keys("")  # paper-5x5 gives base_address, word_order and r_scale
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        prof = parse_profile(text.replace("base_address = 0", "base_address = 50"), "p.toml")
    assert prof.modbus.plc.base_address == 50


def _served(profile: str, plc: PlcOptions, port: int) -> tuple[list[int], list[int], bool]:
    """Holding and input registers of the block at unit 7 once the idle scene's data are
    valid, and whether unit 1 is refused."""
    node = NodeConfig.of("grip", profile, "scene", scene="idle")
    config = BridgeConfig(node=(node,), outputs={"plc": plc}, log=LogSettings(format="json", status_every_s=0))
    with running_bridge(config) as run, ModbusTcpClient("127.0.0.1", port=port, timeout=3) as client:
        wait_for(lambda: run.block(0)["STATUS"] & Status.DATA_VALID, 10, "valid data")
        holding = client.read_holding_registers(0, count=IMAGE_COUNT, device_id=7)
        inputs = client.read_input_registers(0, count=IMAGE_COUNT, device_id=7)
        other = client.read_holding_registers(0, count=1, device_id=1)
    assert not holding.isError() and not inputs.isError(), (holding, inputs)
    return holding.registers, inputs.registers, other.isError()


@pytest.mark.slow
def test_the_same_bytes_are_served_from_the_old_profile_key_and_the_new_plc_key(tmp_path: Path) -> None:
    port = free_port()
    old = tmp_path / "old.toml"
    old.write_text(_with_plc_keys(f'unit_id = 7\nport = {port}\nbind = "127.0.0.1"'))
    with pytest.warns(DeprecatedKey) as seen:
        from_profile = _served(str(old), PlcOptions(mode="server"), port)
    assert sorted(str(w.message).split(": ", 1)[1] for w in seen) == [
        f"[modbus.plc] {k} is deprecated: write [plc] {v} in the bridge configuration (bridge.toml)"
        for k, v in (("bind", "host"), ("port", "port"), ("unit_id", "unit_id"))]
    port = free_port()
    from_plc = _served(PAPER, PlcOptions(mode="server", host="127.0.0.1", port=port, unit_id=7), port)
    for got in (from_profile, from_plc):
        assert got[2], "unit 1 answered: unit_id = 7 not applied"

    def still(regs: list[int]) -> list[int]:
        return [v for i, v in enumerate(regs) if i not in MOVING]

    assert still(from_profile[0]) == still(from_plc[0]) and still(from_profile[1]) == still(from_plc[1])
    # and [plc] wins over the profile's key
    with pytest.warns(DeprecatedKey):
        port = free_port()
        both = _served(str(old), PlcOptions(mode="server", host="127.0.0.1", port=port, unit_id=7), port)
    assert still(both[0]) == still(from_plc[0])


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "eskin_industrial", *args], capture_output=True, text=True,
                          timeout=60, env=dict(os.environ, PYTHONPATH=os.getcwd()))


def test_profile_show_check_and_bridge_check_name_the_new_places(tmp_path: Path) -> None:
    show = _cli("profile", "show", "paper-5x5")
    assert show.returncode == 0, show.stderr
    plc = show.stdout.split("[modbus.plc]\n", 1)[1].split("\n\n", 1)[0]
    assert plc.splitlines() == ["base_address = 0", 'word_order = "big"', "r_scale = 100.0"], plc
    assert "the PLC's connection and the device identity are the bridge configuration's: [plc] mode, unit_id, host, " \
           "port" in show.stdout and "; [identity]" in show.stdout
    old = tmp_path / "old.toml"
    old.write_text(_with_plc_keys("read_only = true"))
    warn = (f"eskin-bus: warning: {old}: [modbus.plc] read_only is deprecated: write [plc] read_only in the bridge "
            f"configuration (bridge.toml)")
    checked = _cli("profile", "check", str(old))
    assert checked.returncode == 0 and checked.stderr.splitlines() == [warn], checked.stderr
    shown = _cli("profile", "show", str(old))  # a key the file still gives is shown where it is
    assert "read_only = true" in shown.stdout.split("[modbus.plc]\n", 1)[1].split("\n\n", 1)[0]
    bridge = _cli("bridge", "-p", str(old), "--source", "scene:idle", "--plc", f"serve:127.0.0.1:{free_port()}",
                  "--check")
    assert bridge.returncode == 0, bridge.stderr
    assert bridge.stderr.splitlines().count(warn) == 1, bridge.stderr


def test_plc_section_takes_unit_id_and_refuses_a_bad_one() -> None:
    from eskin_industrial.bridge.config import parse_bridge_config
    from eskin_industrial.errors import ProfileError

    nodes = f'[[node]]\nname = "grip"\nprofile = "{PAPER}"\nsource = "scene"\nscene = "idle"\n'
    config = parse_bridge_config('[plc]\nmode = "server"\nunit_id = 7\n' + nodes, "b.toml")
    assert config.outputs["plc"] == replace(PlcOptions(mode="server"), unit_id=7)
    with pytest.raises(ProfileError, match=r"^b\.toml: \[plc\] unit_id: expected a value in \[0, 255\]"):
        parse_bridge_config('[plc]\nunit_id = 300\n' + nodes, "b.toml")
