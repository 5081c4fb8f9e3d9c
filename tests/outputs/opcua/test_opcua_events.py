"""The slip alarm's events under the event filters strict clients send, built by hand
with asyncua's client so that each field is on the wire as that client writes it:
open62541's ConditionId select clause (TypeDefinitionId ConditionType, AttributeId
NodeId, a null BrowsePath: array length -1), a null where clause, a browse name that
is null; and a select clause that makes asyncua itself raise while the event is
fired.  The slip comes from a CAN node on python-can's virtual bus; every event
arrives with what was selected, and the server serves on."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
from typing import Any

import pytest

from eskin_industrial.outputs.opcua import model
from tests.helpers.bridge import can_node, channel, node_thread, running_bridge, slip_raw
from tests.helpers.opcua import NAMESPACE_URI, opcua_config

pytestmark = pytest.mark.slow


def _clause(type_id: int, path: list[str] | None, attribute: int | None = None) -> Any:
    """A select clause; ``path`` None: a null BrowsePath (asyncua writes a None list as -1)."""
    from asyncua import ua

    op = ua.SimpleAttributeOperand()
    op.TypeDefinitionId = ua.NodeId(type_id)
    op.BrowsePath = None if path is None else [ua.QualifiedName(p, 0) for p in path]  # type: ignore[assignment]
    op.AttributeId = ua.AttributeIds.Value if attribute is None else attribute
    return op


def _selects() -> list[Any]:
    """EventId, EventType, SourceName, Message, ConditionId (as open62541 1.5 selects
    it: a null BrowsePath), ActiveState/Id."""
    from asyncua import ua

    base, condition = ua.ObjectIds.BaseEventType, ua.ObjectIds.ConditionType
    return [_clause(base, ["EventId"]), _clause(base, ["EventType"]), _clause(base, ["SourceName"]),
            _clause(base, ["Message"]), _clause(condition, None, ua.AttributeIds.NodeId),
            _clause(ua.ObjectIds.AlarmConditionType, ["ActiveState", "Id"])]


async def _subscribe(client: Any, selects: list[Any], events: asyncio.Queue[list[Any]],
                     where: Any = None) -> Any:
    """A subscription with one event item on the Server object, its filter as given
    (``where`` None: a ContentFilter whose Elements are a null array); the results of
    CreateMonitoredItems.  Each event's fields go to ``events``."""
    from asyncua import ua

    def on_publish(result: Any) -> None:
        for data in result.NotificationMessage.NotificationData or []:
            if isinstance(data, ua.EventNotificationList):
                for e in data.Events or []:
                    events.put_nowait(list(e.EventFields or []))

    sub = await client.uaclient.create_subscription(ua.CreateSubscriptionParameters(
        RequestedPublishingInterval=10, RequestedLifetimeCount=3000, RequestedMaxKeepAliveCount=100,
        PublishingEnabled=True), on_publish)
    flt = ua.EventFilter()
    flt.SelectClauses = selects
    if where is None:
        where = ua.ContentFilter()
        where.Elements = None  # type: ignore[assignment]
    flt.WhereClause = where
    item = ua.MonitoredItemCreateRequest()
    item.ItemToMonitor = ua.ReadValueId(NodeId=ua.NodeId(ua.ObjectIds.Server), AttributeId=ua.AttributeIds.EventNotifier)
    item.MonitoringMode = ua.MonitoringMode.Reporting
    item.RequestedParameters = ua.MonitoringParameters(ClientHandle=7, SamplingInterval=0, QueueSize=100,
                                                       DiscardOldest=True, Filter=flt)
    params = ua.CreateMonitoredItemsParameters(SubscriptionId=sub.SubscriptionId,
                                               TimestampsToReturn=ua.TimestampsToReturn.Both, ItemsToCreate=[item])
    return await client.uaclient.create_monitored_items(params)


async def _next(events: asyncio.Queue[list[Any]], match: Callable[[list[Any]], bool], timeout_s: float,
                what: str) -> list[Any]:
    deadline = time.monotonic() + timeout_s
    while True:
        left = deadline - time.monotonic()
        assert left > 0, f"no {what} within {timeout_s} s"
        try:
            fields = await asyncio.wait_for(events.get(), left)
        except TimeoutError:
            continue
        if match(fields):
            return fields


def _slip(paper_profile: Any, scenario: Callable[[str, Any], Any]) -> tuple[Any, Any]:
    """The bridge with the OPC UA output on a CAN node that slips at about 1.5 s;
    ``scenario(url, node)`` runs as a client while it does (``node.start()`` is its
    to call).  Its result and the node's counters at the end."""
    ch = channel()
    config = opcua_config(can_node("grip", ch))
    raw, _ = slip_raw(paper_profile)
    url = config.outputs["opcua"].endpoint
    with running_bridge(config) as run, node_thread(paper_profile, ch, raw) as node:
        got = asyncio.run(asyncio.wait_for(scenario(url, node), 60))
        return got, run.counters("grip")


def test_open62541s_condition_id_select_clause_gets_the_condition_and_the_server_serves_on(paper_profile) -> None:
    from asyncua import Client, ua

    async def scenario(url: str, node: Any) -> dict[str, Any]:
        async with Client(url, timeout=10) as client:
            ns = await client.get_namespace_index(NAMESPACE_URI)
            events: asyncio.Queue[list[Any]] = asyncio.Queue()
            (result,) = await _subscribe(client, _selects(), events)
            node.start()
            raised = await _next(events, lambda f: f[5].Value is True, 20, "slip alarm")
            # the server is still serving: the condition acknowledged with the ConditionId
            # received, the alarm's end as an event, a read
            (ack,) = await client.uaclient.call([ua.CallMethodRequest(
                ObjectId=raised[4].Value, MethodId=ua.NodeId(ua.ObjectIds.AcknowledgeableConditionType_Acknowledge),
                InputArguments=[ua.Variant(raised[0].Value, ua.VariantType.ByteString),
                                ua.Variant(ua.LocalizedText("seen"), ua.VariantType.LocalizedText)])])
            acked = await _next(events, lambda f: "acknowledged" in f[3].Value.Text, 10, "the acknowledgement")
            node.join(20)
            cleared = await _next(events, lambda f: f[5].Value is False, 10, "the slip's end")
            state = await client.get_node(f"ns={ns};s=grip.GraspState").read_data_value(raise_on_bad_status=False)
            return dict(ns=ns, result=result, raised=raised, cleared=cleared, state=state, ack=ack, acked=acked)

    got, counters = _slip(paper_profile, scenario)
    ns = got["ns"]
    assert got["result"].StatusCode.is_good()
    raised = got["raised"]
    assert raised[1].Value == ua.NodeId(model.TYPE_IDS["SlipAlarmType"], ns)
    assert raised[2].Value == "grip" and "slip on grip" in raised[3].Value.Text
    assert raised[4].Value == ua.NodeId("grip.SlipAlarm", ns)  # the ConditionId (Part 9, 5.5.2)
    assert raised[4].VariantType == ua.VariantType.NodeId
    assert got["ack"].StatusCode.is_good() and got["acked"][4].Value == ua.NodeId("grip.SlipAlarm", ns)
    assert got["cleared"][4].Value == ua.NodeId("grip.SlipAlarm", ns)
    assert got["state"].Value.Value is not None
    assert counters["opcua_alarms"] == 1 and counters["opcua_alarm_acks"] == 1 and counters["opcua_event_errors"] == 0


def test_a_select_clause_with_a_null_browse_name_is_refused_with_its_result(paper_profile) -> None:
    """Part 4, 7.22.3: the filter is refused (BadEventFilterInvalid) with a result per
    select clause: BadBrowseNameInvalid for the broken one, Good for the others."""
    from asyncua import Client, ua

    async def scenario(url: str, node: Any) -> Any:
        async with Client(url, timeout=10) as client:
            selects = _selects()
            broken = _clause(ua.ObjectIds.BaseEventType, ["Message"])
            broken.BrowsePath[0].Name = None  # a null String on the wire
            bad_attribute = _clause(ua.ObjectIds.BaseEventType, [], 99)
            results = await _subscribe(client, [*selects, broken, bad_attribute], asyncio.Queue())
            # the server still answers and fires to a good filter
            events: asyncio.Queue[list[Any]] = asyncio.Queue()
            (good,) = await _subscribe(client, selects, events)
            node.start()
            raised = await _next(events, lambda f: f[5].Value is True, 20, "slip alarm")
            node.join(20)
            return results, good, raised

    (results, good, raised), _ = _slip(paper_profile, scenario)
    (refused,) = results
    assert refused.StatusCode.value == ua.StatusCodes.BadEventFilterInvalid
    codes = [c.value for c in refused.FilterResult.SelectClauseResults]
    assert codes == [ua.StatusCodes.Good] * 6 + [ua.StatusCodes.BadBrowseNameInvalid,
                                                  ua.StatusCodes.BadAttributeIdInvalid]
    assert good.StatusCode.is_good() and raised[4].Value.Identifier == "grip.SlipAlarm"


def test_an_exception_while_an_event_is_fired_is_counted_and_the_other_subscribers_get_it(paper_profile) -> None:
    """A select clause that names one of asyncua's own attributes of its event objects
    (``data_types``, no field of any event type) makes asyncua raise a KeyError while
    it fills that item's fields: the server counts it, logs it once, and the other
    subscription gets the event."""
    from asyncua import Client, ua

    async def scenario(url: str, node: Any) -> Any:
        async with Client(url, timeout=10) as client:
            breaking: asyncio.Queue[list[Any]] = asyncio.Queue()
            (first,) = await _subscribe(client, [_clause(ua.ObjectIds.BaseEventType, ["data_types"])], breaking)
            events: asyncio.Queue[list[Any]] = asyncio.Queue()
            (second,) = await _subscribe(client, _selects(), events)
            node.start()
            raised = await _next(events, lambda f: f[5].Value is True, 20, "slip alarm")
            cleared = await _next(events, lambda f: f[5].Value is False, 20, "the slip's end")
            node.join(20)
            return first, raised, cleared

    ch = channel()
    config = opcua_config(can_node("grip", ch))
    raw, _ = slip_raw(paper_profile)
    url = config.outputs["opcua"].endpoint
    with running_bridge(config) as run, node_thread(paper_profile, ch, raw) as node:
        first, raised, cleared = asyncio.run(asyncio.wait_for(scenario(url, node), 60))
        counters = run.counters("grip")
        errors = run.log.events("opcua_event_error")
    assert first.StatusCode.is_good()  # (a browse name like any other)
    assert raised[4].Value.Identifier == "grip.SlipAlarm" and cleared[5].Value is False
    assert counters["opcua_event_errors"] >= 2  # raised and cleared, on the Server object
    assert len(errors) == 1 and "KeyError" in errors[0]["detail"]
