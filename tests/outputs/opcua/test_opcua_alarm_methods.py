"""The slip alarm's ConditionType methods (OPC 10000-9, 5.5.4 and 5.5.5) called by
asyncua's client, as a SCADA's alarm console calls them: Disable sets EnabledState
false (its event says Retain false, and a slip while disabled raises nothing),
Enable sets it back, AddComment sets Comment and ClientUserId with an event of its
own; each refusal with the status Part 9 gives it.  The slip comes from a CAN node on
python-can's virtual bus."""

from __future__ import annotations

import asyncio
import time
from typing import Any

import pytest

from tests.helpers.bridge import can_node, channel, node_thread, running_bridge, slip_raw
from tests.helpers.opcua import NAMESPACE_URI, opcua_config
from tests.outputs.opcua.test_opcua_events import _clause, _next, _subscribe

pytestmark = pytest.mark.slow


def _selects() -> list[Any]:
    """EventId, Message, ConditionId, EnabledState/Id, Retain, ActiveState/Id, Comment,
    ClientUserId."""
    from asyncua import ua

    base, condition = ua.ObjectIds.BaseEventType, ua.ObjectIds.ConditionType
    return [_clause(base, ["EventId"]), _clause(base, ["Message"]), _clause(condition, None, ua.AttributeIds.NodeId),
            _clause(condition, ["EnabledState", "Id"]), _clause(condition, ["Retain"]),
            _clause(ua.ObjectIds.AlarmConditionType, ["ActiveState", "Id"]), _clause(condition, ["Comment"]),
            _clause(condition, ["ClientUserId"])]


def test_disable_enable_and_add_comment_work_as_part_9_says(paper_profile: Any) -> None:
    from asyncua import Client, ua

    ch = channel()
    config = opcua_config(can_node("grip", ch))
    raw, _ = slip_raw(paper_profile)
    url = config.outputs["opcua"].endpoint
    text = ua.VariantType.LocalizedText

    async def scenario(node: Any) -> dict[str, Any]:
        async with Client(url, timeout=10) as client:
            ns = await client.get_namespace_index(NAMESPACE_URI)
            cond = ua.NodeId("grip.SlipAlarm", ns)
            alarm = client.get_node(cond)
            own = {name: (await alarm.get_child(f"0:{name}")).nodeid for name in ("Disable", "Enable", "AddComment")}
            declared = {"Disable": ua.NodeId(ua.ObjectIds.ConditionType_Disable),
                        "Enable": ua.NodeId(ua.ObjectIds.ConditionType_Enable),
                        "AddComment": ua.NodeId(ua.ObjectIds.ConditionType_AddComment),
                        "Acknowledge": ua.NodeId(ua.ObjectIds.AcknowledgeableConditionType_Acknowledge)}
            events: asyncio.Queue[list[Any]] = asyncio.Queue()
            (item,) = await _subscribe(client, _selects(), events)
            assert item.StatusCode.is_good()
            codes: dict[str, str] = {}

            async def call(what: str, method: ua.NodeId, *args: ua.Variant) -> None:
                (result,) = await client.uaclient.call([ua.CallMethodRequest(ObjectId=cond, MethodId=method,
                                                                             InputArguments=list(args))])
                codes[what] = result.StatusCode.name

            def comment(event_id: bytes, words: str) -> tuple[ua.Variant, ua.Variant]:
                return ua.Variant(event_id, ua.VariantType.ByteString), ua.Variant(ua.LocalizedText(words), text)

            await call("Enable, enabled", declared["Enable"])
            await call("Disable", own["Disable"])
            disabled = await _next(events, lambda f: "disabled" in f[1].Value.Text, 10, "the Disable's event")
            await call("Disable, disabled", declared["Disable"])
            await call("AddComment, disabled", own["AddComment"], *comment(disabled[0].Value, "x"))
            await call("Acknowledge, disabled", declared["Acknowledge"], *comment(disabled[0].Value, "x"))
            node.start()  # the slip, at about 1.5 s, while the alarm is disabled
            slips = client.get_node(ua.NodeId("grip.Counters.SlipEvents", ns))
            deadline = time.monotonic() + 20
            while (await slips.read_data_value(raise_on_bad_status=False)).Value.Value in (None, 0):
                assert time.monotonic() < deadline, "no slip within 20 s"
                await asyncio.sleep(0.05)
            await asyncio.sleep(0.3)
            while_disabled = [events.get_nowait() for _ in range(events.qsize())]
            await call("Enable", own["Enable"])
            enabled = await _next(events, lambda f: "enabled" in f[1].Value.Text, 10, "the Enable's event")
            await call("Enable, enabled again", own["Enable"])
            await call("AddComment, an unknown EventId", declared["AddComment"], *comment(b"nope", "x"))
            await call("AddComment", declared["AddComment"], *comment(enabled[0].Value, "checked the gripper"))
            commented = await _next(events, lambda f: "comment" in f[1].Value.Text, 10, "the comment's event")
            read = {path: (await alarm.get_child([f"0:{p}" for p in path.split("/")])).read_value()
                    for path in ("EnabledState/Id", "Comment", "ClientUserId")}
            values = {path: await value for path, value in read.items()}
            node.join(20)
            return dict(ns=ns, cond=cond, codes=codes, disabled=disabled, while_disabled=while_disabled,
                        enabled=enabled, commented=commented, values=values)

    with running_bridge(config) as run, node_thread(paper_profile, ch, raw) as node:
        got = asyncio.run(asyncio.wait_for(scenario(node), 60))
        counters = run.counters("grip")
    assert got["codes"] == {
        "Enable, enabled": "BadConditionAlreadyEnabled",
        "Disable": "Good",
        "Disable, disabled": "BadConditionAlreadyDisabled",
        "AddComment, disabled": "BadConditionDisabled",
        "Acknowledge, disabled": "BadConditionDisabled",
        "Enable": "Good",
        "Enable, enabled again": "BadConditionAlreadyEnabled",
        "AddComment, an unknown EventId": "BadEventIdUnknown",
        "AddComment": "Good",
    }
    cond = got["cond"]
    disabled, enabled, commented = got["disabled"], got["enabled"], got["commented"]
    assert disabled[2].Value == cond and disabled[3].Value is False and disabled[4].Value is False
    assert got["while_disabled"] == []  # the slip raised nothing while disabled
    assert counters["opcua_alarms"] == 0
    assert enabled[2].Value == cond and enabled[3].Value is True
    assert enabled[4].Value == enabled[5].Value  # retained while the slip is still on, and only then
    assert commented[2].Value == cond and commented[3].Value is True
    assert commented[6].Value.Text == "checked the gripper" and commented[7].Value == "anonymous"
    assert len({disabled[0].Value, enabled[0].Value, commented[0].Value}) == 3  # each event its own EventId
    values = got["values"]
    assert values["EnabledState/Id"] is True and values["Comment"].Text == "checked the gripper"
    assert values["ClientUserId"] == "anonymous"
