"""The monitored items a client asks for (CreateMonitoredItems, ModifyMonitoredItems),
checked before asyncua's subscription service keeps them: their event filters
(:mod:`.eventfilter`) and their deadbands (:mod:`.deadband`).  A refused item gets its
own result; the others go on to asyncua, and the results come back in the order
asked."""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from typing import Any

from asyncua import ua
from asyncua.ua.uaprotocol_auto import (
    DataChangeFilter as _DataChangeFilter,  # (what the decoder makes: ua's is a subclass)
)

from . import deadband
from .eventfilter import empty_null_arrays, event_filter_problem
from .typeinfo import TypeInfo
from .uaconv import status_code

_NO_RESULT = ua.ExtensionObject()


def _problem(types: TypeInfo, read: ua.ReadValueId, flt: Any) -> tuple[ua.StatusCode, Any] | None:
    if int(read.AttributeId) == ua.AttributeIds.EventNotifier:
        return event_filter_problem(flt)
    if isinstance(flt, ua.EventFilter):
        return status_code(ua.StatusCodes.BadFilterNotAllowed), _NO_RESULT
    if isinstance(flt, _DataChangeFilter):
        code = deadband.deadband_problem(types, read.NodeId, int(read.AttributeId), flt)
        if code is not None:
            return status_code(code), _NO_RESULT
    return None


def guard(iserver: Any, on_refused: Callable[[int], None] = lambda code: None) -> None:
    """Check the items of every CreateMonitoredItems and ModifyMonitoredItems before
    asyncua's subscription service (``iserver.subscription_service``) takes them;
    ``on_refused(code)`` for each item refused."""
    types = TypeInfo(iserver.aspace)
    subscriptions = iserver.subscription_service
    create: Callable[[ua.CreateMonitoredItemsParameters], Awaitable[list[ua.MonitoredItemCreateResult]]]
    create = subscriptions.create_monitored_items
    modify: Callable[[ua.ModifyMonitoredItemsParameters], list[ua.MonitoredItemModifyResult]]
    modify = subscriptions.modify_monitored_items

    def items_of(subscription_id: int) -> Any:
        sub = subscriptions.subscriptions.get(subscription_id)
        if sub is None:
            return None
        srv = sub.monitored_item_srv
        # (this server's deadbands: element by element for an array; on the instance)
        srv._is_deadband_exceeded = deadband.exceeded
        return srv

    async def create_checked(params: ua.CreateMonitoredItemsParameters) -> list[ua.MonitoredItemCreateResult]:
        empty_null_arrays(params)
        items_of(params.SubscriptionId)
        items = params.ItemsToCreate
        refused: dict[int, ua.MonitoredItemCreateResult] = {}
        for i, item in enumerate(items):
            problem = _problem(types, item.ItemToMonitor, item.RequestedParameters.Filter)
            if problem is not None:
                refused[i] = ua.MonitoredItemCreateResult(StatusCode=problem[0], FilterResult=problem[1])
                on_refused(problem[0].value)
        params.ItemsToCreate = [item for i, item in enumerate(items) if i not in refused]
        made = iter(await create(params))  # (also with nothing left: the subscription is checked)
        return [refused[i] if i in refused else next(made) for i in range(len(items))]

    def modify_checked(params: ua.ModifyMonitoredItemsParameters) -> list[ua.MonitoredItemModifyResult]:
        empty_null_arrays(params)
        srv = items_of(params.SubscriptionId)
        kept = {} if srv is None else srv._monitored_items
        items = params.ItemsToModify
        refused: dict[int, ua.MonitoredItemModifyResult] = {}
        for i, item in enumerate(items):
            flt = item.RequestedParameters.Filter
            mdata = kept.get(item.MonitoredItemId)
            # (asyncua keeps the item's filter when none is given; an unknown item is its to answer)
            problem = None if flt is None or mdata is None else _problem(types, mdata.read_value_id, flt)
            if problem is not None:
                refused[i] = ua.MonitoredItemModifyResult(StatusCode=problem[0], FilterResult=problem[1])
                on_refused(problem[0].value)
        params.ItemsToModify = [item for i, item in enumerate(items) if i not in refused]
        made = iter(modify(params))
        return [refused[i] if i in refused else next(made) for i in range(len(items))]

    # (on the instance: every session of this server calls its one subscription service)
    subscriptions.create_monitored_items = create_checked
    subscriptions.modify_monitored_items = modify_checked
