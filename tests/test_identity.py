"""The device identity: one ``[identity]`` section of the bridge configuration, read by
the PLC server's device identification (FC43/14, read with pymodbus' client) and by
the OPC UA nameplate of each node (read with asyncua's client) alike; a profile's
``[modbus.plc.identity]`` of earlier releases still loads, with one deprecation line
per key naming its new place, and is used when the configuration has none."""

from __future__ import annotations

import asyncio
import warnings
from dataclasses import replace
from pathlib import Path

import pytest
from pymodbus.client import ModbusTcpClient

from eskin_industrial import __version__
from eskin_industrial.bridge.config import NodeConfig, parse_bridge_config
from eskin_industrial.errors import DeprecatedKey, ProfileError
from eskin_industrial.identity import DeviceIdentity
from eskin_industrial.outputs.plc.options import PlcOptions
from eskin_industrial.profile import parse_profile
from tests.helpers.bridge import PAPER, running_bridge
from tests.helpers.modbus import free_port
from tests.helpers.opcua import NAMESPACE_URI, opcua_config

ACME = DeviceIdentity(vendor_name="Acme Tactile", product_code="AT-5X5", revision="2.3",
                      vendor_url="https://acme.example", product_name="Acme grip bridge", model_name="Fingertip 5")
OLD_IDENTITY = '\n[modbus.plc.identity]\nvendor_name = "Old Vendor"\nproduct_code = "OLD-1"\n'


def _legacy_profile(tmp_path: Path) -> Path:
    path = tmp_path / "old.toml"
    path.write_text(Path(PAPER).read_text() + OLD_IDENTITY)
    return path


def _fc43(port: int) -> dict[int, str]:
    """Objects 0 to 6 of the device identification (regular and extended streams)."""
    with ModbusTcpClient("127.0.0.1", port=port, timeout=3) as client:
        reply = client.read_device_information(read_code=2, object_id=0, device_id=1)
        assert not reply.isError(), reply
        return {k: v.decode() for k, v in reply.information.items()}


def _nameplate(url: str, node: str) -> dict[str, str]:
    from asyncua import Client, ua

    async def read() -> dict[str, str]:
        async with Client(url, timeout=10) as client:
            ns = await client.get_namespace_index(NAMESPACE_URI)
            out = {}
            for name in ("Manufacturer", "Model", "ProductCode", "SoftwareRevision", "ProductInstanceUri"):
                value = await client.get_node(ua.NodeId(f"{node}.Identification.{name}", ns)).read_value()
                out[name] = value.Text if isinstance(value, ua.LocalizedText) else value
            return out

    return asyncio.run(asyncio.wait_for(read(), 30))


def _bridge(tmp_path: Path, profile: str, identity: DeviceIdentity | None):
    config = opcua_config(NodeConfig.of("grip", profile, "scene", scene="idle"))
    plc = PlcOptions(mode="server", host="127.0.0.1", port=free_port())
    return replace(config, outputs={**config.outputs, "plc": plc}, identity=identity)


def test_a_profile_identity_key_is_deprecated_once_each_naming_the_identity_section() -> None:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        prof = parse_profile(Path(PAPER).read_text() + OLD_IDENTITY, "old.toml")
    lines = [str(w.message) for w in caught if issubclass(w.category, DeprecatedKey)]
    assert lines == [
        "old.toml: [modbus.plc.identity] vendor_name is deprecated: write [identity] vendor_name in the bridge "
        "configuration (bridge.toml)",
        "old.toml: [modbus.plc.identity] product_code is deprecated: write [identity] product_code in the bridge "
        "configuration (bridge.toml)",
    ]
    assert (prof.modbus.plc.identity.vendor_name, prof.modbus.plc.identity.product_code) == ("Old Vendor", "OLD-1")


def test_the_bridge_configuration_reads_identity_and_names_a_bad_key() -> None:
    nodes = f'[[node]]\nname = "grip"\nprofile = "{PAPER}"\nsource = "scene"\nscene = "idle"\n'
    config = parse_bridge_config('[identity]\nvendor_name = "Acme Tactile"\nrevision = "2.3"\n' + nodes, "b.toml")
    assert config.identity == DeviceIdentity(vendor_name="Acme Tactile", revision="2.3")
    assert parse_bridge_config(nodes, "b.toml").identity is None
    with pytest.raises(ProfileError) as bad:
        parse_bridge_config('[identity]\nvendor = "x"\n' + nodes, "b.toml")
    assert str(bad.value).startswith("b.toml: [identity] vendor: unknown key"), bad.value


@pytest.mark.slow
def test_fc43_and_the_opcua_nameplate_both_read_the_identity_section(tmp_path: Path) -> None:
    config = _bridge(tmp_path, PAPER, ACME)
    with running_bridge(config):
        fc43 = _fc43(config.outputs["plc"].port)
        plate = _nameplate(config.outputs["opcua"].endpoint, "grip")
    assert fc43 == {0: "Acme Tactile", 1: "AT-5X5", 2: "2.3", 3: "https://acme.example", 4: "Acme grip bridge",
                    5: "Fingertip 5"}
    assert plate == {"Manufacturer": "Acme Tactile", "Model": "Fingertip 5", "ProductCode": "AT-5X5",
                     "SoftwareRevision": "2.3", "ProductInstanceUri": "urn:Acme-Tactile:AT-5X5:grip"}


@pytest.mark.slow
def test_without_an_identity_section_a_profile_identity_still_applies_and_the_section_wins_over_it(
        tmp_path: Path) -> None:
    old = str(_legacy_profile(tmp_path))
    for identity, vendor, code in ((None, "Old Vendor", "OLD-1"), (ACME, "Acme Tactile", "AT-5X5")):
        config = _bridge(tmp_path, old, identity)
        with pytest.warns(DeprecatedKey) as seen, running_bridge(config):
            fc43 = _fc43(config.outputs["plc"].port)
            plate = _nameplate(config.outputs["opcua"].endpoint, "grip")
        assert len(seen) == 2 and "write [identity] vendor_name" in str(seen[0].message)
        assert (fc43[0], fc43[1], plate["Manufacturer"], plate["ProductCode"]) == (vendor, code, vendor, code)
        if identity is None:  # the blanks filled as ever: the version, the sensor's name
            assert (fc43[2], fc43[5], plate["Model"]) == (__version__, "paper-5x5", "paper-5x5")


@pytest.mark.slow
def test_mbpoll_reads_the_identity_section_in_the_report_server_id_over_rtu(tmp_path: Path) -> None:
    from tests.helpers.modbus import mbpoll, pty_pair

    with pty_pair(tmp_path) as (a, b):
        config = opcua_config(NodeConfig.of("grip", PAPER, "scene", scene="idle"))
        rtu = PlcOptions(mode="server", transport="rtu", serial_port=a)
        config = replace(config, outputs={"plc": rtu}, identity=ACME)
        with running_bridge(config):
            out = mbpoll("-m", "rtu", "-b", "115200", "-P", "none", "-a", "1", "-u", "-1", "-o", "2", b)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "Acme Tactile Acme grip bridge 2.3" in out.stdout, out.stdout
