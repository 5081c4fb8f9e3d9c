"""What a strict client reads of the server itself, with asyncua's client: the
endpoints' and FindServers' ApplicationType Server (not ClientAndServer: the bridge
is no client), ServerCapabilities filled (the profile, the locale, the sample rate,
the continuation points), and EngineeringUnits on every value with a unit."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from eskin_industrial.bridge.config import NodeConfig
from eskin_industrial.outputs.opcua import model
from tests.helpers.bridge import PAPER, running_bridge
from tests.helpers.opcua import NAMESPACE_URI, opcua_config

pytestmark = pytest.mark.slow


def test_the_server_says_what_it_is_and_every_value_with_a_unit_says_which() -> None:
    from asyncua import Client, ua

    config = opcua_config(NodeConfig.of("grip", PAPER, "scene", scene="idle"))
    url = config.outputs["opcua"].endpoint

    async def read() -> dict[str, Any]:
        async with Client(url, timeout=10) as client:
            ns = await client.get_namespace_index(NAMESPACE_URI)
            endpoints = await client.get_endpoints()
            servers = await client.find_servers()
            caps = {}
            for name in ("ServerProfileArray", "LocaleIdArray", "MinSupportedSampleRate",
                         "MaxBrowseContinuationPoints", "MaxQueryContinuationPoints", "MaxHistoryContinuationPoints"):
                node = client.get_node(ua.NodeId(getattr(ua.ObjectIds, f"Server_ServerCapabilities_{name}")))
                caps[name] = (await node.read_data_value()).Value
            units = {}
            for v in model.VARIABLES:
                if v.unit:
                    node = client.get_node(ua.NodeId(f"grip.{v.path.replace('/', '.')}.EngineeringUnits", ns))
                    units[v.path] = await node.read_value()
            return dict(endpoints=endpoints, servers=servers, caps=caps, units=units)

    with running_bridge(config):
        got = asyncio.run(asyncio.wait_for(read(), 60))
    assert got["endpoints"] and {e.Server.ApplicationType for e in got["endpoints"]} == {ua.ApplicationType.Server}
    assert got["servers"] and {s.ApplicationType for s in got["servers"]} == {ua.ApplicationType.Server}
    caps = got["caps"]
    assert caps["ServerProfileArray"].Value == ["http://opcfoundation.org/UA-Profile/Server/MicroEmbeddedDevice2017"]
    assert caps["ServerProfileArray"].VariantType == ua.VariantType.String and caps["LocaleIdArray"].Value == ["en"]
    assert caps["MinSupportedSampleRate"] == ua.Variant(0.0, ua.VariantType.Double)
    for name in ("MaxBrowseContinuationPoints", "MaxQueryContinuationPoints", "MaxHistoryContinuationPoints"):
        assert caps[name] == ua.Variant(0, ua.VariantType.UInt16), name
    with_units = {v.path for v in model.VARIABLES if v.unit}
    assert {"Health/FrameAge", "TotalForce", "CentreOfForceX", "CentreOfForceY"} <= with_units
    assert set(got["units"]) == with_units
    for path, eu in got["units"].items():
        v = model.VARIABLES[model.INDEX[path]]
        assert isinstance(eu, ua.EUInformation), path
        assert (eu.NamespaceUri, eu.UnitId, eu.DisplayName.Text) == (model.UNECE_NAMESPACE, model.UNITS[v.unit][0],
                                                                      v.unit), path
