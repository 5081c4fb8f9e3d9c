"""The Call service as a strict client meets it (Part 4, 5.11.2): each request built by
hand with asyncua's client, so that the arguments go on the wire as given.  Too many
arguments: BadTooManyArguments; an argument of the wrong type: BadInvalidArgument with
BadTypeMismatch for it and Good for the others; a method that is not the object's:
BadMethodInvalid; an object that does not exist: BadNodeIdUnknown.  A refused call
never reaches the node's loop."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from eskin_industrial.bridge.config import NodeConfig
from tests.helpers.bridge import PAPER, running_bridge
from tests.helpers.opcua import NAMESPACE_URI, opcua_config

pytestmark = pytest.mark.slow


def test_methods_check_their_arguments_and_their_object() -> None:
    from asyncua import Client, ua

    config = opcua_config(NodeConfig.of("grip", PAPER, "scene", scene="idle"))
    url = config.outputs["opcua"].endpoint
    boolean, int32 = ua.VariantType.Boolean, ua.VariantType.Int32

    async def calls() -> dict[str, Any]:
        async with Client(url, timeout=10) as client:
            ns = await client.get_namespace_index(NAMESPACE_URI)
            grip = ua.NodeId("grip", ns)

            def request(obj: ua.NodeId, method: ua.NodeId | str, *args: ua.Variant) -> ua.CallMethodRequest:
                mid = ua.NodeId(f"grip.{method}", ns) if isinstance(method, str) else method
                return ua.CallMethodRequest(ObjectId=obj, MethodId=mid, InputArguments=list(args))

            alarm = ua.NodeId("grip.SlipAlarm", ns)
            acknowledge = ua.NodeId(ua.ObjectIds.AcknowledgeableConditionType_Acknowledge)
            asked = {
                "Tare(true)": request(grip, "Tare", ua.Variant(True, boolean)),
                "AcknowledgeSlip(1,2)": request(grip, "AcknowledgeSlip", ua.Variant(1, int32), ua.Variant(2, int32)),
                "Enable(true,true)": request(grip, "Enable", ua.Variant(True, boolean), ua.Variant(True, boolean)),
                "Enable()": request(grip, "Enable"),
                "Enable(1)": request(grip, "Enable", ua.Variant(1, int32)),
                "Enable([true])": request(grip, "Enable", ua.Variant([True], boolean)),
                "Acknowledge(1, comment)": request(alarm, acknowledge, ua.Variant(1, int32),
                                                   ua.Variant(ua.LocalizedText("x"), ua.VariantType.LocalizedText)),
                "Server.GetMonitoredItems on grip": request(grip, ua.NodeId(ua.ObjectIds.Server_GetMonitoredItems),
                                                            ua.Variant(1, ua.VariantType.UInt32)),
                "grip.Nothing": request(grip, "Nothing"),
                "Tare on no object": request(ua.NodeId("nothing", ns), "Tare"),
                "AcknowledgeSlip()": request(grip, "AcknowledgeSlip"),
                "Enable(true)": request(grip, "Enable", ua.Variant(True, boolean)),
            }
            results = await client.uaclient.call(list(asked.values()))
            return dict(zip(asked, results))

    with running_bridge(config) as run:
        got = asyncio.run(asyncio.wait_for(calls(), 60))
        counters = run.counters("grip")
    codes = {k: (r.StatusCode.name, [c.name for c in r.InputArgumentResults or []]) for k, r in got.items()}
    assert codes == {
        "Tare(true)": ("BadTooManyArguments", []),
        "AcknowledgeSlip(1,2)": ("BadTooManyArguments", []),
        "Enable(true,true)": ("BadTooManyArguments", []),
        "Enable()": ("BadArgumentsMissing", []),
        "Enable(1)": ("BadInvalidArgument", ["BadTypeMismatch"]),
        "Enable([true])": ("BadInvalidArgument", ["BadTypeMismatch"]),
        "Acknowledge(1, comment)": ("BadInvalidArgument", ["BadTypeMismatch", "Good"]),
        "Server.GetMonitoredItems on grip": ("BadMethodInvalid", []),
        "grip.Nothing": ("BadMethodInvalid", []),
        "Tare on no object": ("BadNodeIdUnknown", []),
        "AcknowledgeSlip()": ("Good", []),
        "Enable(true)": ("Good", ["Good"]),
    }, codes
    # only the two good calls reached the node
    assert counters["opcua_method_calls"] == 2 and counters["opcua_commands"] == 2
    assert counters["opcua_calls_refused"] == 10
