"""A small TOML writer for plain tables (the standard library reads TOML but does not
write it); enough for ``profile show``."""

from __future__ import annotations

import json
from typing import Any


def _value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)  # TOML basic strings share JSON's escapes
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(f"cannot write {type(v).__name__} as TOML")


def _key(k: str) -> str:
    return k if k.replace("_", "").replace("-", "").isalnum() and not k.isdigit() else json.dumps(k)


def dumps(table: dict[str, Any], prefix: str = "", given: dict[str, Any] | None = None) -> str:
    """TOML text of ``table``.  With ``given`` (the table as the file wrote it), a key
    the file left out is marked ``# default``: where each value came from."""
    lines: list[str] = []
    scalars = {k: v for k, v in table.items() if not isinstance(v, dict) or not v}
    subtables = {k: v for k, v in table.items() if k not in scalars}
    if prefix and (scalars or not subtables):
        lines.append(f"\n[{prefix}]")
    for k, v in scalars.items():
        note = "  # default" if given is not None and k not in given else ""
        lines.append(f"{_key(k)} = {_value(v)}{note}")
    out = "\n".join(lines) + ("\n" if lines else "")
    for k, v in subtables.items():
        sub = None if given is None else (given.get(k) if isinstance(given.get(k), dict) else {})
        out += dumps(v, f"{prefix}.{_key(k)}" if prefix else _key(k), sub)
    return out

