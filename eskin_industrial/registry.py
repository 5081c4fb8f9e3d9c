"""Kinds by name, imported on first use: the one lookup behind the source registry
(``bus/source.py``), the output registry (``outputs/base.py``) and the methods'
plug-ins, as python-can finds an interface by name.

A kind is built in (a ``name -> "module:Class"`` table in the package) or a plug-in:
an entry point of an installed distribution in the kind's group, as python-can's
``can.interface`` group adds interfaces::

    [project.entry-points."eskin_industrial.sinks"]
    state-log = "mypackage.statelog:StateLogKind"

A plug-in never replaces a built-in kind of the same name: the built-in one is used.
Entry points are read once per process.
"""

from __future__ import annotations

import difflib
import functools
import importlib
import importlib.metadata
from collections.abc import Mapping
from typing import Any

from .errors import ProfileError

#: The entry-point groups, by what they add.
SOURCE_GROUP = "eskin_industrial.sources"
SINK_GROUP = "eskin_industrial.sinks"
METHOD_GROUP = "eskin_industrial.methods"


@functools.cache
def plugins(group: str) -> dict[str, str]:
    """``name -> "module:attr"`` of the installed distributions' entry points in
    ``group``, sorted by name (read once per process)."""
    found = {ep.name: ep.value for ep in importlib.metadata.entry_points(group=group)}
    return dict(sorted(found.items()))


def kinds(table: Mapping[str, str], group: str) -> dict[str, str]:
    """The built-in ``table`` and the plug-ins of ``group`` that do not shadow one of
    its names, built-ins first (the order of logs, ``--check`` and the command line)."""
    return {**table, **{k: v for k, v in plugins(group).items() if k not in table}}


def load_attr(target: str) -> Any:
    """The object ``"module:attr"`` names (an import error of a plug-in propagates: a
    broken install is a bug to see, not a kind to skip)."""
    module, _, attr = target.partition(":")
    obj: Any = importlib.import_module(module)
    for part in attr.split("."):
        obj = getattr(obj, part)
    return obj


def load_kind(table: Mapping[str, str], name: str, what: str, base: type, group: str | None = None) -> Any:
    """The class ``table[name]`` names (``"module:Class"``), or the plug-in of that name
    in ``group``, checked to be a ``base``; an unknown name is one line with the
    nearest and the valid names."""
    every = kinds(table, group) if group is not None else dict(table)
    target = every.get(name)
    if target is None:
        near = difflib.get_close_matches(name, list(every), n=1)
        hint = f" (did you mean {near[0]!r}?)" if near else ""
        raise ProfileError(f"unknown {what} {name!r}{hint}; valid kinds: {', '.join(every)}")
    cls = load_attr(target)
    if not (isinstance(cls, type) and issubclass(cls, base)):
        raise TypeError(f"{target}: registered as {what} {name!r}, but not a {base.__name__}")  # a bug, not input
    return cls
