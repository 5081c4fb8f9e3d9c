"""The information model as data: the namespace, the types' names, every variable of
a node with its data type, unit, status group and meaning, and the values of one
snapshot.  Pure code: :mod:`.build` turns it into nodes, ``docs/opcua.md`` shows it
(:func:`model_tree`, kept equal to the page by a test).

One object per sensor node under OPC 40001-1's ``Objects/Machines``, of the object
type ``GraspSensorType``, with its nameplate and state machines as that specification
lays them out; its variables, by browse path (``Health/SensorStale``), are
:data:`VARIABLES`.  Browse names are fixed: a SCADA tag stays valid whichever method
decides; the scores' display names are the method's own (``onset_score``), as
``eskin-bus plc map`` names them.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

from ...detect.state import LABELS
from .status import Group

#: Our namespace (the types and the nodes' objects).
NAMESPACE_URI = "urn:eskin-industrial:opcua:grasp"

#: Fixed numeric ids of the type model in our namespace (the NodeSet2 keeps them).
TYPE_IDS = {
    "GraspStateEnumeration": 3001,
    "GraspSensorType": 1001,
    "SlipAlarmType": 1101,
}
#: The enumeration's names: the project's state labels, codes 0..3 as the PLC's STATE.
STATE_NAMES: tuple[str, ...] = LABELS

#: UNECE Recommendation 20 codes (OPC UA Part 8, EUInformation), by our unit.
UNITS: dict[str, tuple[int, str]] = {
    "N": (5129559, "newton"),  # NEW
    "mm": (5066068, "millimetre"),  # MMT
    "s": (5457219, "second"),  # SEC
}
UNECE_NAMESPACE = "http://www.opcfoundation.org/UA/units/un/cefact"


class Var(NamedTuple):
    """One variable of a node, a component of ``GraspSensorType``."""

    path: str  #: browse path under the node's object, ``/`` between names
    datatype: str  #: Boolean, Double, UInt16, UInt32, UInt64, String, GraspStateEnumeration, Float
    group: Group  #: whose status it takes (:func:`.status.quality`)
    doc: str
    unit: str = ""  #: N, mm, s (EngineeringUnits)
    analog: bool = False  #: an AnalogItemType, with EURange (and EngineeringUnits)


#: Every variable of a node, in the order of :func:`values`.
VARIABLES: tuple[Var, ...] = (
    Var("GraspState", "GraspStateEnumeration", "decision",
        "the grasp state: no_contact (0), stable (1), variable_force (2), slip (3)"),
    Var("GraspStateName", "String", "decision", "the grasp state's name"),
    Var("StateValid", "Boolean", "fact", "the state is a verdict: claimed, indicators valid, no bus fault"),
    Var("Slip", "Boolean", "decision", "slip now"),
    Var("Contact", "Boolean", "decision", "in contact (any state but no_contact)"),
    Var("TurnUnseen", "Boolean", "decision",
        "in contact, but a turn about the skin's normal would go unseen: read stable (FLAGS bit TURN_UNSEEN)"),
    Var("SlipLatched", "Boolean", "fact", "a slip since the last acknowledge (set while the slip lasts)"),
    Var("Enabled", "Boolean", "fact", "detection enabled"),
    Var("Health/SensorStale", "Boolean", "fact", "no scan for longer than the profile's stale_s"),
    Var("Health/BusFault", "Boolean", "fact", "the sensor bus fails"),
    Var("Health/Offline", "Boolean", "fact", "the bridge has stopped: nothing is claimed"),
    Var("Health/FrameAge", "Double", "fact", "age of the newest scan at publication", "s"),
    Var("Indicators/R_coe", "Double", "decision", "the paper's decorrelation indicator, whatever method decides"),
    Var("Indicators/R_dw", "Double", "decision", "the paper's wavelet detail energy indicator, whatever method decides"),
    Var("Scores/ScoreA", "Double", "decision", "the deciding method's first score (display name: its own name)"),
    Var("Scores/ScoreB", "Double", "decision", "the deciding method's second score (display name: its own name)"),
    Var("TotalForce", "Double", "measurement", "total force of the newest frame", "N", True),
    Var("CentreOfForceX", "Double", "measurement", "centre of force, x (held while out of contact)", "mm", True),
    Var("CentreOfForceY", "Double", "measurement", "centre of force, y (held while out of contact)", "mm", True),
    Var("Flags", "UInt32", "measurement", "the newest update's frame and update flags (FrameFlag)"),
    Var("Counters/SlipEvents", "UInt32", "fact", "entries into slip since start"),
    Var("Counters/StateChanges", "UInt32", "fact", "changes of the state since start"),
    Var("Counters/LostScans", "UInt32", "fact", "failed polls and sequence gaps"),
    Var("Counters/BusErrors", "UInt32", "fact", "the transport's error count"),
    Var("Counters/Scans", "UInt64", "fact", "scans the node's loop has taken since start"),
    Var("Method", "String", "fact", "the deciding method's name"),
    Var("MethodCode", "UInt16", "fact", "its fixed number (as the PLC's METHOD_ID)"),
)
#: Every Boolean variable is a TwoStateDiscreteType (Part 8): its TrueState and
#: FalseState, what a client shows for true and false.
FLAG_STATES: dict[str, tuple[str, str]] = {
    "StateValid": ("verdict", "no verdict"),
    "Slip": ("slip", "no slip"),
    "Contact": ("contact", "no contact"),
    "TurnUnseen": ("turn unseen", "turn seen"),
    "SlipLatched": ("slip latched", "no slip since acknowledge"),
    "Enabled": ("enabled", "disabled"),
    "Health/SensorStale": ("stale", "fresh"),
    "Health/BusFault": ("bus fault", "bus ok"),
    "Health/Offline": ("offline", "online"),
}
#: The taxel frame: a component only with ``frame_interval_s`` (its ModellingRule: Optional).
FRAME = Var("Taxels", "Float", "measurement",
            "the calibrated taxel frame, rows x cols (ArrayDimensions), row-major, NaN for a refused reading",
            "N", True)
#: The folders of the variables (objects of FolderType under the node's object).
FOLDERS: tuple[str, ...] = ("Health", "Indicators", "Scores", "Counters")
#: The nameplate: properties of OPC 40001-1's MachineIdentificationType, browse names
#: in the DI namespace (OPC 10000-100); the first three are the type's mandatory ones.
IDENTIFICATION: tuple[tuple[str, str, str], ...] = (
    ("Manufacturer", "LocalizedText", "[identity] vendor_name of the bridge configuration"),
    ("SerialNumber", "String", "the node's name (its [[node]] name)"),
    ("ProductInstanceUri", "String", "urn:VENDOR:PRODUCT_CODE:SERIAL_NUMBER"),
    ("Model", "LocalizedText", "the profile's [sensor] name (model_name when given)"),
    ("ProductCode", "String", "[identity] product_code of the bridge configuration"),
    ("SoftwareRevision", "String", "the package's version"),
    ("ComponentName", "LocalizedText", "the node's name"),
)
#: OPC 40001-1's MachineIdentificationType, in the Machinery namespace.
MACHINE_IDENTIFICATION_TYPE = 1012
#: The state machines of OPC 40001-1 under the node's ``MachineryBuildingBlocks``:
#: browse name -> (their type, each state's name and NodeId in the Machinery namespace,
#: as the specification numbers them; CurrentState/Id is that NodeId).
STATE_MACHINES: dict[str, tuple[int, dict[str, int]]] = {
    "MachineryItemState": (1002, {"NotAvailable": 5005, "OutOfService": 5004, "NotExecuting": 5007,
                                  "Executing": 5006}),
    "MachineryOperationMode": (1008, {"None": 5024, "Maintenance": 5025, "Setup": 5027, "Processing": 5026}),
}
#: Before the node's first snapshot is applied: no scan yet, no mode claimed.
INITIAL_STATES = {"MachineryItemState": "NotExecuting", "MachineryOperationMode": "None"}
MACHINERY_STATES = ("Executing", "NotExecuting", "OutOfService", "NotAvailable")
OPERATION_MODES = ("Processing", "Setup", "None")  #: the ones the bridge takes (never Maintenance)
#: The methods of a node: (name, input argument or None, what it does).
METHODS: tuple[tuple[str, tuple[str, str] | None, str], ...] = (
    ("Tare", None, "tare with the gripper open (refused in contact or without a verdict: BadInvalidState)"),
    ("AcknowledgeSlip", None, "acknowledge the slip latch (it stays set while the slip lasts)"),
    ("Enable", ("Enabled", "Boolean"), "true: enable detection, false: disable it"),
)
#: The slip alarm's own fields beyond AlarmConditionType's.
ALARM_FIELDS: tuple[tuple[str, str, str], ...] = (
    ("ScoreA", "Double", "the deciding method's first score at the slip's entry"),
    ("ScoreB", "Double", "its second score"),
    ("ScoreNames", "String", "the two scores' names, comma-separated"),
    ("R_coe", "Double", "the paper's R_coe at the entry"),
    ("R_dw", "Double", "the paper's R_dw at the entry"),
    ("Delay", "Double", "seconds from the deciding scan's arrival to the alarm's raise (the bridge's own delay)"),
    ("SensorTime", "Double", "the deciding update's time on the sensor's clock (s)"),
    ("SlipEvents", "UInt32", "entries into slip since start, this one included"),
)
INDEX = {v.path: i for i, v in enumerate(VARIABLES)}
GROUPS: tuple[Group, ...] = tuple(v.group for v in VARIABLES)


def _real(v: float | None) -> float | None:
    """A Double's value: None stays None (no value), NaN and infinities too (a client
    must not read them as numbers)."""
    return float(v) if v is not None and math.isfinite(v) else None


def values(s: Any) -> tuple[Any, ...]:
    """The variables of one snapshot, in :data:`VARIABLES` order; None where the
    snapshot has no value (no state claimed, no scan yet): the variable then keeps its
    last value under an Uncertain status, or none under a Bad one."""
    state = s.state
    age = s.frame_age_s
    return (
        state,
        None if state is None else (LABELS[state] if state < len(LABELS) else str(state)),
        s.valid,
        None if state is None else state == _SLIP,
        None if state is None else state != _NO_CONTACT,
        None if state is None else s.turn_unseen,
        s.slip_latched,
        s.enabled,
        s.stale,
        s.bus_fault,
        s.offline,
        None if age is None or not math.isfinite(age) else float(age),
        _real(s.r_coe),
        _real(s.r_dw),
        _real(s.score_a),
        _real(s.score_b),
        _real(s.f_sum_n),
        _real(s.xc_mm),
        _real(s.yc_mm),
        None if s.f_sum_n is None else s.flags & 0xFFFFFFFF,
        s.slip_events & 0xFFFFFFFF,
        s.state_changes & 0xFFFFFFFF,
        s.lost_scans & 0xFFFFFFFF,
        s.bus_errors & 0xFFFFFFFF,
        s.scans,
        s.method,
        s.method_code,
    )


_SLIP = 3  #: GraspState.SLIP
_NO_CONTACT = 0


def model_tree(rows: int = 5, cols: int = 5) -> list[str]:
    """The model as a tree (``docs/opcua.md``): one node's object and what it holds."""
    def kind(v: Var) -> str:
        unit = f", {v.unit}" if v.unit else ""
        return f"({v.datatype}{unit}, {variable_type(v)}, {v.group})"

    # (name, what, children): the node's object's children in the order a browse lists them
    top: list[tuple[str, str, list[str]]] = [
        ("DI:Identification", "(MachineIdentificationType, HasAddIn)",
         [f"DI:{name}  ({dtype}, property)" for name, dtype, _ in IDENTIFICATION]),
        ("Machinery:MachineryBuildingBlocks", "(FolderType)", [
            "DI:Identification  (HasAddIn: the nameplate above)",
            "Machinery:MachineryItemState  (MachineryItemState_StateMachineType, HasAddIn): CurrentState, "
            "CurrentState/Id: " + ", ".join(MACHINERY_STATES),
            "Machinery:MachineryOperationMode  (MachineryOperationModeStateMachineType, HasAddIn): CurrentState, "
            "CurrentState/Id: " + ", ".join(OPERATION_MODES)]),
    ]
    for folder in FOLDERS:
        top.append((folder, "(FolderType)", [f"{v.path.rpartition('/')[2]}  {kind(v)}" for v in VARIABLES
                                              if v.path.startswith(folder + "/")]))
    top += [(v.path, kind(v), []) for v in VARIABLES if "/" not in v.path]
    top.append((FRAME.path, f"(Float[{rows}][{cols}], N, AnalogItemType, measurement; with frame_interval_s only)",
                []))
    top.append(("SlipAlarm", "(SlipAlarmType, an AlarmConditionType)", []))
    top += [(f"{name}({'' if arg is None else arg[0] + ': ' + arg[1]})", "(method)", []) for name, arg, _ in METHODS]
    out = ["Objects", "└─ Machinery:Machines  (FolderType, OPC 40001-1)", "   └─ NODE  (GraspSensorType)  one per [[node]]"]
    for k, (name, what, children) in enumerate(top):
        last = k == len(top) - 1
        out.append(f"      {'└' if last else '├'}─ {name}  {what}")
        for c, child in enumerate(children):
            out.append(f"      {' ' if last else '│'}  {'└' if c == len(children) - 1 else '├'}─ {child}")
    return out


def variable_type(v: Var) -> str:
    """The variable's type definition (Part 8's for measurements and flags)."""
    if v.analog:
        return "AnalogItemType"
    return "TwoStateDiscreteType" if v.datatype == "Boolean" else "BaseDataVariableType"


def variable_table() -> list[str]:
    """The variables of a node (``docs/opcua.md``; a test keeps the page equal to it)."""
    rows = ["| browse path | data type | unit | status group | meaning |", "|---|---|---|---|---|"]
    for v in (*VARIABLES, FRAME):
        kind = " (AnalogItemType: EURange, EngineeringUnits)" if v.analog else ""
        if v.path in FLAG_STATES:
            kind = " (TwoStateDiscreteType: TrueState '{}', FalseState '{}')".format(*FLAG_STATES[v.path])
        dtype = "Float[rows][cols]" if v is FRAME else v.datatype
        rows.append(f"| `{v.path}` | {dtype} | {v.unit or '-'} | {v.group} | {v.doc}{kind} |")
    return rows
