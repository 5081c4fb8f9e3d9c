"""Deadbands as a strict client asks for them (Part 4, 7.22.2; Part 8, 6.2), each
DataChangeFilter written by hand with asyncua's client: a Percent deadband on an
analog item is applied from its EURange, one the item cannot take is refused
(BadDeadbandFilterInvalid, BadFilterNotAllowed).  The values come from a CAN node on
python-can's virtual bus going through a slip."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from tests.helpers.bridge import can_node, channel, node_thread, running_bridge, slip_raw
from tests.helpers.opcua import NAMESPACE_URI, opcua_config

pytestmark = pytest.mark.slow


def _item(ua: Any, nodeid: Any, handle: int, deadband: tuple[int, float] | None) -> Any:
    item = ua.MonitoredItemCreateRequest()
    item.ItemToMonitor = ua.ReadValueId(NodeId=nodeid, AttributeId=ua.AttributeIds.Value)
    item.MonitoringMode = ua.MonitoringMode.Reporting
    flt = None
    if deadband is not None:
        flt = ua.DataChangeFilter(Trigger=ua.DataChangeTrigger.StatusValue, DeadbandType=deadband[0],
                                  DeadbandValue=deadband[1])
    item.RequestedParameters = ua.MonitoringParameters(ClientHandle=handle, SamplingInterval=0, QueueSize=1000,
                                                       DiscardOldest=True, Filter=flt)
    return item


def test_a_percent_deadband_is_applied_from_the_eu_range_and_a_wrong_one_refused(paper_profile) -> None:
    from asyncua import Client, ua

    ch = channel()
    config = opcua_config(can_node("grip", ch))
    raw, _ = slip_raw(paper_profile)
    url = config.outputs["opcua"].endpoint
    percent, absolute = ua.DeadbandType.Percent, ua.DeadbandType.Absolute

    async def scenario(node: Any) -> Any:
        async with Client(url, timeout=10) as client:
            ns = await client.get_namespace_index(NAMESPACE_URI)
            force = ua.NodeId("grip.TotalForce", ns)
            eu = await client.get_node(ua.NodeId("grip.TotalForce.EURange", ns)).read_value()
            seen: dict[int, list[ua.DataValue]] = {1: [], 2: []}

            def on_publish(result: Any) -> None:
                for data in result.NotificationMessage.NotificationData or []:
                    if isinstance(data, ua.DataChangeNotification):
                        for m in data.MonitoredItems or []:
                            seen.setdefault(m.ClientHandle, []).append(m.Value)

            sub = await client.uaclient.create_subscription(ua.CreateSubscriptionParameters(
                RequestedPublishingInterval=10, RequestedLifetimeCount=3000, RequestedMaxKeepAliveCount=100,
                PublishingEnabled=True), on_publish)
            items = [_item(ua, force, 1, None), _item(ua, force, 2, (percent, 0.01)),
                     _item(ua, force, 3, (percent, 150.0)),
                     _item(ua, ua.NodeId("grip.Scores.ScoreA", ns), 4, (percent, 5.0)),
                     _item(ua, ua.NodeId("grip.GraspStateName", ns), 5, (absolute, 1.0)),
                     _item(ua, force, 6, (absolute, -1.0))]
            results = await client.uaclient.create_monitored_items(ua.CreateMonitoredItemsParameters(
                SubscriptionId=sub.SubscriptionId, TimestampsToReturn=ua.TimestampsToReturn.Both,
                ItemsToCreate=items))
            node.start()
            node.join(20)
            await asyncio.sleep(0.5)
            return eu, [r.StatusCode.name for r in results], seen

    with running_bridge(config) as run, node_thread(paper_profile, ch, raw) as node:
        eu, codes, seen = asyncio.run(asyncio.wait_for(scenario(node), 60))
        counters = run.counters("grip")
    assert codes == ["Good", "Good", "BadDeadbandFilterInvalid", "BadDeadbandFilterInvalid", "BadFilterNotAllowed",
                     "BadDeadbandFilterInvalid"]
    assert counters["opcua_filters_refused"] == 4
    band = 0.0001 * (eu.High - eu.Low)  # 0.01 %: 25 mN of 0 to 250 N
    assert band > 0

    def steps(values: list[Any]) -> list[float]:
        good = [v.Value.Value for v in values if v.StatusCode.is_good() and v.Value.Value is not None]
        return [abs(b - a) for a, b in zip(good, good[1:])]

    plain, banded = steps(seen[1]), steps(seen[2])
    assert plain and min(plain) <= band  # (the force moves by less than the band: the test can fail)
    assert banded and min(banded) > band, (band, sorted(banded)[:5])
    assert len(banded) < len(plain)
