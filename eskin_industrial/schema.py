"""Turn parsed TOML tables into frozen, typed dataclasses, refusing anything else.

The profile sections are plain frozen dataclasses; their type hints *are* the schema.
Constraints that a type cannot say (a positive number, a range) sit in the field's
metadata under ``"check"`` as ``(predicate, "what was expected")``.  Cross-field rules
live in each class's ``__post_init__`` and raise :class:`ValueError`, which the loader
turns into a one-line :class:`~eskin_industrial.errors.ProfileError` naming the file
and key.

No value is ever read as a string and guessed into a type: TOML already carries
types, and a wrong one is an error, not a conversion.

A section may be open to tables that its class cannot name: a field marked
:func:`open_sections` collects the sub-tables that ``sections`` (given to
:func:`build` by the loader) names a class for, each built and checked like any other
(a plug-in method's ``[detector.<key>]``); ``to_table`` writes them back in place.
"""

from __future__ import annotations

import dataclasses
import difflib
import ipaddress
import math
import tomllib
import types
import typing
import warnings
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, Literal, TypeVar, Union, get_args, get_origin

from .errors import DeprecatedKey, ProfileError

T = TypeVar("T")

Check = tuple[Callable[[Any], bool], str]
#: ``(owner class, key) -> the dataclass a sub-table of that key is`` (None: no such
#: section): how an open section's tables are known (:func:`open_sections`).
Sections = Callable[[type, str], "type | None"]


class SchemaError(ValueError):
    """A value does not fit the schema; ``key`` is the dotted path to it."""

    def __init__(self, key: str, message: str) -> None:
        super().__init__(f"{key}: {message}" if key else message)
        self.key = key
        self.message = message


def positive(what: str = "a number > 0") -> dict[str, Check]:
    return {"check": (lambda v: v > 0, what)}


def non_negative(what: str = "a number >= 0") -> dict[str, Check]:
    return {"check": (lambda v: v >= 0, what)}


def in_range(lo: float, hi: float) -> dict[str, Any]:
    """The check, and the bounds as numbers (``"range"``: a teach-in keeps a threshold it
    sets within them)."""
    return {"check": (lambda v: lo <= v <= hi, f"a value in [{lo:g}, {hi:g}]"), "range": (lo, hi)}


def positive_at_most(hi: float, what: str = "a number") -> dict[str, Check]:
    """A number in (0, hi]: the bounds a setting can sanely take (``docs/profiles.md``
    lists each), so that an absurd value is refused before the run, not met in it."""
    shown = f"{int(hi)}" if float(hi).is_integer() else f"{hi:g}"
    return {"check": (lambda v: 0 < v <= hi, f"{what} > 0 and at most {shown}")}


def open_sections() -> dict[str, bool]:
    """The metadata of the one field of a section that holds its open sub-tables, as
    ``(key, built dataclass)`` pairs sorted by key: no TOML key of its own."""
    return {"sections": True}


def _is_network(v: Any) -> bool:
    try:
        ipaddress.ip_network(v, strict=False)
    except ValueError:
        return False
    return True


def ip_network() -> dict[str, Check]:
    """An IP address or network, each entry of a list (an allow-list)."""
    return {"check": (_is_network, "an IP address or network (10.0.0.5, 10.0.0.0/24)")}


def _describe(tp: Any) -> str:
    origin = get_origin(tp)
    if tp is float:
        return "a number"
    if tp is int:
        return "an integer"
    if tp is bool:
        return "true or false"
    if tp is str:
        return "a string"
    if origin is Literal:
        return "one of " + ", ".join(repr(a) for a in get_args(tp))
    if origin is tuple:
        return f"a list of {_describe(get_args(tp)[0]).removeprefix('a ').removeprefix('an ')}s"
    if origin in (Union, types.UnionType):
        return " or ".join(_describe(a) for a in get_args(tp) if a is not type(None))
    if origin is dict:
        return "a table"
    if dataclasses.is_dataclass(tp):
        return "a table"
    return str(tp)


def _convert(tp: Any, value: Any, key: str, sections: Sections | None = None) -> Any:
    origin = get_origin(tp)
    if origin in (Union, types.UnionType):
        args = get_args(tp)
        if value is None and type(None) in args:
            return None
        errors = []
        for arg in args:
            if arg is type(None):
                continue
            try:
                return _convert(arg, value, key, sections)
            except SchemaError as exc:
                errors.append(exc)
        # Prefer the error of a branch that got past the type check (a table with a
        # bad key inside) over a generic "expected X or Y".
        deep = [e for e in errors if e.key != key]
        if deep:
            raise deep[0]
        raise SchemaError(key, f"expected {_describe(tp)}, got {_show(value)}")
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise SchemaError(key, f"expected a number, got {_show(value)}")
        # TOML has nan and inf; no setting means them (NaN would pass every range check
        # and reach the detector, inf overflows where times become sample counts).
        try:
            number = float(value)  # an integer beyond the float range overflows here
        except OverflowError:
            number = math.inf
        if not math.isfinite(number):
            raise SchemaError(key, f"expected a finite number, got {_show(value)}")
        return number
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise SchemaError(key, f"expected an integer, got {_show(value)}")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise SchemaError(key, f"expected true or false, got {_show(value)}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise SchemaError(key, f"expected a string, got {_show(value)}")
        return value
    if origin is Literal:
        choices = get_args(tp)
        if value not in choices:
            near = difflib.get_close_matches(str(value), [str(c) for c in choices], n=1)
            hint = f" (did you mean {near[0]!r}?)" if near else ""
            raise SchemaError(
                key, f"expected one of {', '.join(repr(c) for c in choices)}, got {_show(value)}{hint}"
            )
        return value
    if origin is tuple:
        if not isinstance(value, list):
            raise SchemaError(key, f"expected {_describe(tp)}, got {_show(value)}")
        (item_tp, *_rest) = get_args(tp)
        return tuple(_convert(item_tp, v, f"{key}[{i}]", sections) for i, v in enumerate(value))
    if origin is dict:
        if not isinstance(value, dict):
            raise SchemaError(key, f"expected a table, got {_show(value)}")
        _k_tp, v_tp = get_args(tp)
        return {k: _convert(v_tp, v, f"{key}.{k}", sections) for k, v in value.items()}
    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            raise SchemaError(key, f"expected a table, got {_show(value)}")
        return build(tp, value, key, sections)
    raise TypeError(f"schema type {tp!r} at {key} is not supported")  # a bug, not input


def _show(value: Any) -> str:
    if isinstance(value, dict):
        return "a table"
    if isinstance(value, list):
        return "a list"
    if isinstance(value, bool):
        return "true" if value else "false"
    return repr(value)


def build(cls: type, table: dict[str, Any], where: str = "", sections: Sections | None = None) -> Any:
    """Build dataclass ``cls`` from ``table``; every key is checked, none guessed.

    ``where`` is the dotted path of ``table`` in the file, used in messages;
    ``sections`` names the classes of open sections' tables (:func:`open_sections`).
    """
    hints = typing.get_type_hints(cls)
    every = [f for f in dataclasses.fields(cls) if f.init]
    fields = {f.name: f for f in every if not f.metadata.get("sections")}
    held = next((f.name for f in every if f.metadata.get("sections")), None)
    prefix = f"{where}." if where else ""
    opened: dict[str, Any] = {}
    for name in table:
        if name not in fields:
            found = sections(cls, name) if held is not None and sections is not None else None
            if found is not None:
                if not isinstance(table[name], dict):
                    raise SchemaError(f"{prefix}{name}", f"expected a table, got {_show(table[name])}")
                opened[name] = build(found, table[name], f"{prefix}{name}", sections)
                continue
            near = difflib.get_close_matches(name, list(fields), n=1, cutoff=0.6)
            hint = f"; did you mean {near[0]!r}?" if near else f"; valid keys: {', '.join(fields)}"
            raise SchemaError(f"{prefix}{name}", f"unknown key{hint}")
    kwargs: dict[str, Any] = {}
    for name, f in fields.items():
        key = f"{prefix}{name}"
        if name not in table:
            if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
                what = "section" if dataclasses.is_dataclass(hints[name]) else "key"
                raise SchemaError(key, f"missing {what} (expected {_describe(hints[name])})")
            continue
        value = _convert(hints[name], table[name], key, sections)
        check = f.metadata.get("check")
        if check is not None and value is not None:
            predicate, expected = check
            items = value if isinstance(value, tuple) else (value,)
            for item in items:
                if not predicate(item):
                    raise SchemaError(key, f"expected {expected}, got {_show(item)}")
        kwargs[name] = value
    if opened:
        assert held is not None
        kwargs[held] = tuple(sorted(opened.items()))
    try:
        return cls(**kwargs)
    except SchemaError:
        raise
    # A __post_init__ rule may also fail on arithmetic with huge values (OverflowError)
    # or inside a library it consults (PyWavelets raises TypeError for an empty wavelet
    # name): still one line naming the section, not a traceback.
    except (ValueError, OverflowError, TypeError) as exc:
        # __post_init__ messages start with the offending field's name.
        msg = str(exc)
        field, _, rest = msg.partition(": ")
        if field in fields and rest:
            raise SchemaError(f"{prefix}{field}", rest) from None
        raise SchemaError(where, msg) from None


def to_table(obj: Any) -> Any:
    """The inverse of :func:`build`, for ``profile show``: dataclasses to plain dicts."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        out: dict[str, Any] = {}
        for f in dataclasses.fields(obj):
            if not f.init:
                continue
            if f.metadata.get("sections"):  # written back where they were read
                out.update((key, to_table(section)) for key, section in getattr(obj, f.name))
                continue
            value = to_table(getattr(obj, f.name))
            if value is not None:
                out[f.name] = value
        return out
    if isinstance(obj, tuple):
        return [to_table(v) for v in obj]
    if isinstance(obj, dict):
        return {k: to_table(v) for k, v in obj.items()}
    return obj


def read_toml_file(path: Path, what: str) -> str:
    """The text of a TOML file; one :class:`ProfileError` line when it cannot be read
    (``what``: "profile", "scene", ... for the message)."""
    try:
        return path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ProfileError(f"{path}: cannot read {what}: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:  # TOML is UTF-8; say where it is not
        raise ProfileError(f"{path}: cannot read {what}: not UTF-8 text (byte {exc.start}: "
                           f"{exc.object[exc.start:exc.start + 1]!r})") from None


def _spell(dotted: str) -> str:
    """``modbus.plc.stale_s`` as a reader finds it in a file: ``[modbus.plc] stale_s``."""
    section, _, key = dotted.rpartition(".")
    return f"[{section}] {key}" if section else key


def move_keys(table: dict[str, Any], moved: Mapping[str, str], source: str) -> None:
    """Move each deprecated key of ``moved`` (old dotted path -> new dotted path) to its
    new place in ``table``, with one :class:`~eskin_industrial.errors.DeprecatedKey`
    warning naming both; a key given under both spellings is a :class:`ProfileError`
    (which of the two was meant cannot be known)."""
    for old, new in moved.items():
        *path, key = old.split(".")
        here: Any = table
        for part in path:
            here = here.get(part) if isinstance(here, dict) else None
        if not isinstance(here, dict) or key not in here:
            continue
        value = here.pop(key)
        *npath, nkey = new.split(".")
        there: Any = table
        for part in npath:
            if not isinstance(there, dict):
                break
            there = there.setdefault(part, {})
        if not isinstance(there, dict):
            continue  # the new section is not a table: the schema says so below
        if nkey in there:
            raise ProfileError(f"{source}: {_spell(old)}: deprecated, and {_spell(new)} is given too; "
                               f"keep {_spell(new)} only")
        there[nkey] = value
        warnings.warn(DeprecatedKey(f"{source}: {_spell(old)} is deprecated: write {_spell(new)}"), stacklevel=2)


def parse_toml(cls: type[T], text: str, source: str, moved: Mapping[str, str] | None = None,
               sections: Sections | None = None) -> T:
    """TOML text to ``cls``; any problem is one :class:`ProfileError` line:
    ``SOURCE: [section] key: what was expected``.  ``moved``: keys that moved
    (:func:`move_keys`), still read under their old spelling; ``sections``: the
    classes of open sections' tables (:func:`build`)."""
    try:
        table = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ProfileError(f"{source}: not valid TOML: {exc}") from None
    if moved:
        move_keys(table, moved, source)
    try:
        return build(cls, table, sections=sections)
    except SchemaError as exc:
        section, _, key = exc.key.partition(".")
        where = f"[{section}] {key}" if key else f"[{section}]"
        raise ProfileError(f"{source}: {where}: {exc.message}") from None
