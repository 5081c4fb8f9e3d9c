"""What a Machinery-aware client finds, with asyncua's client: the companion
specifications loaded (DI, IA, Machinery, from the shipped NodeSet2 files), our
namespace still at index 2."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from eskin_industrial.bridge.config import NodeConfig
from eskin_industrial.outputs.opcua import companions
from tests.helpers.bridge import PAPER, running_bridge
from tests.helpers.opcua import NAMESPACE_URI, opcua_config

pytestmark = pytest.mark.slow


def test_the_companion_specifications_are_loaded_before_our_model() -> None:
    from asyncua import Client

    config = opcua_config(NodeConfig.of("grip", PAPER, "scene", scene="idle"))
    url = config.outputs["opcua"].endpoint

    async def read() -> dict[str, Any]:
        async with Client(url, timeout=10) as client:
            uris = await client.get_namespace_array()
            machinery = uris.index(companions.MACHINERY_URI)
            di = uris.index(companions.DI_URI)
            return dict(
                uris=uris,
                # OPC 40001-1's entry point and nameplate type, OPC 10000-100's device type
                machines=await client.get_node(f"ns={machinery};i=1001").read_browse_name(),
                nameplate=await client.get_node(f"ns={machinery};i=1012").read_browse_name(),
                device=await client.get_node(f"ns={di};i=1002").read_browse_name(),
            )

    with running_bridge(config):
        got = asyncio.run(asyncio.wait_for(read(), 60))
    uris = got["uris"]
    assert uris.index(NAMESPACE_URI) == 2  # ours first: a SCADA's tags keep ns=2
    assert {companions.DI_URI, companions.IA_URI, companions.MACHINERY_URI} <= set(uris)
    assert got["machines"].Name == "Machines" and got["nameplate"].Name == "MachineIdentificationType"
    assert got["device"].Name == "DeviceType"
