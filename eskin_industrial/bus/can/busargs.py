"""python-can's bus arguments beyond interface, channel and bit rates, in python-can's
own syntax (``can.logger``, ``can.viewer``): ``--timing KEY=INT ...``, ``--filter
ID:MASK ...`` (hexadecimal), ``--bus-kwargs KEY=VALUE ...``; and the bit rate that
python-can's configuration resolves, so that the profile's rate is only the default.

Parsing is pure: text in, plain values out, ``ValueError`` naming what is wrong.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from typing import Any

import can
from can.typechecking import BitTimingDict, BitTimingFdDict
from can.util import cast_from_string

#: python-can's ``CAN_INV_FILTER`` (an inverted SocketCAN filter, ``ID~MASK``)
CAN_INV_FILTER = 0x20000000
_KWARG = re.compile(r"^(?P<name>[_a-zA-Z][_a-zA-Z0-9]*)=(?P<value>\S*)$")
#: Interfaces that take no bit rate (the kernel or nothing sets it).
NO_BITRATE = ("virtual", "socketcan")


def _words(items: Iterable[str]) -> list[str]:
    """Each option may be repeated and each value may hold several space-separated
    words: ``--timing "f_clock=8000000 brp=2" --timing tseg1=5`` is one list."""
    return [w for item in items for w in item.split()]


def parse_bus_kwargs(items: Iterable[str]) -> dict[str, int | float | str | bool]:
    """``KEY=VALUE`` words to keyword arguments of the bus class, values cast as
    python-can casts them (``1234`` an int, ``true`` a bool, ``1.5`` a float)."""
    out: dict[str, int | float | str | bool] = {}
    for word in _words(items):
        m = _KWARG.match(word)
        if not m:
            raise ValueError(f"expected KEY=VALUE, got {word!r}")
        out[m["name"]] = cast_from_string(m["value"])
    return out


def parse_timing(items: Iterable[str]) -> dict[str, int]:
    """``KEY=INT`` words to a bit timing table (checked by :func:`make_timing`)."""
    table: dict[str, int] = {}
    for word in _words(items):
        key, sep, value = word.partition("=")
        try:
            if not sep:
                raise ValueError
            table[key] = int(value, 0)
        except ValueError:
            raise ValueError(f"expected KEY=INTEGER, got {word!r}") from None
    if table:
        make_timing(table)  # refused here, before anything opens
    return table


def make_timing(table: dict[str, int]) -> can.BitTiming | can.BitTimingFd:
    """python-can's bit timing object, as python-can's tools make it: every key of
    ``BitTimingFdDict`` (``nom_*``, ``data_*``) makes a CAN FD timing, every key of
    ``BitTimingDict`` a classic one, checked non-strictly (``strict=False``, as there);
    a missing or unknown key is refused here, where python-can would drop the timing."""
    fd = any(k.startswith(("nom_", "data_")) for k in table)
    cls: Any = can.BitTimingFd if fd else can.BitTiming
    keys = list((BitTimingFdDict if fd else BitTimingDict).__annotations__)
    missing = [k for k in keys if k not in table]
    unknown = [k for k in table if k not in keys]
    if missing or unknown:
        what = "; ".join(x for x in (f"missing {', '.join(missing)}" if missing else "",
                                     f"unknown {', '.join(unknown)}" if unknown else "") if x)
        raise ValueError(f"{'CAN FD ' if fd else ''}timing: {what} (keys: {' '.join(keys)})")
    try:
        return cls(**table, strict=False)
    except ValueError as exc:
        raise ValueError(f"timing {table}: {exc}") from None


def parse_filters(items: Iterable[str]) -> list[dict[str, int]]:
    """python-can's filter syntax, hexadecimal: ``ID:MASK`` matches when
    ``received & MASK == ID & MASK``; ``ID~MASK`` when it does not (SocketCAN only)."""
    out: list[dict[str, int]] = []
    for word in _words(items):
        sep = ":" if ":" in word else "~" if "~" in word else None
        if sep is None:
            raise ValueError(f"expected ID:MASK or ID~MASK in hexadecimal, got {word!r}")
        ident, _, mask = word.partition(sep)
        try:
            can_id, can_mask = int(ident, 16), int(mask, 16)
        except ValueError:
            raise ValueError(f"expected ID:MASK or ID~MASK in hexadecimal, got {word!r}") from None
        if not (0 <= can_id <= 0x1FFFFFFF and 0 <= can_mask <= 0x1FFFFFFF):
            raise ValueError(f"{word!r}: ID and MASK are 29-bit values at most")
        out.append({"can_id": can_id | (CAN_INV_FILTER if sep == "~" else 0), "can_mask": can_mask})
    return out


def configured(interface: str | None, channel: str | None) -> dict[str, Any]:
    """What python-can's configuration makes of the given interface and channel: its
    config files, ``can.rc``, ``CAN_INTERFACE``/``CAN_CHANNEL``/``CAN_BITRATE`` and
    ``CAN_CONFIG`` fill in what is not given (the command line wins), exactly as
    ``can.Bus`` and python-can's own tools resolve them."""
    given = {k: v for k, v in (("interface", interface), ("channel", channel)) if v is not None}
    try:
        return dict(can.util.load_config(config=dict(given)))
    except (can.CanInterfaceNotImplementedError, ValueError, TypeError):
        return given  # no interface anywhere, or an unknown one: can.Bus says which
