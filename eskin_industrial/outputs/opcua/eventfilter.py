"""The event filters a client sends with CreateMonitoredItems and ModifyMonitoredItems,
made safe before asyncua keeps them (Part 4, 7.22.3; :mod:`.itemcheck` calls this).

asyncua reads a filter only when an event fires, on the server's loop: a null array
(length -1 on the wire, None once decoded) in a select clause's BrowsePath made it
raise there (``len(None)``), in the slip alarm's path.  open62541 selects the
ConditionId that way (TypeDefinitionId ConditionType, AttributeId NodeId, a null
BrowsePath; Part 9, 5.5.2).  So, at the request:

- every null array in the request is made empty (Part 6, 5.2.5: a null array and an
  empty one mean the same to the receiver); a select clause with an empty BrowsePath
  and AttributeId NodeId then selects the condition's NodeId (the event's ``NodeId``
  field);
- a filter asyncua would fail on later is refused now: BadEventFilterInvalid with a
  result per select clause (BadBrowseNameInvalid for a null or empty browse name,
  BadAttributeIdInvalid for an attribute that does not exist, Good for the others);
  an event item whose filter is no EventFilter is BadEventFilterInvalid.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from asyncua import ua

from .uaconv import status_code

_ATTRIBUTES = frozenset(int(a) for a in ua.AttributeIds)
_GOOD = status_code(ua.StatusCodes.Good)


def empty_null_arrays(value: Any) -> None:
    """Every null array in a decoded request's structures made empty, in place (a
    Variant's value and dimensions are left as they are: there a null is a value)."""
    if isinstance(value, list):
        for item in value:
            empty_null_arrays(item)
        return
    if not dataclasses.is_dataclass(value) or isinstance(value, (type, ua.Variant, ua.NodeId)):
        return
    for f in dataclasses.fields(value):
        v = getattr(value, f.name)
        if v is None:
            if str(f.type).strip("'\"").startswith("list["):  # (asyncua's annotations are strings, quoted)
                setattr(value, f.name, [])
        else:
            empty_null_arrays(v)


def event_filter_problem(flt: Any) -> tuple[ua.StatusCode, Any] | None:
    """Why an event item's filter is refused, with its filter result; None: it is fine."""
    if not isinstance(flt, ua.EventFilter):
        return status_code(ua.StatusCodes.BadEventFilterInvalid), ua.ExtensionObject()
    results = [_select_result(c) for c in flt.SelectClauses]
    if all(r.is_good() for r in results):
        return None
    return status_code(ua.StatusCodes.BadEventFilterInvalid), ua.EventFilterResult(SelectClauseResults=results)


def _select_result(clause: ua.SimpleAttributeOperand) -> ua.StatusCode:
    if int(clause.AttributeId) not in _ATTRIBUTES:
        return status_code(ua.StatusCodes.BadAttributeIdInvalid)
    if any(not q.Name for q in clause.BrowsePath):
        return status_code(ua.StatusCodes.BadBrowseNameInvalid)
    return _GOOD
