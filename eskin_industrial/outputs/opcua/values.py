"""The snapshots applied to the address space: each variable's value with its status
and source timestamp (only what changed is written), the two OPC 40001-1 state
machines, the taxel frame."""

from __future__ import annotations

import datetime
from typing import Any

from asyncua import Server, ua

from ...node import NodeSnapshot
from . import model, status
from .alarm import Transition
from .build import variant_type
from .nodestate import NodeState
from .options import OpcuaOptions
from .report import Report
from .uaconv import data_value, node_id

_VALUE = ua.AttributeIds.Value
_OFFLINE = model.INDEX["Health/Offline"]
_GROUP_INDEX = {"decision": 0, "measurement": 1, "fact": 2}
_GROUPS = tuple(_GROUP_INDEX[g] for g in model.GROUPS)
_VTYPES = tuple(variant_type(v.datatype) for v in model.VARIABLES)
_UTC = datetime.UTC
_VARIANT_NONE = ua.Variant(None)


class Values:
    """Writes the nodes' values on the server's loop."""

    def __init__(self, server: Server, options: OpcuaOptions, report: Report) -> None:
        self.server = server
        self.options = options
        self.report = report
        self.machinery_ns = 0  #: the Machinery namespace's index (its states' NodeIds), set once loaded

    async def write_initial(self, n: NodeState) -> None:
        """Before the first snapshot: every variable BadWaitingForInitialData."""
        assert n.handles is not None
        now = datetime.datetime.now(_UTC)
        dv = data_value(ua.Variant(None), status.BAD_WAITING_FOR_INITIAL_DATA, now, now)
        for j, nodeid in enumerate(n.handles.variables):
            await self.server.write_attribute_value(nodeid, dv)
            n.last[j] = (None, status.BAD_WAITING_FOR_INITIAL_DATA)

    async def apply(self, n: NodeState, s: NodeSnapshot) -> Transition | None:
        """The snapshot's values written; the alarm's transition it makes, if any."""
        server, handles = self.server, n.handles
        assert handles is not None
        n.snapshot = s
        n.applied += 1
        q = status.quality(s, n.source_end, self.options.bad_after_s)
        source_ts = datetime.datetime.fromtimestamp(s.wall_time_s, _UTC)
        now = datetime.datetime.now(_UTC)
        last = n.last
        writes = 0
        aspace = server.iserver.aspace  # (what Server.write_attribute_value calls, two calls down)
        for j, value in enumerate(model.values(s)):
            code = status.GOOD if j == _OFFLINE else q[_GROUPS[j]]  # Offline is known even when stopped
            if status.is_bad(code):
                value = None
            elif value is None:
                if status.is_uncertain(code) and last[j][0] is not None:
                    value = last[j][0]  # the last usable value, with its new status
                else:
                    code = status.BAD_WAITING_FOR_INITIAL_DATA
            if last[j] == (value, code):
                continue
            last[j] = (value, code)
            variant = _VARIANT_NONE if value is None else ua.Variant(value, _VTYPES[j])
            await aspace.write_attribute_value(handles.variables[j], _VALUE, data_value(variant, code,
                                                                                  source_ts, now))
            writes += 1
        self.report.counts["writes"] += writes
        for machine, state in (("MachineryItemState", status.machinery_state(s, n.source_end)),
                               ("MachineryOperationMode", status.operation_mode(s))):
            if n.machinery.get(machine) != state:
                n.machinery[machine] = state
                await self._write_state(handles.states[machine], state, model.STATE_MACHINES[machine][1][state],
                                        source_ts, now)
        return n.alarm.observe(s)

    async def _write_state(self, nodes: tuple[ua.NodeId, ua.NodeId], state: str, state_number: int,
                           source_ts: datetime.datetime, now: datetime.datetime) -> None:
        """A state machine's CurrentState and its Id (the state's NodeId in the
        Machinery namespace, which the Id's value names already)."""
        current, state_id = nodes
        await self.server.write_attribute_value(current, data_value(
            ua.Variant(ua.LocalizedText(state), ua.VariantType.LocalizedText), status.GOOD, source_ts, now))
        await self.server.write_attribute_value(state_id, data_value(
            ua.Variant(node_id(state_number, self.machinery_ns), ua.VariantType.NodeId), status.GOOD, source_ts, now))

    async def write_frame(self, n: NodeState, forces: Any, wall_time_s: float) -> None:
        assert n.handles is not None and n.handles.frame is not None
        s = n.snapshot
        code = status.GOOD if s is None else status.quality(s, n.source_end, self.options.bad_after_s).measurement
        shape = list(n.info.frame_shape or (0, 0))
        variant = (ua.Variant(None) if status.is_bad(code) else
                   ua.Variant(forces.tolist(), ua.VariantType.Float, Dimensions=[ua.Int32(d) for d in shape]))
        now = datetime.datetime.now(_UTC)
        await self.server.write_attribute_value(n.handles.frame, data_value(
            variant, code, datetime.datetime.fromtimestamp(wall_time_s, _UTC), now))
        self.report.node_counts[n.index]["frames"] += 1
