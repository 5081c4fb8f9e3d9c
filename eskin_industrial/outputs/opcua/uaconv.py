"""asyncua's typed scalars from plain Python values (its constructors are typed with
``UInt32``, ``Int32``, ``Int16``, ``DateTime``): one place for the conversions, so
that the rest reads as plain ints, strings and datetimes."""

from __future__ import annotations

import datetime
from typing import cast

from asyncua import ua


def node_id(identifier: int | str, ns: int = 0) -> ua.NodeId:
    """A numeric or string node id in namespace ``ns``."""
    ident: ua.Int32 | ua.String = ua.Int32(identifier) if isinstance(identifier, int) else ua.String(identifier)
    return ua.NodeId(ident, ua.Int16(ns))


_CODES: dict[int, ua.StatusCode] = {}


def status_code(code: int) -> ua.StatusCode:
    """The status code object of ``code`` (made once: values are written with a few codes, often)."""
    made = _CODES.get(code)
    if made is None:
        made = _CODES[code] = ua.StatusCode(ua.UInt32(code))
    return made


def data_value(variant: ua.Variant, code: int, source: datetime.datetime, server: datetime.datetime) -> ua.DataValue:
    """A value with its status, source timestamp and server timestamp."""
    # (asyncua's DateTime is a datetime subclass it never checks for: a datetime is one)
    return ua.DataValue(variant, status_code(code), cast(ua.DateTime, source), cast(ua.DateTime, server))
