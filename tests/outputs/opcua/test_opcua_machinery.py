"""What a Machinery-aware client finds, with asyncua's client: the companion
specifications loaded (DI, IA, Machinery, from the shipped NodeSet2 files), our
namespace still at index 2; each node under OPC 40001-1's Machines folder with its
nameplate and its two state machines, CurrentState and CurrentState/Id driven from
the bridge's state."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from eskin_industrial import __version__
from eskin_industrial.bridge.config import NodeConfig
from eskin_industrial.outputs.opcua import companions, model
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
    assert [uris.index(u) for u in (companions.DI_URI, companions.IA_URI, companions.MACHINERY_URI)] == [3, 4, 5]
    assert {companions.DI_URI, companions.IA_URI, companions.MACHINERY_URI} <= set(uris)
    assert got["machines"].Name == "Machines" and got["nameplate"].Name == "MachineIdentificationType"
    assert got["device"].Name == "DeviceType"


def test_a_machinery_client_finds_the_node_its_nameplate_and_its_states() -> None:
    from asyncua import Client, Node, ua

    config = opcua_config(NodeConfig.of("grip", PAPER, "scene", scene="idle"))
    url = config.outputs["opcua"].endpoint

    async def state(client: Client, machine: Node) -> tuple[str, str, str]:
        """(CurrentState, the browse name of the state its Id names, the Id's namespace URI)."""
        current = await machine.get_child("0:CurrentState")
        state_id = await current.get_child("0:Id")
        target = await state_id.read_value()
        uris = await client.get_namespace_array()
        return ((await current.read_value()).Text, (await client.get_node(target).read_browse_name()).Name,
                uris[target.NamespaceIndex])

    async def browse() -> dict[str, Any]:
        async with Client(url, timeout=10) as client:
            m = await client.get_namespace_index(companions.MACHINERY_URI)
            di = await client.get_namespace_index(companions.DI_URI)
            ours = await client.get_namespace_index(NAMESPACE_URI)
            # the standard entry point, by its browse path as a Machinery client finds it
            machines = await client.nodes.objects.get_child(f"{m}:Machines")
            assert machines.nodeid == ua.NodeId(ua.Int32(1001), ua.Int16(m))
            (node,) = await machines.get_children(refs=ua.ObjectIds.Organizes)
            got: dict[str, Any] = {"node": (await node.read_browse_name()).Name,
                                   "type": await node.read_type_definition(), "ours": ours}
            ident = await node.get_child(f"{di}:Identification")
            addins = await node.get_children(refs=ua.ObjectIds.HasAddIn)
            got["ident_is_addin"] = ident in addins
            got["ident_type"] = await ident.read_type_definition()
            got["ident"] = {}
            for child in await ident.get_properties():
                qname = await child.read_browse_name()
                value = await child.read_value()
                got["ident"][(qname.NamespaceIndex, qname.Name)] = value.Text if isinstance(value, ua.LocalizedText) \
                    else value
            blocks = await node.get_child(f"{m}:MachineryBuildingBlocks")
            block_addins = await blocks.get_children(refs=ua.ObjectIds.HasAddIn)
            got["ident_in_blocks"] = ident in block_addins
            got["machines"] = {}
            for machine_name in model.STATE_MACHINES:
                machine = await blocks.get_child(f"{m}:{machine_name}")
                got["machines"][machine_name] = (machine in block_addins, await machine.read_type_definition(),
                                         await state(client, machine))
            # detection disabled: the operation mode follows (Setup), the item state too
            await node.call_method(f"{ours}:Enable", ua.Variant(False, ua.VariantType.Boolean))
            mode = await blocks.get_child(f"{m}:MachineryOperationMode")
            item = await blocks.get_child(f"{m}:MachineryItemState")
            for _ in range(100):
                if (await state(client, mode))[0] == "Setup":
                    break
                await asyncio.sleep(0.05)
            got["disabled"] = (await state(client, mode), await state(client, item))
            got["m"], got["di"] = m, di
            return got

    with running_bridge(config):
        got = asyncio.run(asyncio.wait_for(browse(), 60))
    m, di = got["m"], got["di"]

    assert got["node"] == "grip" and got["type"] == ua.NodeId(ua.Int32(model.TYPE_IDS["GraspSensorType"]),
                                                              ua.Int16(got["ours"]))
    assert got["ident_is_addin"] and got["ident_in_blocks"]
    assert got["ident_type"] == ua.NodeId(ua.Int32(model.MACHINE_IDENTIFICATION_TYPE), ua.Int16(m))
    ident = got["ident"]
    assert set(ident) == {(di, name) for name, _, _ in model.IDENTIFICATION}  # every name in the DI namespace
    assert ident[(di, "Manufacturer")] == "eskin-industrial" and ident[(di, "SerialNumber")] == "grip"
    assert ident[(di, "SoftwareRevision")] == __version__ and ident[(di, "Model")] == "paper-5x5"
    assert ident[(di, "ProductInstanceUri")].endswith(":grip")
    item, mode = got["machines"]["MachineryItemState"], got["machines"]["MachineryOperationMode"]
    assert item[0] and item[1] == ua.NodeId(ua.Int32(1002), ua.Int16(m))  # MachineryItemState_StateMachineType
    assert mode[0] and mode[1] == ua.NodeId(ua.Int32(1008), ua.Int16(m))  # MachineryOperationModeStateMachineType
    # CurrentState/Id names the specification's state object, whose name CurrentState shows
    assert item[2] == ("Executing", "Executing", companions.MACHINERY_URI)
    assert mode[2] == ("Processing", "Processing", companions.MACHINERY_URI)
    assert got["disabled"] == (("Setup", "Setup", companions.MACHINERY_URI),
                               ("NotExecuting", "NotExecuting", companions.MACHINERY_URI))
