"""Kinds by name, imported on first use: the one lookup behind the source registry
(``bus/source.py``) and the output registry (``sinks/base.py``), as python-can finds
an interface by name."""

from __future__ import annotations

import difflib
import importlib
from collections.abc import Mapping
from typing import Any

from .errors import ProfileError

def load_kind(table: Mapping[str, str], name: str, what: str, base: type) -> Any:
    """The class ``table[name]`` names (``"module:Class"``), checked to be a ``base``;
    an unknown name is one line with the nearest and the valid names."""
    target = table.get(name)
    if target is None:
        near = difflib.get_close_matches(name, list(table), n=1)
        hint = f" (did you mean {near[0]!r}?)" if near else ""
        raise ProfileError(f"unknown {what} {name!r}{hint}; valid kinds: {', '.join(table)}")
    module, _, attr = target.partition(":")
    cls = getattr(importlib.import_module(module), attr)
    if not (isinstance(cls, type) and issubclass(cls, base)):
        raise TypeError(f"{target}: registered as {what} {name!r}, but not a {base.__name__}")  # a bug, not input
    return cls
