"""The slip alarm on the wire: each transition of a node's :class:`.alarm.AlarmState`
as an event of ``SlipAlarmType`` (on the node's object, then on the Server object,
where a SCADA subscribes), the condition's own variables, and its methods:
Acknowledge, Disable, Enable and AddComment."""

from __future__ import annotations

import datetime
import time
from collections.abc import Sequence
from typing import Any

from asyncua import Server, ua
from asyncua.common.events import get_event_obj_from_type_node

from ...node import NodeSnapshot
from . import model, status
from .access import REQUEST_USER
from .alarm import Transition
from .nodestate import NodeState
from .options import OpcuaOptions
from .report import Report
from .uaconv import data_value, node_id, status_code

_UTC = datetime.UTC
_FIELD_TYPES = {"Double": ua.VariantType.Double, "String": ua.VariantType.String, "UInt32": ua.VariantType.UInt32}


class AlarmEvents:
    """Every node's slip alarm on one server (its loop)."""

    def __init__(self, server: Server, options: OpcuaOptions, nodes: Sequence[NodeState], report: Report) -> None:
        self.server = server
        self.options = options
        self.nodes = nodes
        self.report = report
        self._by_condition: dict[ua.NodeId, int] = {}
        self._errors_logged: set[str] = set()

    async def attach(self, n: NodeState, alarm_type: ua.NodeId) -> None:
        """The node's event object and condition variables, once its nodes are built."""
        assert n.handles is not None
        self._by_condition[n.handles.alarm] = n.index
        n.event = await self._event_object(n, alarm_type)
        await self._condition_variables(n, datetime.datetime.now(_UTC))

    async def _event_object(self, n: NodeState, alarm_type: ua.NodeId) -> Any:
        assert n.handles is not None
        ev: Any = await get_event_obj_from_type_node(self.server.get_node(alarm_type))
        ev.add_property("NodeId", n.handles.alarm, ua.VariantType.NodeId)  # the ConditionId
        for name, dtype, _ in model.ALARM_FIELDS:
            ev.add_property(name, 0.0 if dtype == "Double" else "" if dtype == "String" else 0, _FIELD_TYPES[dtype])
        for state in ("ActiveState", "AckedState", "EnabledState"):
            ev.add_property(f"{state}/TransitionTime", None, ua.VariantType.DateTime)
        ev.SourceNode = n.handles.obj
        ev.SourceName = n.info.name
        ev.ConditionName = "SlipAlarm"
        ev.ConditionClassId = node_id(ua.ObjectIds.BaseConditionClassType)
        ev.ConditionClassName = ua.LocalizedText("BaseConditionClassType")
        ev.BranchId = ua.NodeId()
        ev.EnabledState = ua.LocalizedText("Enabled")
        setattr(ev, "EnabledState/Id", True)
        ev.Quality = status_code(0)
        ev.Severity = self.options.alarm_severity
        ev.LastSeverity = self.options.alarm_severity
        ev.Retain = False
        ev.ActiveState = ua.LocalizedText("Inactive")
        setattr(ev, "ActiveState/Id", False)
        ev.AckedState = ua.LocalizedText("Acknowledged")
        setattr(ev, "AckedState/Id", True)
        ev.ConfirmedState = None
        ev.SuppressedOrShelved = False
        ev.Comment = ua.LocalizedText("")
        ev.ClientUserId = ""
        ev.Message = ua.LocalizedText("")
        return ev

    async def fire(self, n: NodeState, transition: Transition, s: NodeSnapshot | None, comment: str = "") -> None:
        """The condition's new state as an event (on the node's object, then on the Server
        object: where a SCADA subscribes), and on the condition's own variables."""
        assert n.handles is not None
        ev, a = n.event, n.alarm
        now = datetime.datetime.now(_UTC)
        ev.EventId = a.event_id
        ev.Retain = a.retain
        ev.ActiveState = ua.LocalizedText("Active" if a.active else "Inactive")
        setattr(ev, "ActiveState/Id", a.active)
        ev.AckedState = ua.LocalizedText("Acknowledged" if a.acked else "Unacknowledged")
        setattr(ev, "AckedState/Id", a.acked)
        ev.EnabledState = ua.LocalizedText("Enabled" if a.enabled else "Disabled")
        setattr(ev, "EnabledState/Id", a.enabled)
        ev.ReceiveTime = now
        if transition in ("acknowledged", "commented", "disabled", "enabled"):
            ev.Time = now
            if transition in ("acknowledged", "commented"):  # (Part 9: Acknowledge's comment is one too)
                ev.Comment = ua.LocalizedText(comment)
                ev.ClientUserId = REQUEST_USER.get()
            if transition == "acknowledged":
                setattr(ev, "AckedState/TransitionTime", now)
            elif transition in ("disabled", "enabled"):
                setattr(ev, "EnabledState/TransitionTime", now)
            ev.Message = ua.LocalizedText(
                f"slip on {n.info.name} acknowledged" if transition == "acknowledged"
                else f"comment on the slip alarm of {n.info.name}" if transition == "commented"
                else f"slip alarm of {n.info.name} {transition}"
                + (", a slip on" if transition == "enabled" and a.active else ""))
        else:
            assert s is not None
            ev.Time = datetime.datetime.fromtimestamp(s.wall_time_s, _UTC)
            setattr(ev, "ActiveState/TransitionTime", ev.Time)
        if transition == "raised":
            assert s is not None
            delay = max(time.perf_counter() - s.t_event, 0.0)
            names = s.score_names
            ev.ScoreA, ev.ScoreB = float(s.score_a or 0.0), float(s.score_b or 0.0)
            ev.ScoreNames = ",".join(names)
            ev.R_coe, ev.R_dw = float(s.r_coe or 0.0), float(s.r_dw or 0.0)
            ev.Delay = delay
            ev.SensorTime = float(s.t or 0.0)
            ev.SlipEvents = s.slip_events & 0xFFFFFFFF
            ev.Message = ua.LocalizedText(
                f"slip on {n.info.name}: {names[0]} {ev.ScoreA:.2f}, {names[1]} {ev.ScoreB:.2f}, "
                f"raised {delay * 1000:.1f} ms after the deciding scan")
            self.report.node_counts[n.index]["alarms"] += 1
            self.report.event("opcua_alarm", "info", node_event=n.info.name, transition=transition,
                              severity=self.options.alarm_severity, delay_ms=round(delay * 1000, 2))
        elif transition == "cleared":
            ev.Message = ua.LocalizedText(f"slip on {n.info.name} over"
                                          + ("" if a.acked else ", not acknowledged"))
        # ConditionRefresh replays the retained conditions with the node they were last
        # emitted from: the Server object, where a SCADA subscribes, last
        for emitter in (n.handles.obj, node_id(ua.ObjectIds.Server)):
            ev.emitting_node = emitter
            await self._trigger(n, ev)
        await self._condition_variables(n, now)

    async def _trigger(self, n: NodeState, ev: Any) -> None:
        """The event to each subscription in turn: what asyncua raises while it fills
        one subscription's items is counted and logged (once for each kind), and the
        other subscriptions get the event; nothing of it reaches the server's loop."""
        subs = self.server.iserver.subscription_service
        # (no subscription: the call still keeps a retained condition for ConditionRefresh;
        # 0 is no subscription's id)
        for sid in list(subs.subscriptions) or [0]:
            try:
                await subs.trigger_event(ev, sid)
            except Exception as exc:  # noqa: BLE001 - asyncua's, from a client's filter: the alarm goes on
                self.report.node_counts[n.index]["event_errors"] += 1
                kind = type(exc).__name__
                if kind not in self._errors_logged:
                    self._errors_logged.add(kind)
                    self.report.event("opcua_event_error", "error", node_event=n.info.name, subscription=sid,
                                      detail=f"{kind}: {exc}"[:200])

    async def _condition_variables(self, n: NodeState, now: datetime.datetime) -> None:
        """The condition object's variables, as its newest event says (a client that
        browses to SlipAlarm reads what a subscriber was told)."""
        assert n.handles is not None
        ev = n.event
        for path, nodeid in n.handles.alarm_vars.items():
            value = getattr(ev, path, None)
            if value is None:
                continue
            dtype = ev.data_types.get(path)
            vtype = dtype if isinstance(dtype, ua.VariantType) else ua.VariantType.DateTime
            await self.server.write_attribute_value(nodeid, data_value(ua.Variant(value, vtype), status.GOOD,
                                                                         now, now))

    def _condition(self, parent: ua.NodeId) -> int | None:
        return self._by_condition.get(parent)

    def _event_call(self, parent: ua.NodeId, args: tuple[Any, ...]) -> tuple[int, bytes, Any] | ua.StatusCode:
        """The (node index, EventId, Comment) of a method that takes (EventId, Comment),
        Acknowledge and AddComment alike; or the status that refuses the call."""
        i = self._condition(parent)
        if i is None:
            return status_code(ua.StatusCodes.BadNodeIdInvalid)
        if len(args) < 2:
            return status_code(ua.StatusCodes.BadArgumentsMissing)
        event_id, comment = args[0].Value, args[1].Value
        if not isinstance(event_id, bytes):
            return status_code(ua.StatusCodes.BadTypeMismatch)
        return i, event_id, comment

    async def acknowledge(self, parent: ua.NodeId, *args: Any) -> Any:
        """AcknowledgeableConditionType.Acknowledge(EventId, Comment) on a node's SlipAlarm."""
        call = self._event_call(parent, args)
        if not isinstance(call, tuple):
            return call
        i, event_id, comment = call
        n = self.nodes[i]
        counts = self.report.node_counts[i]
        code = n.alarm.acknowledge(event_id)
        if code != status.GOOD:
            counts["alarm_acks_refused"] += 1
            return status_code(code)
        counts["alarm_acks"] += 1
        text = _text(comment)
        await self.fire(n, "acknowledged", n.snapshot, text)
        self.report.event("opcua_alarm", "info", node_event=n.info.name, transition="acknowledged",
                          comment=text or "-")
        return []

    async def disable(self, parent: ua.NodeId, *args: Any) -> Any:
        """ConditionType.Disable() on a node's SlipAlarm."""
        return await self._switch(parent, "disabled")

    async def enable(self, parent: ua.NodeId, *args: Any) -> Any:
        """ConditionType.Enable() on a node's SlipAlarm."""
        return await self._switch(parent, "enabled")

    async def _switch(self, parent: ua.NodeId, transition: Transition) -> Any:
        i = self._condition(parent)
        if i is None:
            return status_code(ua.StatusCodes.BadNodeIdInvalid)
        n = self.nodes[i]
        code = n.alarm.disable() if transition == "disabled" else n.alarm.enable()
        if code != status.GOOD:
            return status_code(code)
        await self.fire(n, transition, n.snapshot)
        self.report.event("opcua_alarm", "info", node_event=n.info.name, transition=transition,
                          user=REQUEST_USER.get() or "-")
        return []

    async def add_comment(self, parent: ua.NodeId, *args: Any) -> Any:
        """ConditionType.AddComment(EventId, Comment) on a node's SlipAlarm."""
        call = self._event_call(parent, args)
        if not isinstance(call, tuple):
            return call
        i, event_id, comment = call
        n = self.nodes[i]
        code = n.alarm.comment(event_id)
        if code != status.GOOD:
            return status_code(code)
        text = _text(comment)
        await self.fire(n, "commented", n.snapshot, text)
        self.report.event("opcua_alarm", "info", node_event=n.info.name, transition="commented", comment=text or "-")
        return []


def _text(comment: Any) -> str:
    """A Comment argument's text (a LocalizedText; a null one: empty)."""
    return str(comment.Text or "") if isinstance(comment, ua.LocalizedText) else str(comment or "")
