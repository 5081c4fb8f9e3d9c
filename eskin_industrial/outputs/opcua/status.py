"""Status codes: what a value's quality says when the bridge is not deciding.

Every variable of a node belongs to one of three groups, and each group's status
follows from the node's snapshot and its source (pure code, one place):

- **decision** (the grasp state, slip, contact, the indicators and scores): Good only
  while the bridge decides: enabled, the sensor fresh, the verdict valid;
- **measurement** (total force, centre of force, the taxel frame): Good while the
  sensor is fresh, whether or not detection is enabled;
- **fact** (validity, the slip latch, enable, the health conditions, the counters, the
  method): what the bridge knows about itself, Good until the bridge stops.

| condition (first that applies) | decision | measurement | fact |
|---|---|---|---|
| the bridge stopped (the last snapshot) | BadOutOfService | BadOutOfService | BadOutOfService (Offline: Good) |
| the node's source failed (a corrupt log) | BadDeviceFailure | BadDeviceFailure | Good |
| the node's source ended (a finished replay) | BadOutOfService | BadOutOfService | Good |
| bus fault | BadNoCommunication | BadNoCommunication | Good |
| a sensor fault (Flags DEAD_TAXELS, FROZEN, RATE, STREAM) | BadSensorFailure | BadSensorFailure | Good |
| no scan yet since start | BadWaitingForInitialData | BadWaitingForInitialData | Good |
| (before any: the server up, the node's first snapshot not yet in) | BadWaitingForInitialData | BadWaitingForInitialData | BadWaitingForInitialData |
| sensor stale (no scan for ``stale_s``) | UncertainLastUsableValue | UncertainLastUsableValue | Good |
| ... for ``bad_after_s`` (default 1 s) | BadNoCommunication | BadNoCommunication | Good |
| detection disabled | BadOutOfService | Good | Good |
| claimed, not a verdict (warm-up) | Uncertain | Good | Good |
| deciding | Good | Good | Good |

A Bad status carries no value (OPC UA Part 4, 7.7.1: the value is null); an
Uncertain one carries the last value written.
"""

from __future__ import annotations

from typing import Literal, NamedTuple

from ...node import NodeSnapshot

GOOD = 0x00000000
UNCERTAIN = 0x40000000
UNCERTAIN_LAST_USABLE_VALUE = 0x40900000
BAD_WAITING_FOR_INITIAL_DATA = 0x80320000
BAD_NO_COMMUNICATION = 0x80310000
BAD_OUT_OF_SERVICE = 0x808D0000
BAD_DEVICE_FAILURE = 0x808B0000
BAD_SENSOR_FAILURE = 0x808C0000
#: Method results.
BAD_INVALID_STATE = 0x80AF0000
BAD_USER_ACCESS_DENIED = 0x801F0000
BAD_TOO_MANY_OPERATIONS = 0x80100000
BAD_EVENT_ID_UNKNOWN = 0x809A0000
BAD_CONDITION_BRANCH_ALREADY_ACKED = 0x80CF0000
BAD_CONDITION_ALREADY_DISABLED = 0x80980000
BAD_CONDITION_ALREADY_ENABLED = 0x80CC0000
BAD_CONDITION_DISABLED = 0x80990000

NAMES: dict[int, str] = {
    GOOD: "Good", UNCERTAIN: "Uncertain", UNCERTAIN_LAST_USABLE_VALUE: "UncertainLastUsableValue",
    BAD_WAITING_FOR_INITIAL_DATA: "BadWaitingForInitialData", BAD_NO_COMMUNICATION: "BadNoCommunication",
    BAD_OUT_OF_SERVICE: "BadOutOfService", BAD_DEVICE_FAILURE: "BadDeviceFailure",
    BAD_SENSOR_FAILURE: "BadSensorFailure",
    BAD_INVALID_STATE: "BadInvalidState", BAD_USER_ACCESS_DENIED: "BadUserAccessDenied",
    BAD_TOO_MANY_OPERATIONS: "BadTooManyOperations", BAD_EVENT_ID_UNKNOWN: "BadEventIdUnknown",
    BAD_CONDITION_BRANCH_ALREADY_ACKED: "BadConditionBranchAlreadyAcked",
    BAD_CONDITION_ALREADY_DISABLED: "BadConditionAlreadyDisabled",
    BAD_CONDITION_ALREADY_ENABLED: "BadConditionAlreadyEnabled", BAD_CONDITION_DISABLED: "BadConditionDisabled",
}

Group = Literal["decision", "measurement", "fact"]
#: What became of the node's source: still running, ended cleanly, or failed.
SourceEnd = Literal["", "ended", "failed"]


class Quality(NamedTuple):
    decision: int
    measurement: int
    fact: int


_DECIDING = Quality(GOOD, GOOD, GOOD)


def is_bad(code: int) -> bool:
    return code & 0x80000000 != 0


def is_uncertain(code: int) -> bool:
    return code & 0xC0000000 == 0x40000000


def quality(s: NodeSnapshot, source: SourceEnd = "", bad_after_s: float = 1.0) -> Quality:
    """The three groups' status codes for this snapshot (the module's table)."""
    if s.offline:
        return Quality(BAD_OUT_OF_SERVICE, BAD_OUT_OF_SERVICE, BAD_OUT_OF_SERVICE)
    if source == "failed":
        return Quality(BAD_DEVICE_FAILURE, BAD_DEVICE_FAILURE, GOOD)
    if source == "ended":
        return Quality(BAD_OUT_OF_SERVICE, BAD_OUT_OF_SERVICE, GOOD)
    if s.bus_fault:
        return Quality(BAD_NO_COMMUNICATION, BAD_NO_COMMUNICATION, GOOD)
    if s.sensor_fault:  # dead taxels, a frozen sensor, a rate far from the profile's
        return Quality(BAD_SENSOR_FAILURE, BAD_SENSOR_FAILURE, GOOD)
    if s.f_sum_n is None:  # no update since start
        return Quality(BAD_WAITING_FOR_INITIAL_DATA, BAD_WAITING_FOR_INITIAL_DATA, GOOD)
    if s.stale:
        age = s.frame_age_s
        if age is None or not age < bad_after_s:  # (a NaN age: silent too)
            return Quality(BAD_NO_COMMUNICATION, BAD_NO_COMMUNICATION, GOOD)
        return Quality(UNCERTAIN_LAST_USABLE_VALUE, UNCERTAIN_LAST_USABLE_VALUE, GOOD)
    if not s.enabled:
        return Quality(BAD_OUT_OF_SERVICE, GOOD, GOOD)
    if not s.valid:
        return Quality(UNCERTAIN, GOOD, GOOD)
    return _DECIDING


def machinery_state(s: NodeSnapshot, source: SourceEnd = "") -> str:
    """The node's MachineryItemState (OPC 40001-1's names): Executing while a state is
    claimed; NotExecuting when disabled or before the first scan; OutOfService when
    the sensor is stale, its bus fails or its source failed; NotAvailable when the
    bridge stopped or the source ended."""
    if s.offline or source == "ended":
        return "NotAvailable"
    if source == "failed" or s.bus_fault or s.sensor_fault or (s.stale and s.f_sum_n is not None):
        return "OutOfService"
    if s.state is None:
        return "NotExecuting"
    return "Executing"


def operation_mode(s: NodeSnapshot) -> str:
    """The node's MachineryOperationMode (OPC 40001-1's names): Processing while
    detection is enabled, Setup while it is disabled (what an operator does while
    setting the gripper up: a tare, a changeover), None once the bridge has stopped.
    The bridge knows nothing of maintenance: never Maintenance."""
    if s.offline:
        return "None"
    return "Processing" if s.enabled else "Setup"
