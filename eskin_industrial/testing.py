"""Conformance checks for a detection method, a source kind and an output kind: what
the seams promise, checked on the real thing, as river's and scikit-learn's
``check_estimator`` check an estimator.  A plug-in's own tests call them::

    from eskin_industrial.testing import check_method, check_sink, check_source

    def test_peak_shift_keeps_the_promises():
        check_method("peak-shift")

    def test_state_log_keeps_the_promises(tmp_path):
        check_sink("state-log", {"path": str(tmp_path / "states.log")})

Each check builds the kind the way the bridge does (its settings or options from a
table, checked by their declared dataclass), runs it, and raises ``AssertionError``
with one line naming the kind and the broken promise.  The package's own tests run
them over every built-in method, source kind and output kind
(``tests/test_conformance.py``).

- :func:`check_method`: its settings are a frozen dataclass with a default for every
  key and round-trip through a profile; on a shipped scene, the stream frame by frame
  gives the batch answer, its scores are finite, its states are ``GraspState`` codes,
  and nothing but ``no_contact`` is claimed before the scene's first contact.
- :func:`check_source`: the kind declares ``kind``, ``spec`` and ``Options``; it opens,
  yields scans of the profile's taxels, reports health and counters of its own names,
  and closes twice safely.
- :func:`check_sink`: the kind declares ``name``, ``Options`` and ``cli_options``; it
  opens one sink per node, told the kind's name, takes the snapshots and updates of a node's loop (a scene played through it)
  and its last, offline snapshot, reports health and counters of its own names,
  flushes, and closes twice safely.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from .bridge.loop import NodeLoop
from .bus.source import Source, SourceHealth, source_class
from .detect.learned import Model
from .detect.methods import Method
from .detect.settings import DetectorSettings
from .detect.state import GraspState
from .detect.updates import COLUMNS, UpdateTable
from .errors import EskinError
from .methods import bind, get_method
from .outputs.base import CliOption, Sink, SinkHealth, output_kind
from .profile import Profile, load_profile, parse_profile
from .scenes import render
from .schema import SchemaError, build, to_table
from .seam import OpenContext

__all__ = ["check_method", "check_sink", "check_source", "loop_counters"]


class _Broken(AssertionError):
    """One broken promise: ``what: why``, on one line."""

    def __init__(self, what: str, why: str) -> None:
        super().__init__(f"{what}: {' '.join(why.split())}")


def _that(ok: object, what: str, why: str) -> None:
    if not ok:
        raise _Broken(what, why)


# -- methods ---------------------------------------------------------------------------

def check_method(method: str | Method, *, scene: str = "case2", profile: str = "paper-5x5",
                 rate_hz: float = 100.0, seed: int = 0, model: Model | None = None) -> None:
    """Check a registered detection method (by name, or its :class:`Method`) against
    what every method promises, on the shipped ``scene`` seen through ``profile``
    (``model``: for a method that needs one, instead of the model the package ships)."""
    m = _registered(method)
    what = f"method {m.name!r}"
    base = load_profile(profile)
    settings = _check_settings(m, base, what)
    rec = render(scene, rate_hz, seed)
    _that(rec.forces.shape[1] == base.taxels, what, f"scene {scene} has {rec.forces.shape[1]} taxels, profile "
          f"{base.name} {base.taxels}; give a scene and profile that match")
    x, y = base.coordinates_mm
    ready = bind(m, model)
    det = ready.stream(settings, x, y, rate_hz)
    for name in ("push", "feed", "dropped", "time_faults"):
        _that(hasattr(det, name), what, f"its detector has no {name!r} (detect/protocol.py: Detector)")
    streamed: list[Any] = []
    for t, f in zip(rec.t, rec.forces):  # frame by frame, as a node's loop feeds it
        streamed.extend(det.push(float(t), f, 0))
    batch = ready.batch(settings, x, y, rate_hz, rec.t, rec.forces)
    _that(len(streamed) > 0, what, f"no update from {rec.t[-1] - rec.t[0]:.1f} s of scene {scene}")
    _same(UpdateTable.from_updates(streamed), batch, what, scene)
    _check_updates(batch, rec.t[np.nonzero(rec.labels != "no_contact")[0][0]], what, scene)


def _registered(method: str | Method) -> Method:
    name = method if isinstance(method, str) else method.name
    try:
        found = get_method(name)
    except (KeyError, EskinError) as exc:
        raise _Broken(f"method {name!r}", str(exc).strip("'\"")) from None
    _that(isinstance(method, str) or found is method, f"method {name!r}",
          "another Method of this name is registered; check the one the registry finds (its entry point)")
    return found


def _check_settings(m: Method, base: Profile, what: str) -> DetectorSettings:
    """The method's declared settings: a frozen dataclass with every key defaulted, read
    back from a profile that writes them out.  Returns the detector settings to run."""
    settings = dataclasses.replace(base.detector, method=m.name)
    cls = m.settings
    if cls is None:
        return settings
    _that(isinstance(cls, type) and dataclasses.is_dataclass(cls) and cls.__dataclass_params__.frozen,  # type: ignore[attr-defined]
          what, f"its settings must be a frozen dataclass, got {cls!r}")
    try:
        defaults = build(cls, {}, f"detector.{m.key}" if m.key else "detector")
    except SchemaError as exc:
        raise _Broken(what, f"its settings need a default for every key: {exc}") from None
    own = m.settings_of(settings)
    _that(isinstance(own, cls), what, f"settings_of gave {type(own).__name__}, not its {cls.__name__}")
    if m.key:
        _that(m.key.isidentifier(), what, f"[detector.{m.key}] is no TOML key of one word")
    # written out in full, as `profile show` does, and read back by the profile loader
    table = base.to_table()
    table["detector"]["method"] = m.name
    section = table["detector"].setdefault(m.key, {}) if m.key else table["detector"]
    section.update(to_table(defaults))
    text = _toml(table)
    try:
        loaded = parse_profile(text, f"<{m.name} settings>")
    except EskinError as exc:
        raise _Broken(what, f"a profile with its settings written out is refused: {exc}") from None
    _that(m.settings_of(loaded.detector) == defaults, what,
          f"its settings do not round-trip through a profile: wrote {defaults}, read {m.settings_of(loaded.detector)}")
    again = parse_profile(_toml(loaded.to_table()), f"<{m.name} shown>")
    _that(again.detector == loaded.detector, what, "the profile as shown (profile show) reads back otherwise")
    return loaded.detector


def _same(streamed: UpdateTable, batch: UpdateTable, what: str, scene: str) -> None:
    _that(len(streamed) == len(batch), what, f"scene {scene}: {len(streamed)} updates frame by frame, "
          f"{len(batch)} in a batch")
    for col in COLUMNS:
        a, b = getattr(streamed, col), getattr(batch, col)
        if col in ("state", "flags", "valid"):
            bad = np.nonzero(np.asarray(a) != np.asarray(b))[0]
        else:
            close = np.isclose(a, b, rtol=1e-9, atol=1e-9, equal_nan=True)
            bad = np.nonzero(~close)[0]
        _that(bad.size == 0, what, f"scene {scene}: the stream is not the batch answer: {col} of update "
              f"{bad[0] if bad.size else 0} (t = {batch.t[bad[0]] if bad.size else 0:.3f} s) is "
              f"{a[bad[0]] if bad.size else 0} frame by frame, {b[bad[0]] if bad.size else 0} in a batch")


def _check_updates(table: UpdateTable, contact_t: float, what: str, scene: str) -> None:
    for col in ("score_a", "score_b", "r_coe", "r_dw"):
        values = np.asarray(getattr(table, col), float)
        bad = np.nonzero(~np.isfinite(values))[0]
        _that(bad.size == 0, what, f"scene {scene}: {col} is not finite at t = "
              f"{table.t[bad[0]] if bad.size else 0:.3f} s ({values[bad[0]] if bad.size else 0})")
    codes = {int(s) for s in GraspState}
    states = np.asarray(table.state)
    wrong = sorted(set(states.tolist()) - codes)
    _that(not wrong, what, f"scene {scene}: state {wrong[0] if wrong else 0} is no GraspState code "
          f"({', '.join(f'{int(s)} {s.label}' for s in GraspState)})")
    early = np.nonzero((np.asarray(table.t) < contact_t) & (states != int(GraspState.NO_CONTACT)))[0]
    _that(early.size == 0, what, f"scene {scene}: state {states[early[0]] if early.size else 0} at t = "
          f"{table.t[early[0]] if early.size else 0:.3f} s, before the first contact ({contact_t:.3f} s)")


def _toml(table: Mapping[str, Any], prefix: str = "") -> str:
    """A profile table as TOML: the plain values, then each sub-table under its header."""
    lines = [f"{k} = {_toml_value(v)}" for k, v in table.items() if not isinstance(v, dict)]
    text = "\n".join(lines) + ("\n" if lines else "")
    for k, v in table.items():
        if isinstance(v, dict):
            name = f"{prefix}{k}"
            text += f"\n[{name}]\n" + _toml(v, f"{name}.")
    return text


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else ("inf" if v > 0 else "-inf")
    if isinstance(v, (int, str)):
        return repr(v) if isinstance(v, int) else '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"no TOML value for {v!r}")  # a bug, not input


# -- sources and sinks -------------------------------------------------------------------

@dataclass(frozen=True)
class _Node:
    """A resolved node, as the bridge hands one to a kind (``seam.NodeLike``)."""

    name: str
    profile: Profile
    rate_hz: float
    options: Any


def _options(cls: type, kind: str, table: Mapping[str, Any] | None, what: str) -> Any:
    options_cls = cls.Options  # type: ignore[attr-defined]
    _that(isinstance(options_cls, type) and dataclasses.is_dataclass(options_cls)
          and options_cls.__dataclass_params__.frozen, what,  # type: ignore[attr-defined]
          f"its Options must be a frozen dataclass, got {options_cls!r}")
    try:
        return build(options_cls, dict(table or {}), kind)
    except SchemaError as exc:
        raise _Broken(what, f"its Options refuse the table given: {exc}") from None


@functools.cache
def loop_counters() -> frozenset[str]:
    """The node loop's own counters (``NodeLoop.counters``, read off a loop): a kind's
    counters are merged into the same table, so none of its names may be one of these."""
    prof = load_profile("paper-5x5")
    scene = source_class("scene")
    node = _Node("conformance", prof, prof.sensor.rate_hz, build(scene.Options, {"scene": "idle"}, "scene"))
    context = OpenContext()
    (src,) = scene.open_nodes([node], context)
    try:
        return frozenset(NodeLoop(prof, src, []).counters()) - set(src.counters())
    finally:
        for close in context.closers:
            close()


def _check_counters(counters: object, what: str) -> set[str]:
    _that(isinstance(counters, dict), what, f"counters() must be a dict, got {type(counters).__name__}")
    assert isinstance(counters, dict)
    for name, value in counters.items():
        _that(isinstance(name, str) and name.isidentifier(), what, f"counter {name!r} is no name")
        _that(isinstance(value, int) and not isinstance(value, bool) and value >= 0, what,
              f"counter {name!r} is {value!r}, not a count")
    shared = sorted(set(counters) & loop_counters())
    _that(not shared, what, f"counter {shared[0] if shared else ''!r} is the node loop's own; name it for the kind")
    return set(counters)


def _closes_twice(closers: list[Any], what: str) -> None:
    for round_ in ("first", "second"):
        for close in closers:
            try:
                close()
            except Exception as exc:  # noqa: BLE001 - the promise is that it does not raise
                raise _Broken(what, f"the {round_} close raised {type(exc).__name__}: {exc}") from None


def check_source(kind: str, options: Mapping[str, Any] | None = None, *, profile: str = "paper-5x5",
                 scans: int = 5, timeout_s: float = 10.0) -> set[str]:
    """Check the source kind ``kind`` opened with ``options`` (its ``[[node]]`` keys;
    what it reads from, such as a virtual CAN channel with a node sending on it, is
    the caller's to provide) against the seam; returns its counters' names."""
    what = f"source kind {kind!r}"
    try:
        cls = source_class(kind)
    except EskinError as exc:
        raise _Broken(what, str(exc)) from None
    _that(cls.kind == kind, what, f"its class says kind {cls.kind!r}")
    _that(isinstance(cls.spec, str) and cls.spec, what, "it declares no --source spec")
    opts = _options(cls, kind, options, what)
    prof = load_profile(profile)
    try:
        node = _Node("conformance", cls.adapt_profile(prof, opts), prof.sensor.rate_hz, opts)
        cls.check(node, os.getcwd())
    except ValueError as exc:
        raise _Broken(what, f"check refused the node: {exc}") from None
    _that(isinstance(cls.describe(node), str) and cls.describe(node), what, "describe gave no line")
    context = OpenContext()
    try:
        opened = _open(lambda: cls.open_nodes([node], context), what)
        _that(len(opened) == 1 and isinstance(opened[0], Source), what,
              f"open_nodes gave {len(opened)} objects for one node, not one Source")
        src = opened[0]
        src.start()
        got: list[Any] = []
        end = time.monotonic() + timeout_s
        while len(got) < scans and time.monotonic() < end and not (src.done and not src.pending):
            scan = src.poll(0.05)
            if scan is not None:
                got.append(scan)
        _that(len(got) >= scans, what, f"{len(got)} scans in {timeout_s:g} s, expected {scans} "
              f"(last error: {src.last_error or 'none'})")
        for scan in got:
            raw = np.asarray(scan.raw)
            _that(raw.shape == (node.profile.taxels,), what, f"a scan of shape {raw.shape}, expected "
                  f"({node.profile.taxels},): the profile's taxels")
        ts = [s.t for s in got]
        _that(all(b >= a for a, b in zip(ts, ts[1:])), what, f"scan times run backwards: {ts}")
        health = src.health()
        _that(isinstance(health, SourceHealth), what, f"health() gave {type(health).__name__}")
        _that(health.frame_age_s is not None and health.frame_age_s >= 0, what,
              f"health() says no scan came (frame_age_s {health.frame_age_s}) after {len(got)}")
        names = _check_counters(src.counters(), what)
    except BaseException:
        _close_quietly(context.closers)
        raise
    _closes_twice(list(dict.fromkeys([src.close, *context.closers])), what)
    return names


def _open(opening: Callable[[], list[Any]], what: str) -> list[Any]:
    """What ``opening`` opens; an expected failure to open (a file, a port, a device the
    options name) is the check's one line."""
    try:
        return opening()
    except (EskinError, OSError, ValueError) as exc:
        raise _Broken(what, f"open_nodes failed: {exc}") from None


def _close_quietly(closers: list[Any]) -> None:
    """Close what was opened when a check failed: its own message is the one to see."""
    for close in closers:
        try:
            close()
        except Exception:  # noqa: BLE001 - the failed check's message is the one that matters
            pass


def check_sink(kind: str, options: Mapping[str, Any] | None = None, *, profile: str = "paper-5x5",
               scene: str = "case2", scans: int = 60) -> set[str]:
    """Check the output kind ``kind`` opened with ``options`` (its ``[KIND]`` section;
    None: its default options; what it talks to, such as an MQTT broker, is the
    caller's to provide) against the seam, fed by one node's loop playing ``scene``;
    returns its counters' names."""
    what = f"output kind {kind!r}"
    try:
        cls = output_kind(kind)
    except EskinError as exc:
        raise _Broken(what, str(exc)) from None
    _that(cls.name == kind, what, f"its class says name {cls.name!r}")
    _that(isinstance(cls.cli_options, tuple) and all(isinstance(o, CliOption) for o in cls.cli_options), what,
          "cli_options must be a tuple of CliOption")
    node_cls = cls.NodeOptions
    _that(node_cls is None or (dataclasses.is_dataclass(node_cls) and node_cls.__dataclass_params__.frozen),  # type: ignore[attr-defined]
          what, f"NodeOptions must be None or a frozen dataclass, got {node_cls!r}")
    opts = cls.default_options() if options is None else _options(cls, kind, options, what)
    prof = load_profile(profile)
    scene_cls = source_class("scene")
    node = _Node("conformance", prof, prof.sensor.rate_hz, build(scene_cls.Options, {"scene": scene}, "scene"))
    try:
        cls.check(opts, [node])
        cls.probe(opts, [node])
    except ValueError as exc:
        raise _Broken(what, f"check refused the node: {exc}") from None
    _that(isinstance(cls.describe(opts, node), str) and cls.describe(opts, node), what, "describe gave no line")
    context = OpenContext()
    try:
        (src,) = scene_cls.open_nodes([node], context)
        opened = _open(lambda: cls.open_nodes(opts, [node], context), what)
        _that(len(opened) == 1 and isinstance(opened[0], Sink), what,
              f"open_nodes gave {len(opened)} objects for one node, not one Sink")
        sink = opened[0]
        _that(sink.kind == kind, what, f"its sink says kind {sink.kind!r}: open_nodes tells each sink the kind's name")
        updates: list[Any] = []
        loop = NodeLoop(node.profile, src.start(), [sink], rate_hz=node.rate_hz, on_update=updates.append)
        loop.run(max_scans=scans, duration_s=max(10.0, 3 * scans / node.rate_hz))
        _that(loop.publications > 0 and updates, what, f"the loop published nothing in {scans} scans")
        loop.shutdown()  # the last snapshot, offline
        health = sink.health()
        _that(isinstance(health, SinkHealth), what, f"health() gave {type(health).__name__}")
        _that(health.failures == 0, what, f"health() counts {health.failures} failures: {health.last_error}")
        names = _check_counters(sink.counters(), what)
        _that(isinstance(sink.flush(2.0), bool), what, "flush() must say whether anything is left")
    except BaseException:
        _close_quietly(context.closers)
        raise
    _closes_twice(list(dict.fromkeys([sink.close, *context.closers])), what)
    return names
