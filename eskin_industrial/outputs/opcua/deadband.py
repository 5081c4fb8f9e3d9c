"""The deadbands of the data change filters clients send (Part 4, 7.22.2; Part 8,
6.2), checked and made whole before asyncua keeps them: asyncua logs a Percent
deadband as not implemented and reports every change, and subtracts arrays and
strings as numbers (an item that then never reports).

- The deadband is for the Value attribute of a variable of a number data type, else
  BadFilterNotAllowed; a deadband type other than None, Absolute, Percent, or a
  value below 0: BadDeadbandFilterInvalid.
- Percent: 0 to 100 of the item's EURange (an AnalogItem's), taken as the Absolute
  deadband ``value / 100 * (High - Low)`` it stands for; without an EURange that
  spans something, or above 100: BadDeadbandFilterInvalid.
- A change is measured from the value last reported, and an array's deadband applies
  to each element: a change of any element beyond it reports the array
  (:func:`exceeded`, in place of asyncua's for this server).
"""

from __future__ import annotations

import math
from typing import Any

from asyncua import ua

from .typeinfo import NUMBERS, TypeInfo

_NONE, _ABSOLUTE, _PERCENT = ua.DeadbandType.None_, ua.DeadbandType.Absolute, ua.DeadbandType.Percent
_NUMERIC = NUMBERS[ua.ObjectIds.Number] | frozenset(NUMBERS)


def deadband_problem(types: TypeInfo, nodeid: ua.NodeId, attr: int, flt: ua.DataChangeFilter) -> int | None:
    """Why the filter is refused (a status code), or None; a Percent deadband is
    turned into its Absolute one, in place."""
    kind = int(flt.DeadbandType)
    if kind == _NONE:
        return None
    if kind not in (_ABSOLUTE, _PERCENT) or not flt.DeadbandValue >= 0:  # (NaN too)
        return ua.StatusCodes.BadDeadbandFilterInvalid
    data_type = types.attribute(nodeid, ua.AttributeIds.DataType) if nodeid in types else None
    if attr != ua.AttributeIds.Value or data_type is None or types.kind(data_type) not in _NUMERIC:
        return ua.StatusCodes.BadFilterNotAllowed
    if kind == _PERCENT:
        rng = types.property_value(nodeid, "EURange")
        span = (rng.High - rng.Low) if isinstance(rng, ua.Range) else math.nan
        if flt.DeadbandValue > 100 or not span > 0 or math.isinf(span):
            return ua.StatusCodes.BadDeadbandFilterInvalid
        flt.DeadbandType = _ABSOLUTE
        flt.DeadbandValue = flt.DeadbandValue / 100.0 * span
    return None


def exceeded(values: Any, flt: ua.DataChangeFilter) -> bool:
    """A change beyond the item's Absolute deadband from the value last reported
    (Part 4's "last cached value"; asyncua compares with the last value written, so
    that a slow drift in small steps would never be reported), element by element for
    an array; a change of status is always reported.  In place of asyncua's
    ``MonitoredItemService._is_deadband_exceeded``."""
    if flt.DeadbandType == _NONE:
        return True
    cur = values.get_current_datavalue()
    last = getattr(values, "reported", None)
    if (last is not None and cur is not None and cur.Value is not None and last.Value is not None
            and cur.StatusCode == last.StatusCode
            and not _changed(cur.Value.Value, last.Value.Value, flt.DeadbandValue)):
        return False
    values.reported = cur
    return True


def _changed(a: Any, b: Any, band: float) -> bool:
    if isinstance(a, list) or isinstance(b, list):
        if not (isinstance(a, list) and isinstance(b, list)) or len(a) != len(b):
            return True
        return any(_changed(x, y, band) for x, y in zip(a, b))
    try:
        d = abs(float(a) - float(b))
    except (TypeError, ValueError):
        return bool(a != b)
    if math.isnan(d):  # a NaN reading that comes or goes is a change
        return math.isnan(float(a)) != math.isnan(float(b))
    return d > band
