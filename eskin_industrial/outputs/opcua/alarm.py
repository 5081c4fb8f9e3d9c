"""The slip alarm's state, as OPC UA's AlarmConditionType keeps it (Part 9): active,
acknowledged, retained.  Pure code: :mod:`.server` turns each transition into an
event of ``SlipAlarmType``.

- Each entry into slip raises it: ActiveState true, AckedState false, Retain true
  (a new slip while it is still active raises it again: one event per slip).
- The slip's end clears ActiveState: a claimed state other than slip, or the bridge
  stopping.  While nothing is claimed (detection disabled, the sensor stale) the alarm
  stays as it was: the same slip claimed again is not a new alarm.  The condition
  stays retained until it has been acknowledged, so that a SCADA's alarm list keeps an
  unacknowledged slip that is already over.
- Acknowledge (with the EventId of one of this slip's events) sets AckedState; an
  acknowledged, inactive condition is no longer retained.  Another EventId is
  BadEventIdUnknown; a second acknowledge is BadConditionBranchAlreadyAcked.
- Disable (ConditionType, Part 9 5.5.4) sets EnabledState false; its event says
  Retain false, so that a SCADA's alarm list drops it, and the alarm raises nothing
  while disabled (the slip is followed, not told).  Enable sets it true again, and its
  event tells the condition as it is then: a slip still on comes back active and
  unacknowledged.  A second Disable is BadConditionAlreadyDisabled, a second Enable
  BadConditionAlreadyEnabled; Acknowledge and AddComment on a disabled alarm are
  BadConditionDisabled.
- AddComment (with the EventId of one of this condition's events since its last raise,
  else BadEventIdUnknown) sets Comment and ClientUserId, and is an event of its own.

Acknowledging the alarm is the operator's business in the SCADA: it does not clear
the slip latch the PLC reads (the method AcknowledgeSlip does that).
"""

from __future__ import annotations

import uuid
from typing import Literal

from ...node import NodeSnapshot
from .status import (
    BAD_CONDITION_ALREADY_DISABLED,
    BAD_CONDITION_ALREADY_ENABLED,
    BAD_CONDITION_BRANCH_ALREADY_ACKED,
    BAD_CONDITION_DISABLED,
    BAD_EVENT_ID_UNKNOWN,
    GOOD,
)

_SLIP = 3  #: GraspState.SLIP

Transition = Literal["raised", "cleared", "acknowledged", "disabled", "enabled", "commented"]


class AlarmState:
    """One node's slip alarm."""

    def __init__(self) -> None:
        self.active = False
        self.acked = True
        self.retain = False
        self.enabled = True
        self.slip_events = 0  #: the node's count at the last raise
        self.event_id = b""  #: of the newest event
        self._ids: set[bytes] = set()  #: this slip's events, any of which may be acknowledged
        self.raised = 0
        self.acknowledged = 0

    def observe(self, s: NodeSnapshot) -> Transition | None:
        """The transition this snapshot makes, if any (then :attr:`event_id` is new)."""
        slip = s.state == _SLIP
        if not self.enabled:  # followed, not told: Enable tells the state as it is then
            if slip:
                self.active = True
                self.slip_events = s.slip_events
            elif s.state is not None or s.offline:
                self.active = False
            return None
        if slip and (not self.active or s.slip_events > self.slip_events):
            self.active, self.acked, self.retain = True, False, True
            self.slip_events = s.slip_events
            self.raised += 1
            self._ids.clear()
            self._new_id()
            return "raised"
        if self.active and not slip and (s.state is not None or s.offline):
            self.active = False
            self.retain = not self.acked
            self._new_id()
            return "cleared"
        return None

    def acknowledge(self, event_id: bytes) -> int:
        """An Acknowledge call's result code; on Good the transition is made."""
        if not self.enabled:
            return BAD_CONDITION_DISABLED
        if event_id not in self._ids:
            return BAD_EVENT_ID_UNKNOWN
        if self.acked:
            return BAD_CONDITION_BRANCH_ALREADY_ACKED
        self.acked = True
        self.retain = self.active
        self.acknowledged += 1
        self._new_id()
        return GOOD

    def disable(self) -> int:
        """A Disable call's result code; on Good the transition is made."""
        if not self.enabled:
            return BAD_CONDITION_ALREADY_DISABLED
        self.enabled = False
        self.retain = False
        self._new_id()
        return GOOD

    def enable(self) -> int:
        """An Enable call's result code; on Good the transition is made."""
        if self.enabled:
            return BAD_CONDITION_ALREADY_ENABLED
        self.enabled = True
        self.acked = not self.active  # (a slip still on is told as a new one: unacknowledged)
        self.retain = self.active
        self._ids.clear()
        self._new_id()
        return GOOD

    def comment(self, event_id: bytes) -> int:
        """An AddComment call's result code; on Good the new event's id is made."""
        if not self.enabled:
            return BAD_CONDITION_DISABLED
        if event_id not in self._ids:
            return BAD_EVENT_ID_UNKNOWN
        self._new_id()
        return GOOD

    def _new_id(self) -> None:
        self.event_id = uuid.uuid4().bytes
        self._ids.add(self.event_id)
