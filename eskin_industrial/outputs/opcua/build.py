"""The address space, built from :mod:`.model` in an asyncua server: the type model
(``GraspStateEnumeration``, ``GraspSensorType``, ``SlipAlarmType``, fixed numeric ids
in our namespace, exported as NodeSet2 by :mod:`.nodeset`) and one object per node
under OPC 40001-1's ``Machines`` folder, on the types of the companion specifications
:mod:`.companions` loads (the nameplate, the two state machines).

Instances are built here, child by child, from the same lists as the type's instance
declarations (string node ids ``NODE.Health.SensorStale``, stable across restarts for
a SCADA's tags); the slip alarm's condition object is instantiated from its type by
asyncua (the standard AlarmConditionType's many children).  Every variable is
read-only.
"""

from __future__ import annotations

import itertools
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from typing import Any

from asyncua import Node, Server, ua
from asyncua.common.instantiate_util import instantiate
from asyncua.common.structures104 import new_enum

from . import model
from .companions import DI_URI, MACHINERY_URI
from .model import FOLDERS, FRAME, IDENTIFICATION, METHODS, STATE_MACHINES, VARIABLES, Var
from .nodeinfo import NodeInfo
from .uaconv import node_id

#: OPC 10000-3's HasAddIn (a HasComponent): how OPC 40001-1 adds its building blocks.
HAS_ADD_IN = ua.ObjectIds.HasAddIn
_BUILTIN: dict[str, tuple[int, ua.VariantType]] = {
    "Boolean": (ua.ObjectIds.Boolean, ua.VariantType.Boolean),
    "Double": (ua.ObjectIds.Double, ua.VariantType.Double),
    "Float": (ua.ObjectIds.Float, ua.VariantType.Float),
    "UInt16": (ua.ObjectIds.UInt16, ua.VariantType.UInt16),
    "UInt32": (ua.ObjectIds.UInt32, ua.VariantType.UInt32),
    "UInt64": (ua.ObjectIds.UInt64, ua.VariantType.UInt64),
    "String": (ua.ObjectIds.String, ua.VariantType.String),
    "LocalizedText": (ua.ObjectIds.LocalizedText, ua.VariantType.LocalizedText),
}
_TYPEDEFS = {"AnalogItemType": ua.ObjectIds.AnalogItemType, "TwoStateDiscreteType": ua.ObjectIds.TwoStateDiscreteType,
             "BaseDataVariableType": ua.ObjectIds.BaseDataVariableType}
#: The alarm's own fields: their variant types.
_FIELD_TYPES = {"Double": ua.VariantType.Double, "String": ua.VariantType.String, "UInt32": ua.VariantType.UInt32}
_FIELD_DEFAULTS: dict[str, Any] = {"Double": 0.0, "String": "", "UInt32": 0}


def variant_type(datatype: str) -> ua.VariantType:
    """The variant a variable's values travel in (the enumeration: Int32)."""
    return ua.VariantType.Int32 if datatype == "GraspStateEnumeration" else _BUILTIN[datatype][1]


@dataclass
class TypeIds:
    """The type model's nodes."""

    enum: ua.NodeId
    sensor: ua.NodeId
    alarm: ua.NodeId
    di: int  #: the namespace indexes of OPC 10000-100 (DI) and OPC 40001-1 (Machinery)
    machinery: int
    methods: dict[str, ua.NodeId] = field(default_factory=dict)  #: the type's method declarations


@dataclass
class NodeHandles:
    """One node's object and what the server writes or is called on."""

    obj: ua.NodeId
    variables: list[ua.NodeId]  #: in :data:`.model.VARIABLES` order
    frame: ua.NodeId | None
    #: each state machine's (CurrentState, CurrentState/Id), by its browse name
    states: dict[str, tuple[ua.NodeId, ua.NodeId]]
    alarm: ua.NodeId
    methods: dict[str, ua.NodeId]  #: name -> the instance's method node
    alarm_methods: dict[str, ua.NodeId]  #: the condition's own (Acknowledge, ...)
    #: The condition's variables by browse path (``ActiveState/Id``), kept equal to its events.
    alarm_vars: dict[str, ua.NodeId] = field(default_factory=dict)


def _ranges(info: NodeInfo) -> dict[str, tuple[float, float]]:
    return {"TotalForce": info.force_range, "CentreOfForceX": info.x_range, "CentreOfForceY": info.y_range,
            "Taxels": info.frame_range}


class _Builder:
    """Adds nodes through the server's internal session (no network)."""

    def __init__(self, server: Server, idx: int) -> None:
        self.server = server
        self.session = server.iserver.isession
        self.idx = idx

    def node(self, nodeid: ua.NodeId | int) -> Node:
        return self.server.get_node(nodeid)

    async def add(self, item: ua.AddNodesItem) -> ua.NodeId:
        (res,) = await self.session.add_nodes([item])
        res.StatusCode.check()
        return res.AddedNodeId

    async def obj(self, nodeid: ua.NodeId, parent: ua.NodeId, name: str, typedef: int | ua.NodeId,
                  description: str = "", ref: int = ua.ObjectIds.HasComponent, notifier: bool = False,
                  ns: int | None = None) -> ua.NodeId:
        item = ua.AddNodesItem()
        item.RequestedNewNodeId = nodeid
        item.BrowseName = ua.QualifiedName(name, self.idx if ns is None else ns)
        item.NodeClass = ua.NodeClass.Object
        item.ParentNodeId = parent
        item.ReferenceTypeId = node_id(ref)
        item.TypeDefinition = typedef if isinstance(typedef, ua.NodeId) else node_id(typedef)
        attrs = ua.ObjectAttributes()
        attrs.DisplayName = ua.LocalizedText(name)
        attrs.Description = ua.LocalizedText(description)
        attrs.EventNotifier = 1 if notifier else 0  # SubscribeToEvents
        item.NodeAttributes = attrs
        return await self.add(item)

    async def var(self, nodeid: ua.NodeId, parent: ua.NodeId, name: str, datatype: ua.NodeId,
                  value: ua.Variant, *, typedef: int = ua.ObjectIds.BaseDataVariableType,
                  ref: int = ua.ObjectIds.HasComponent, ns: int | None = None, description: str = "",
                  display: str | None = None, dims: list[int] | None = None) -> ua.NodeId:
        item = ua.AddNodesItem()
        item.RequestedNewNodeId = nodeid
        item.BrowseName = ua.QualifiedName(name, self.idx if ns is None else ns)
        item.NodeClass = ua.NodeClass.Variable
        item.ParentNodeId = parent
        item.ReferenceTypeId = node_id(ref)
        item.TypeDefinition = node_id(typedef)
        attrs = ua.VariableAttributes()
        attrs.DisplayName = ua.LocalizedText(display or name)
        attrs.Description = ua.LocalizedText(description)
        attrs.DataType = datatype
        attrs.Value = value
        if dims is None and isinstance(value.Value, list):
            dims = [0]  # a one-dimensional array of any length (EnumStrings)
        attrs.ValueRank = ua.ValueRank.Scalar if dims is None else len(dims)
        if dims is not None:
            attrs.ArrayDimensions = [ua.UInt32(d) for d in dims]
        attrs.AccessLevel = attrs.UserAccessLevel = ua.AccessLevel.CurrentRead.mask
        attrs.WriteMask = attrs.UserWriteMask = 0
        attrs.Historizing = False
        item.NodeAttributes = attrs
        return await self.add(item)

    async def prop(self, nodeid: ua.NodeId, parent: ua.NodeId, name: str, datatype: int | ua.NodeId, value: Any,
                   vtype: ua.VariantType, ns: int | None = None, description: str = "") -> ua.NodeId:
        dt = datatype if isinstance(datatype, ua.NodeId) else node_id(datatype)
        return await self.var(nodeid, parent, name, dt, ua.Variant(value, vtype), typedef=ua.ObjectIds.PropertyType,
                              ref=ua.ObjectIds.HasProperty, ns=ns, description=description)

    async def rule(self, nodeid: ua.NodeId, mandatory: bool = True) -> None:
        await self.node(nodeid).set_modelling_rule(mandatory)


def _analog_children(info: NodeInfo | None, v: Var) -> tuple[ua.Range, ua.EUInformation]:
    lo, hi = (0.0, 0.0) if info is None else _ranges(info)[v.path.rpartition("/")[2]]
    code, name = model.UNITS[v.unit]
    eu = ua.EUInformation(NamespaceUri=model.UNECE_NAMESPACE, UnitId=code, DisplayName=ua.LocalizedText(v.unit),
                          Description=ua.LocalizedText(name))
    return ua.Range(Low=float(lo), High=float(hi)), eu


async def build_types(server: Server, idx: int, method_callback: Callable[..., Any]) -> TypeIds:
    """The type model in namespace ``idx`` (fixed ids: :data:`.model.TYPE_IDS`); the
    type's method declarations call ``method_callback(name)(parent, *args)``."""
    b = _Builder(server, idx)
    ids = iter(itertools.count(1002))

    def nid() -> ua.NodeId:
        return node_id(next(ids), idx)

    # the enumeration: DataTypeDefinition (1.04) and EnumStrings (for older clients)
    enum_id = node_id(model.TYPE_IDS["GraspStateEnumeration"], idx)
    enum_node = await new_enum(server, enum_id, ua.QualifiedName("GraspStateEnumeration", idx),
                               list(model.STATE_NAMES))
    await b.prop(node_id(model.TYPE_IDS["GraspStateEnumeration"] + 1, idx), enum_node.nodeid, "EnumStrings",
                 ua.ObjectIds.LocalizedText, [ua.LocalizedText(n) for n in model.STATE_NAMES],
                 ua.VariantType.LocalizedText, ns=0)

    # the slip alarm's type
    alarm_id = node_id(model.TYPE_IDS["SlipAlarmType"], idx)
    alarm = await b.node(ua.ObjectIds.AlarmConditionType).add_object_type(alarm_id, ua.QualifiedName(
        "SlipAlarmType", idx))
    for j, (name, dtype, doc) in enumerate(model.ALARM_FIELDS):
        p = await b.prop(node_id(model.TYPE_IDS["SlipAlarmType"] + 1 + j, idx), alarm_id, name, _BUILTIN[dtype][0],
                         _FIELD_DEFAULTS[dtype], _FIELD_TYPES[dtype], description=doc)
        await b.rule(p)

    # the sensor's type, its instance declarations
    sensor_id = node_id(model.TYPE_IDS["GraspSensorType"], idx)
    sensor = await b.node(ua.ObjectIds.BaseObjectType).add_object_type(sensor_id, ua.QualifiedName(
        "GraspSensorType", idx))
    await sensor.write_attribute(ua.AttributeIds.Description, ua.DataValue(ua.Variant(
        ua.LocalizedText("a tactile sensor node on a gripper, with its grasp state"), ua.VariantType.LocalizedText)))
    types = TypeIds(enum_id, sensor.nodeid, alarm.nodeid, await server.get_namespace_index(DI_URI),
                    await server.get_namespace_index(MACHINERY_URI))
    async for _ in _members(b, sensor.nodeid, lambda path: nid(), None, types, method_callback, declare=True):
        pass
    return types


async def _members(b: _Builder, parent: ua.NodeId, nid: Callable[[str], ua.NodeId], info: NodeInfo | None,
                   types: TypeIds, method_callback: Callable[..., Any], declare: bool
                   ) -> AsyncIterator[tuple[str, ua.NodeId]]:
    """The children of a sensor object (``declare``: the type's instance declarations,
    with modelling rules), yielded as (what, node id): ``var:PATH``, ``frame``,
    ``state``, ``method:NAME``.  ``nid(path)`` names each child's node id from its
    browse path (``Health.SensorStale``)."""
    async def rule(n: ua.NodeId, mandatory: bool = True) -> None:
        if declare:
            await b.rule(n, mandatory)

    # OPC 40001-1: the nameplate, an AddIn of the machine (DI:Identification) ...
    ident = await b.obj(nid("Identification"), parent, "Identification",
                        node_id(model.MACHINE_IDENTIFICATION_TYPE, types.machinery),
                        "the node's nameplate (OPC 40001-1, MachineIdentificationType)", ref=HAS_ADD_IN, ns=types.di)
    await rule(ident)
    for name, dtype, doc in IDENTIFICATION:
        text = "" if info is None else info.identification.get(name, "")
        value = ua.LocalizedText(text) if dtype == "LocalizedText" else text
        p = await b.prop(nid(f"Identification.{name}"), ident, name, _BUILTIN[dtype][0], value, _BUILTIN[dtype][1],
                         ns=types.di, description=doc)
        await rule(p)
    # ... and every building block, the nameplate too, in MachineryBuildingBlocks
    blocks = await b.obj(nid("MachineryBuildingBlocks"), parent, "MachineryBuildingBlocks", ua.ObjectIds.FolderType,
                         "the node's OPC 40001-1 building blocks", ns=types.machinery)
    await rule(blocks)
    await b.node(blocks).add_reference(ident, HAS_ADD_IN)
    for machine, (type_id, states) in STATE_MACHINES.items():
        path = f"MachineryBuildingBlocks.{machine}"
        first = model.INITIAL_STATES[machine]
        sm = await b.obj(nid(path), blocks, machine, node_id(type_id, types.machinery),
                         f"OPC 40001-1's {machine}: " + ", ".join(states), ref=HAS_ADD_IN, ns=types.machinery)
        current = await b.var(nid(f"{path}.CurrentState"), sm, "CurrentState", node_id(ua.ObjectIds.LocalizedText),
                              ua.Variant(ua.LocalizedText(first), ua.VariantType.LocalizedText),
                              typedef=ua.ObjectIds.FiniteStateVariableType, ns=0)
        state_id = await b.prop(nid(f"{path}.CurrentState.Id"), current, "Id", ua.ObjectIds.NodeId,
                                node_id(states[first], types.machinery), ua.VariantType.NodeId, ns=0)
        for n in (sm, current, state_id):
            await rule(n)
        yield f"state:{machine}", current
        yield f"stateid:{machine}", state_id
    folders = {}
    for folder in FOLDERS:
        folders[folder] = await b.obj(nid(folder), parent, folder, ua.ObjectIds.FolderType)
        await rule(folders[folder])
    frame_shape = None if info is None else info.frame_shape
    units_only: list[tuple[str, str, ua.NodeId]] = []
    for v in (*VARIABLES, FRAME):
        if v is FRAME and not declare and frame_shape is None:
            continue
        folder, _, name = v.path.rpartition("/")
        where = folders[folder] if folder else parent
        datatype = types.enum if v.datatype == "GraspStateEnumeration" else node_id(_BUILTIN[v.datatype][0])
        display, doc = None, v.doc
        if info is not None and name in ("ScoreA", "ScoreB"):
            k = 0 if name == "ScoreA" else 1
            display, doc = info.score_names[k], f"{info.score_names[k]}: {info.score_docs[k]}"
        dims = None
        if v is FRAME:
            dims = [0, 0] if frame_shape is None else list(frame_shape)
        path = v.path.replace("/", ".")
        node = await b.var(nid(path), where, name, datatype, ua.Variant(None, ua.VariantType.Null),
                           typedef=_TYPEDEFS[model.variable_type(v)], description=doc, display=display, dims=dims)
        await rule(node, mandatory=v is not FRAME)
        if v.path in model.FLAG_STATES:  # what a client shows for true and false
            for prop, text in zip(("TrueState", "FalseState"), model.FLAG_STATES[v.path], strict=True):
                await rule(await b.prop(nid(f"{path}.{prop}"), node, prop, ua.ObjectIds.LocalizedText,
                                        ua.LocalizedText(text), ua.VariantType.LocalizedText, ns=0))
        if v.analog:
            rng, eu = _analog_children(info, v)
            p1 = await b.prop(nid(f"{path}.EURange"), node, "EURange", ua.ObjectIds.Range, rng, ua.VariantType.ExtensionObject, ns=0)
            p2 = await b.prop(nid(f"{path}.EngineeringUnits"), node, "EngineeringUnits", ua.ObjectIds.EUInformation, eu,
                              ua.VariantType.ExtensionObject, ns=0)
            await rule(p1)
            await rule(p2)
        elif v.unit:
            units_only.append((path, v.unit, node))
        yield ("frame" if v is FRAME else f"var:{v.path}"), node
    for name, arg, doc in METHODS:
        m = await b.node(parent).add_method(nid(name), ua.QualifiedName(name, b.idx), method_callback(name), [], [])
        await b.node(m.nodeid).write_attribute(ua.AttributeIds.Description, ua.DataValue(ua.Variant(
            ua.LocalizedText(doc), ua.VariantType.LocalizedText)))
        await rule(m.nodeid)
        if arg is not None:  # made here, not by asyncua: its id from the browse path as every other's
            inputs = [ua.Argument(Name=arg[0], DataType=node_id(_BUILTIN[arg[1]][0]), ValueRank=-1,
                                  Description=ua.LocalizedText(doc))]
            args = await b.prop(nid(f"{name}.InputArguments"), m.nodeid, "InputArguments", ua.ObjectIds.Argument,
                                inputs, ua.VariantType.ExtensionObject, ns=0)
            await rule(args)
        if declare:
            types.methods[name] = m.nodeid
        yield f"method:{name}", m.nodeid
    # a value with a unit says which, as an analog one does (Health/FrameAge)
    for path, unit, node in units_only:
        code, unit_name = model.UNITS[unit]
        eu = ua.EUInformation(NamespaceUri=model.UNECE_NAMESPACE, UnitId=code, DisplayName=ua.LocalizedText(unit),
                              Description=ua.LocalizedText(unit_name))
        await rule(await b.prop(nid(f"{path}.EngineeringUnits"), node, "EngineeringUnits", ua.ObjectIds.EUInformation,
                                eu, ua.VariantType.ExtensionObject, ns=0))
    if declare:
        # the alarm's declaration with the mandatory children of its type, as an instance
        # has them (another server making an object from the NodeSet makes them too);
        # made last: its children take the numbers after every other declaration's
        made = await instantiate(b.node(parent), b.node(types.alarm), nodeid=nid("SlipAlarm"),
                                 bname=ua.QualifiedName("SlipAlarm", b.idx), dname=ua.LocalizedText("SlipAlarm"),
                                 instantiate_optional=False)
        await made[0].write_attribute(ua.AttributeIds.Description, ua.DataValue(ua.Variant(
            ua.LocalizedText("raised at each entry into slip"), ua.VariantType.LocalizedText)))
        for made_node in made:
            await rule(made_node.nodeid)


async def build_machines(server: Server, types: TypeIds) -> ua.NodeId:
    """OPC 40001-1's ``Objects/Machines`` (loaded with the Machinery NodeSet), in the
    Server object's notifier tree (HasNotifier)."""
    machines = node_id(1001, types.machinery)
    await server.get_node(ua.ObjectIds.Server).add_reference(machines, ua.ObjectIds.HasNotifier)
    return machines


async def build_node(server: Server, idx: int, types: TypeIds, machines: ua.NodeId, info: NodeInfo,
                     method_callback: Callable[..., Any]) -> NodeHandles:
    """One node's object under OPC 40001-1's ``Machines``, its children and its slip alarm."""
    b = _Builder(server, idx)
    base = info.name
    obj = await b.obj(node_id(base, idx), machines, base, types.sensor, f"sensor node {base}",
                      ref=ua.ObjectIds.Organizes, notifier=True)
    # (no HasNotifier from Machines as well: a browse would list the node twice; its
    # events go to subscribers of the node's object and of the Server object)

    def nid(path: str) -> ua.NodeId:
        return node_id(f"{base}.{path}", idx)

    variables: dict[str, ua.NodeId] = {}
    methods: dict[str, ua.NodeId] = {}
    current: dict[str, ua.NodeId] = {}
    state_ids: dict[str, ua.NodeId] = {}
    frame = None
    async for what, node in _members(b, obj, nid, info, types, method_callback, declare=False):
        kind, _, name = what.partition(":")
        if kind == "var":
            variables[name] = node
        elif kind == "method":
            methods[name] = node
        elif kind == "frame":
            frame = node
        elif kind == "state":
            current[name] = node
        elif kind == "stateid":
            state_ids[name] = node
    cond_id = node_id(f"{base}.SlipAlarm", idx)
    # the condition: the mandatory children of AlarmConditionType and ours
    (cond, *_rest) = await instantiate(b.node(obj), b.node(types.alarm), nodeid=cond_id,
                                       bname=ua.QualifiedName("SlipAlarm", idx), dname=ua.LocalizedText("SlipAlarm"),
                                       instantiate_optional=False)
    await b.node(obj).add_reference(cond.nodeid, ua.ObjectIds.HasCondition)
    alarm_methods: dict[str, ua.NodeId] = {}
    for child in await cond.get_children(refs=ua.ObjectIds.HasComponent, nodeclassmask=ua.NodeClass.Method):
        alarm_methods[str((await child.read_browse_name()).Name)] = child.nodeid
    alarm_vars: dict[str, ua.NodeId] = {}
    await _variables_by_path(cond, "", alarm_vars)
    states = {name: (current[name], state_ids[name]) for name in STATE_MACHINES}
    return NodeHandles(obj, [variables[v.path] for v in VARIABLES], frame, states, cond.nodeid, methods,
                       alarm_methods, alarm_vars)


async def _variables_by_path(node: Node, prefix: str, out: dict[str, ua.NodeId]) -> None:
    for child in await node.get_children(refs=ua.ObjectIds.Aggregates, nodeclassmask=ua.NodeClass.Variable):
        path = prefix + str((await child.read_browse_name()).Name)
        out[path] = child.nodeid
        await _variables_by_path(child, path + "/", out)
