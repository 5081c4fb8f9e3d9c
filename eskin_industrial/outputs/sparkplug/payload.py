"""The Sparkplug B ``Payload`` protobuf message: bytes in, bytes out, no I/O.

Written by hand from the specification's field table (``sparkplug_b.proto``) so that
nothing is generated and no ``protoc`` runs at build time; the tests decode what this
encodes with the ``protobuf`` package and a schema of their own.  Covered: the
payload's timestamp, metrics, seq, uuid and body; a metric's name, alias, timestamp,
datatype, is_historical, is_transient, is_null, properties (a PropertySet of scalar
values) and scalar value, and the fixed-size numeric arrays of Sparkplug 3.0
(``Int8Array`` .. ``DoubleArray``, datatypes 22 to 31): their values packed
little-endian in ``bytes_value``, kept as those bytes here (:func:`pack_floats`,
:func:`unpack_floats` for ``FloatArray``).  Unknown fields are skipped, as protobuf does.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass

from ...errors import DecodeError

# Datatypes (the specification's table; the same codes serve PropertyValue types).
INT8, INT16, INT32, INT64 = 1, 2, 3, 4
UINT8, UINT16, UINT32, UINT64 = 5, 6, 7, 8
FLOAT, DOUBLE, BOOLEAN, STRING, DATETIME, TEXT, UUID, BYTES = 9, 10, 11, 12, 13, 14, 15, 17
#: Sparkplug 3.0's FloatArray: 32-bit IEEE floats packed little-endian in bytes_value
#: (the specification's text on array types, 6.4.17, and Eclipse Tahu's encoders; the
#: specification's worked FloatArray example prints big-endian bytes, a known erratum).
FLOAT_ARRAY = 30
#: The fixed-size arrays (Int8Array = 22 .. DoubleArray = 31) -> the size of one element.
ARRAY_ITEM_SIZE = {22: 1, 23: 2, 24: 4, 25: 8, 26: 1, 27: 2, 28: 4, 29: 8, FLOAT_ARRAY: 4, 31: 8}
_BYTES_FIELD = {BYTES, *ARRAY_ITEM_SIZE}  #: carried in bytes_value
_INT_FIELD = {INT8, INT16, INT32, UINT8, UINT16, UINT32}  #: carried in int_value (uint32)
_LONG_FIELD = {INT64, UINT64, DATETIME}  #: carried in long_value (uint64)
_SIGNED_BITS = {INT8: 32, INT16: 32, INT32: 32, INT64: 64}  #: two's complement in the carrier
_STRING_FIELD = {STRING, TEXT, UUID}

Value = int | float | bool | str | bytes | None


class PayloadError(DecodeError):
    """A payload that is not a Sparkplug B protobuf message."""


@dataclass(frozen=True)
class Metric:
    name: str | None = None
    alias: int | None = None
    timestamp: int | None = None
    datatype: int | None = None
    value: Value = None
    is_historical: bool | None = None
    is_transient: bool | None = None
    is_null: bool | None = None
    #: The PropertySet: (key, (type, value)) in order.
    properties: tuple[tuple[str, tuple[int, Value]], ...] = ()


@dataclass(frozen=True)
class Payload:
    timestamp: int | None = None
    metrics: tuple[Metric, ...] = ()
    seq: int | None = None
    uuid: str | None = None
    body: bytes | None = None


# -- encoding ------------------------------------------------------------------------
def _varint(n: int) -> bytes:
    n &= 0xFFFFFFFFFFFFFFFF  # negative numbers as 64-bit two's complement, as protobuf does
    out = bytearray()
    while n > 0x7F:
        out.append((n & 0x7F) | 0x80)
        n >>= 7
    out.append(n)
    return bytes(out)


def _key(field: int, wire: int) -> bytes:
    return _varint(field << 3 | wire)


def _uint(field: int, n: int) -> bytes:
    return _key(field, 0) + _varint(n)


def _bytes(field: int, data: bytes) -> bytes:
    return _key(field, 2) + _varint(len(data)) + data


def _value(datatype: int, value: Value, fields: dict[str, int]) -> bytes:
    """A scalar value in the field its datatype names (Metric and PropertyValue
    number these fields differently: ``fields``)."""
    if value is None:
        return b""
    if datatype in _INT_FIELD:
        return _uint(fields["int"], int(value) & 0xFFFFFFFF)
    if datatype in _LONG_FIELD:
        return _uint(fields["long"], int(value) & 0xFFFFFFFFFFFFFFFF)
    if datatype == FLOAT:
        return _key(fields["float"], 5) + struct.pack("<f", float(value))
    if datatype == DOUBLE:
        return _key(fields["double"], 1) + struct.pack("<d", float(value))
    if datatype == BOOLEAN:
        return _uint(fields["bool"], 1 if value else 0)
    if datatype in _STRING_FIELD:
        return _bytes(fields["string"], str(value).encode("utf-8"))
    if datatype in _BYTES_FIELD and "bytes" in fields:
        return _bytes(fields["bytes"], bytes(value))  # type: ignore[arg-type]
    raise ValueError(f"datatype {datatype}: not supported here")


_METRIC_VALUE = {"int": 10, "long": 11, "float": 12, "double": 13, "bool": 14, "string": 15, "bytes": 16}
_PROPERTY_VALUE = {"int": 3, "long": 4, "float": 5, "double": 6, "bool": 7, "string": 8}


def _encode_metric(m: Metric, datatypes: bool) -> bytes:
    out = bytearray()
    if m.name is not None:
        out += _bytes(1, m.name.encode("utf-8"))
    if m.alias is not None:
        out += _uint(2, m.alias)
    if m.timestamp is not None:
        out += _uint(3, m.timestamp)
    if m.datatype is not None and datatypes:
        out += _uint(4, m.datatype)
    for field, flag in ((5, m.is_historical), (6, m.is_transient), (7, m.is_null)):
        if flag is not None:
            out += _uint(field, int(flag))
    if m.properties:
        props = bytearray()
        for k, _ in m.properties:
            props += _bytes(1, k.encode("utf-8"))
        for _, (typ, v) in m.properties:
            pv = _uint(1, typ) + (_uint(2, 1) if v is None else _value(typ, v, _PROPERTY_VALUE))
            props += _bytes(2, pv)
        out += _bytes(9, bytes(props))
    if m.datatype is not None and not m.is_null:
        out += _value(m.datatype, m.value, _METRIC_VALUE)
    return bytes(out)


def encode(payload: Payload, *, datatypes: bool = True) -> bytes:
    """The payload's bytes.  ``datatypes=False`` leaves each metric's datatype off the
    wire (it still chooses the value's field): a data message after the birth, where
    the specification says the datatype SHOULD NOT be sent
    (tck-id-payloads-metric-datatype-not-req)."""
    out = bytearray()
    if payload.timestamp is not None:
        out += _uint(1, payload.timestamp)
    for m in payload.metrics:
        out += _bytes(2, _encode_metric(m, datatypes))
    if payload.seq is not None:
        out += _uint(3, payload.seq)
    if payload.uuid is not None:
        out += _bytes(4, payload.uuid.encode("utf-8"))
    if payload.body is not None:
        out += _bytes(5, payload.body)
    return bytes(out)


def pack_floats(values: Sequence[float]) -> bytes:
    """A FloatArray's bytes_value: each value as a little-endian 32-bit float."""
    return struct.pack(f"<{len(values)}f", *values)


def unpack_floats(data: bytes) -> tuple[float, ...]:
    """The values of a FloatArray's bytes_value; PayloadError if it is not whole floats."""
    if len(data) % 4:
        raise PayloadError(f"a FloatArray of {len(data)} bytes (not a multiple of 4)")
    return struct.unpack(f"<{len(data) // 4}f", data)


# -- decoding ------------------------------------------------------------------------
def _fields(data: bytes) -> list[tuple[int, int, int | bytes]]:
    """(field, wire type, value) of every field of one message; PayloadError if malformed."""
    out: list[tuple[int, int, int | bytes]] = []
    i, n = 0, len(data)

    def varint() -> int:
        nonlocal i
        shift = result = 0
        while True:
            if i >= n or shift > 63:
                raise PayloadError("truncated or overlong varint")
            b = data[i]
            i += 1
            result |= (b & 0x7F) << shift
            if not b & 0x80:
                return result & 0xFFFFFFFFFFFFFFFF
            shift += 7

    while i < n:
        key = varint()
        field, wire = key >> 3, key & 7
        if field == 0:
            raise PayloadError("field number 0")
        value: int | bytes
        if wire == 0:
            value = varint()
        elif wire in (1, 5):
            size = 8 if wire == 1 else 4
            if i + size > n:
                raise PayloadError("truncated fixed-size field")
            value, i = data[i:i + size], i + size
        elif wire == 2:
            size = varint()
            if i + size > n:
                raise PayloadError("truncated length-delimited field")
            value, i = data[i:i + size], i + size
        else:
            raise PayloadError(f"unsupported wire type {wire}")
        out.append((field, wire, value))
    return out


def _text(v: int | bytes) -> str:
    if not isinstance(v, bytes):
        raise PayloadError("expected a length-delimited field")
    try:
        return v.decode("utf-8")
    except UnicodeDecodeError:
        raise PayloadError("a string that is not UTF-8") from None


def _int(v: int | bytes) -> int:
    if isinstance(v, bytes):
        raise PayloadError("expected a varint field")
    return v


def _scalar(datatype: int | None, wire: int, v: int | bytes, kind: str) -> Value:
    if kind in ("int", "long"):
        n = _int(v)
        bits = _SIGNED_BITS.get(datatype or 0)
        carrier = 32 if kind == "int" else 64
        n &= (1 << carrier) - 1
        if bits is not None and n >= 1 << (carrier - 1):
            n -= 1 << carrier
        return n
    if kind == "float":
        if wire != 5:
            raise PayloadError("expected a 32-bit field")
        return float(struct.unpack("<f", v)[0])  # type: ignore[arg-type]
    if kind == "double":
        if wire != 1:
            raise PayloadError("expected a 64-bit field")
        return float(struct.unpack("<d", v)[0])  # type: ignore[arg-type]
    if kind == "bool":
        return bool(_int(v))
    if kind == "string":
        return _text(v)
    if not isinstance(v, bytes):
        raise PayloadError("expected a length-delimited field")
    return v


_METRIC_KIND = {f: k for k, f in _METRIC_VALUE.items()}
_PROPERTY_KIND = {f: k for k, f in _PROPERTY_VALUE.items()}


def _decode_properties(data: bytes) -> tuple[tuple[str, tuple[int, Value]], ...]:
    keys: list[str] = []
    values: list[tuple[int, Value]] = []
    for field, _wire, v in _fields(data):
        if field == 1:
            keys.append(_text(v))
        elif field == 2:
            if not isinstance(v, bytes):
                raise PayloadError("expected a PropertyValue message")
            typ, value, raw = 0, None, []
            for f2, w2, v2 in _fields(v):
                if f2 == 1:
                    typ = _int(v2)
                elif f2 in _PROPERTY_KIND:
                    raw.append((f2, w2, v2))
            for f2, w2, v2 in raw:  # the type may come after the value
                value = _scalar(typ, w2, v2, _PROPERTY_KIND[f2])
            values.append((typ, value))
    if len(keys) != len(values):
        raise PayloadError("a PropertySet with keys and values of different lengths")
    return tuple(zip(keys, values))


def _decode_metric(data: bytes) -> Metric:
    kw: dict[str, object] = {}
    raw: list[tuple[int, int, int | bytes]] = []
    for field, wire, v in _fields(data):
        if field == 1:
            kw["name"] = _text(v)
        elif field in (2, 3, 4):
            kw[{2: "alias", 3: "timestamp", 4: "datatype"}[field]] = _int(v)
        elif field in (5, 6, 7):
            kw[{5: "is_historical", 6: "is_transient", 7: "is_null"}[field]] = bool(_int(v))
        elif field == 9:
            if not isinstance(v, bytes):
                raise PayloadError("expected a PropertySet message")
            kw["properties"] = _decode_properties(v)
        elif field in _METRIC_KIND:
            raw.append((field, wire, v))
    datatype = kw.get("datatype")
    for field, wire, v in raw:
        kw["value"] = _scalar(datatype if isinstance(datatype, int) else None, wire, v, _METRIC_KIND[field])
    size = ARRAY_ITEM_SIZE.get(datatype) if isinstance(datatype, int) else None
    value = kw.get("value")
    if size is not None and isinstance(value, bytes) and len(value) % size:
        raise PayloadError(f"an array of datatype {datatype} with {len(value)} bytes, not whole {size}-byte items")
    return Metric(**kw)  # type: ignore[arg-type]


def decode(data: bytes) -> Payload:
    """The payload of ``data``; PayloadError (one line) when it is malformed."""
    kw: dict[str, object] = {}
    metrics: list[Metric] = []
    for field, _wire, v in _fields(bytes(data)):
        if field == 1:
            kw["timestamp"] = _int(v)
        elif field == 2:
            if not isinstance(v, bytes):
                raise PayloadError("expected a Metric message")
            metrics.append(_decode_metric(v))
        elif field == 3:
            kw["seq"] = _int(v)
        elif field == 4:
            kw["uuid"] = _text(v)
        elif field == 5:
            if not isinstance(v, bytes):
                raise PayloadError("expected a bytes field")
            kw["body"] = v
    return Payload(metrics=tuple(metrics), **kw)  # type: ignore[arg-type]
