"""Detection methods by name: the built-in ones (``detect/methods.py``) and the
plug-ins of installed distributions, as python-can finds an interface by name.

A plug-in method is an entry point in the ``eskin_industrial.methods`` group that
names a :class:`~eskin_industrial.detect.methods.Method`::

    [project.entry-points."eskin_industrial.methods"]
    peak-shift = "mypackage.peak:METHOD"

Its ``name`` must be the entry point's name, and its ``code`` (the METHOD_ID register
value and the Sparkplug ``Method`` metric, which a PLC program compares) must be
neither 0 (no method) nor another method's: a plug-in that breaks either rule is
refused with one line naming it, never silently given another number.  A plug-in
never replaces a built-in method of the same name.

A plug-in's settings (``Method.settings``, a frozen dataclass) are read from
``[detector.<key>]`` of a profile (``key``: its name with ``-`` as ``_``), checked
like every section: :func:`section_class` tells the profile loader which class a
section is, so that the plug-in is imported only when a profile names it.  The key
must not be one of ``[detector]``'s own.

A method that needs a model (``learned``) is bound here to the one given, or else to
the model the package ships (:mod:`~eskin_industrial.models`, read from package data:
nothing trains at run time).  The pipeline (hence the bridge and every live command),
the offline path (``detect``, ``plot``) and the evaluation all build their methods
through :func:`ready_method`, so that a method name means the same detector everywhere.

This lookup sits above ``detect`` (the numeric core reads no entry points and no
files) and below everything that names a method: profiles, the evaluation, the
outputs, the commands.
"""

from __future__ import annotations

import dataclasses
import difflib
import functools
from collections.abc import Callable
from typing import Any

import numpy as np

from .detect.learned import Model
from .detect.methods import METHODS, Method
from .detect.settings import DetectorSettings
from .errors import ProfileError
from .models import default_model
from .registry import METHOD_GROUP, load_attr, plugins
from .schema import SchemaError, build

#: The keys of ``[detector]`` itself and its built-in sections (no plug-in's section).
_DETECTOR_KEYS = frozenset(f.name for f in dataclasses.fields(DetectorSettings))

#: A stream factory: (settings, x_mm, y_mm, rate_hz) -> a detector.
Factory = Callable[[DetectorSettings, np.ndarray, np.ndarray, float], Any]


def method_names() -> list[str]:
    """Every method's name: the built-in ones in their order, then the plug-ins' (read
    from the entry points without importing them)."""
    return [*METHODS, *(n for n in plugins(METHOD_GROUP) if n not in METHODS)]


#: The built-in baseline that never reports slip (the closed loop's light grip with no
#: sensing): a method, but no detector to score unless asked for.
BASELINE = "none"


def detector_names() -> tuple[str, ...]:
    """Every method that detects slip (all but the ``none`` baseline): what an
    evaluation scores unless told otherwise."""
    return tuple(n for n in method_names() if n != BASELINE)


@functools.cache
def _plugin(name: str) -> Method:
    target = plugins(METHOD_GROUP)[name]
    method = load_attr(target)
    where = f"method plug-in {name!r} ({target})"
    if not isinstance(method, Method):
        raise ProfileError(f"{where}: expected an eskin_industrial.detect.methods.Method, got {type(method).__name__}")
    if method.name != name:
        raise ProfileError(f"{where}: its Method is named {method.name!r}; the entry point and the name must agree")
    taken = {m.code: m.name for m in METHODS.values()}
    if method.code <= 0 or method.code > 0xFFFF:
        raise ProfileError(f"{where}: code {method.code} is not a METHOD_ID (1..65535; 0 means no method)")
    if method.code in taken:
        raise ProfileError(f"{where}: code {method.code} is already {taken[method.code]!r}'s METHOD_ID; "
                           f"give the plug-in a number of its own (the built-in ones use 1..{max(taken)})")
    if method.settings is not None:
        _check_settings(method, where)
    return method


def _check_settings(method: Method, where: str) -> None:
    cls = method.settings
    if not (isinstance(cls, type) and dataclasses.is_dataclass(cls) and cls.__dataclass_params__.frozen):  # type: ignore[attr-defined]
        raise ProfileError(f"{where}: its settings must be a frozen dataclass, got {cls!r}")
    if not method.key.isidentifier() or method.key in _DETECTOR_KEYS:
        raise ProfileError(f"{where}: its settings cannot be [detector.{method.key}] (a key of [detector] itself, "
                           f"or no TOML key); give the Method a section of its own")
    try:
        build(cls, {}, f"detector.{method.key}")
    except SchemaError as exc:
        raise ProfileError(f"{where}: its settings need a default for every key ({exc})") from None


def _plugins_checked() -> dict[str, Method]:
    """Every plug-in method, loaded, with no two sharing a code."""
    found = {n: _plugin(n) for n in plugins(METHOD_GROUP) if n not in METHODS}
    seen: dict[int, str] = {}
    for name, method in found.items():
        if method.code in seen:
            raise ProfileError(f"method plug-ins {seen[method.code]!r} and {name!r} both take METHOD_ID "
                               f"{method.code}; one must change its code")
        seen[method.code] = name
    return found


def get_method(name: str) -> Method:
    """The method ``name``, built in or a plug-in; an unknown name is a ``KeyError``
    naming the nearest and the known ones."""
    if name in METHODS:
        return METHODS[name]
    if name in plugins(METHOD_GROUP):
        return _plugins_checked()[name]
    known = method_names()
    near = difflib.get_close_matches(name, known, n=1)
    hint = f" (did you mean {near[0]!r}?)" if near else ""
    raise KeyError(f"unknown detection method {name!r}{hint}; known: {', '.join(sorted(known))}")


def all_methods() -> dict[str, Method]:
    """Every method by name, the plug-ins loaded and checked."""
    return {**METHODS, **_plugins_checked()}


def section_class(owner: type, key: str) -> type | None:
    """The settings dataclass of the method whose section is ``[detector.<key>]`` when
    ``[detector]`` has no key of that name (a plug-in's; None: no method's), for the
    profile loader (``schema.build``'s ``sections``)."""
    if owner is not DetectorSettings or key in _DETECTOR_KEYS:
        return None
    for method in METHODS.values():
        if method.settings is not None and method.key == key:
            return method.settings
    named = [n for n in plugins(METHOD_GROUP) if n not in METHODS and n.replace("-", "_") == key]
    # the plug-in of that name first (imported alone), then any that names its section itself
    for method in [get_method(n) for n in named] or list(_plugins_checked().values()):
        if method.settings is not None and method.key == key:
            return method.settings
    return None


def method_of_code(code: int) -> Method | None:
    """The method with this METHOD_ID register value (None: 0 or unknown)."""
    return next((m for m in all_methods().values() if m.code == code), None)


def method_of_stream(factory: Callable[..., Any]) -> Method | None:
    """The registered method whose stream factory ``factory`` is (None: no registered
    method's, such as a bound one or a sweep's own)."""
    return next((m for m in all_methods().values() if factory is m.stream), None)


def bind(method: Method, model: Model | None = None) -> Method:
    """``method`` ready to build from (settings, x_mm, y_mm, rate_hz): one that needs
    a model is handed ``model``, or else the shipped one (read once per process; a
    missing or unreadable file is a one-line :class:`~eskin_industrial.models.ModelFileError`);
    any other is returned as it is."""
    if not method.needs_model:
        return method
    return method.with_model(default_model() if model is None else model)


def ready_method(name: str | None, settings: DetectorSettings, model: Model | None = None) -> Method:
    """The method ``name`` (None: the settings' own, a profile's ``detector.method``),
    bound by :func:`bind`; an unknown name is a ``KeyError`` naming the known ones."""
    return bind(get_method(name or settings.method), model)


def ready_factory(factory: Factory) -> Factory:
    """A bare stream factory ready to call: a registered method's factory that needs a
    model (``get_method("learned").stream``) is bound by :func:`bind`; any other
    factory (a bound one, one of the sweeps' own) is returned as it is."""
    method = method_of_stream(factory)
    return factory if method is None or not method.needs_model else bind(method).stream


__all__ = ["Factory", "all_methods", "bind", "detector_names", "get_method", "method_of_code", "method_of_stream",
           "method_names", "ready_factory", "ready_method", "section_class"]
