"""The bridge's configuration: which nodes, from which source, into which outputs.

One TOML file (``eskin-bus bridge --config FILE``), or the same built from the
command line for a single node.  Like profiles, it is validated into frozen
dataclasses before anything starts: an unknown key, a wrong type, a node profile
that does not load, two nodes on the same CAN IDs or the same register block are
each one line naming the file and the key.

Nothing here knows the kinds: a ``[[node]]`` table has the keys every node has
(:class:`NodeConfig`) plus the keys of its ``source`` kind (that kind's ``Options``,
see :mod:`eskin_industrial.bus.source`), and a sub-table per output kind that has
keys of its own for a node (``[node.plc] base_address``: the kind's ``NodeOptions``);
every other top-level section names an output kind (``[plc]``, ``[recorder]``, see
:mod:`eskin_industrial.outputs.base`).

Where a setting can come from, the first that gives it wins: the command line, the
bridge configuration, the node's profile, the defaults (``bridge --check`` prints
each node's resolved values).

Example (two grippers on one CAN bus, written into the PLC over Modbus TCP)::

    [log]
    format = "json"

    [plc]
    mode = "client"
    host = "192.168.0.10"
    port = 502

    [[node]]
    name = "left"
    profile = "paper-5x5"
    interface = "socketcan"
    channel = "can0"

    [[node]]
    name = "right"
    profile = "paper-5x5"
    interface = "socketcan"
    channel = "can0"
    base_id = 0x210
    node_id = 2
    [node.plc]
    base_address = 100
"""

from __future__ import annotations

import dataclasses
import difflib
import tomllib
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

from ..bus.source import Source, source_class
from ..errors import DeprecatedKey, ProfileError
from ..identity import DeviceIdentity
from ..outputs.base import DEFAULT_OUTPUT, OutputKind, output_kind, sink_kinds
from ..profile import MAX_RATE_HZ, STALE_MAX_FACTOR, Profile, derived_stale_s, load_profile
from ..schema import SchemaError, build, in_range, positive_at_most, read_toml_file
from ..seam import DEFAULT_QUEUE_FRAMES, MAX_QUEUE_FRAMES

COMMAND_LINE = "<command line>"


@dataclass(frozen=True)
class NodeConfig:
    """One sensor node: the keys every node has, and its source kind's own options."""

    #: A short name, used in logs, counters and output names.
    name: str
    #: The node's profile; a relative path is taken from the configuration file's folder.
    profile: str
    #: The source kind (``eskin_industrial.bus.source.SOURCES``).
    source: str = "can"
    #: The kind's keys (an instance of its ``Options``), validated.
    options: Any = None
    #: Scan rate; default: the profile's ``[sensor] rate_hz``.
    rate_hz: float | None = field(default=None, metadata=positive_at_most(MAX_RATE_HZ))
    #: Output kind -> its keys for this node (an instance of its ``NodeOptions``):
    #: ``[node.plc] base_address``.
    outputs: dict[str, Any] = field(default_factory=dict)

    @staticmethod
    def of(name: str, profile: str, source: str = "can", *, rate_hz: float | None = None,
           outputs: dict[str, Any] | None = None, **keys: Any) -> NodeConfig:
        """A node from keyword keys, the kind's ones checked as in a file; ``outputs``:
        output kind -> its node keys (a dict, checked as ``[node.KIND]``, or its
        ``NodeOptions`` already built)."""
        cls = source_class(source)
        common = {"rate_hz": rate_hz} if rate_hz is not None else {}
        try:
            options = build(cls.Options, keys)
            node = build(NodeConfig, {"name": name, "profile": profile, **common})  # the bounds, as in a file
            built = {kind: _node_output(kind, value) for kind, value in (outputs or {}).items()}
        except SchemaError as exc:
            raise ProfileError(f"{COMMAND_LINE}: [node {name!r}] {exc}") from None
        return replace(node, source=cls.kind, options=options, outputs=built)


def _node_output(kind: str, value: Any) -> Any:
    """An output kind's node keys: built from a table, or as given."""
    cls = output_kind(kind).NodeOptions
    if cls is None:
        raise SchemaError(kind, f"the output kind {kind!r} has no keys of a node")
    if isinstance(value, dict):
        return build(cls, value, kind)
    return value


_COMMON = [f.name for f in dataclasses.fields(NodeConfig) if f.name not in ("options", "outputs")]


@dataclass(frozen=True)
class LogSettings:
    format: Literal["plain", "json"] = "plain"
    level: Literal["debug", "info", "warning", "error"] = "info"
    #: Every so often, one line with every counter (0: only at the end).
    status_every_s: float = field(default=60.0, metadata=in_range(0, 86400))


@dataclass(frozen=True)
class OutputSupervision:
    """``[supervision.output.KIND]``: one output's own supervision (unset: ``[supervision]``'s)."""

    on_failure: Literal["restart", "stop"] | None = None
    backoff_s: float | None = field(default=None, metadata=in_range(0.01, 60))
    backoff_max_s: float | None = field(default=None, metadata=in_range(0.01, 600))
    hang_s: float | None = field(default=None, metadata=in_range(0.05, 600))


@dataclass(frozen=True)
class SupervisionSettings:
    """``[supervision]``: what an output's failure does (docs/bridge.md, "What stops
    the bridge"): an exception from it, a call of it that hangs, a thread of its own
    that dies."""

    #: Outputs called on the loop's thread (their latency is the product); the others
    #: are handed their data through a mailbox and a thread of their own.
    essential: tuple[str, ...] = ("plc",)
    #: ``restart``: the output is closed and opened again after a back-off, the bridge
    #: goes on; ``stop``: the bridge stops with a failure.
    on_failure: Literal["restart", "stop"] = "restart"
    #: The first wait before a restart, doubling (jittered) up to ``backoff_max_s``.
    backoff_s: float = field(default=1.0, metadata=in_range(0.01, 60))
    backoff_max_s: float = field(default=30.0, metadata=in_range(0.01, 600))
    #: A call of a non-essential output still in progress after this long is a failure.
    hang_s: float = field(default=5.0, metadata=in_range(0.05, 600))
    #: A node loop that has not turned for this long (a hung essential output, a
    #: stuck source call): its nodes' blocks are set offline, nothing claimed, until it
    #: turns again.  A loop turns at least every 50 ms while it runs.
    loop_stall_s: float = field(default=0.5, metadata=in_range(0.1, 600))
    #: Output kind -> its own settings, over the ones above.
    output: dict[str, OutputSupervision] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for key, names in (("essential", self.essential), ("output", tuple(self.output))):
            for name in names:
                if name not in sink_kinds():
                    near = difflib.get_close_matches(name, list(sink_kinds()), n=1, cutoff=0.6)
                    hint = f"did you mean {near[0]!r}?" if near else f"output kinds: {', '.join(sink_kinds())}"
                    raise ValueError(f"{key}: {name!r} is no output kind; {hint}")
        kinds: tuple[str | None, ...] = (None, *self.output)
        for kind in kinds:
            low, high = self.backoff_of(kind), self.policy_value(kind, "backoff_max_s")
            if high < low:
                where = "backoff_max_s" if kind is None else f"output.{kind}.backoff_max_s"
                raise ValueError(f"{where}: expected at least backoff_s ({high:g} < {low:g})")

    def policy_value(self, kind: str | None, key: str) -> Any:
        own = self.output.get(kind) if kind is not None else None
        value = getattr(own, key) if own is not None else None
        return getattr(self, key) if value is None else value

    def backoff_of(self, kind: str | None) -> float:
        value: float = self.policy_value(kind, "backoff_s")
        return value


@dataclass(frozen=True)
class _Top:
    """The top-level keys that are not an output kind's section."""

    log: LogSettings = field(default_factory=LogSettings)
    #: Received CAN frames held per bus; past it, new frames are dropped (counted).
    queue_frames: int = field(default=DEFAULT_QUEUE_FRAMES, metadata=positive_at_most(MAX_QUEUE_FRAMES, "an integer"))
    supervision: SupervisionSettings = field(default_factory=SupervisionSettings)


@dataclass(frozen=True)
class BridgeConfig:
    node: tuple[NodeConfig, ...]
    #: Output kind -> its options, in :data:`SINKS` order; empty: the default output.
    outputs: dict[str, Any] = field(default_factory=dict)
    log: LogSettings = field(default_factory=LogSettings)
    queue_frames: int = DEFAULT_QUEUE_FRAMES
    #: The file it came from, for messages.
    source: str = COMMAND_LINE
    supervision: SupervisionSettings = field(default_factory=SupervisionSettings)
    #: ``[identity]``: the device identity every output names (None: not given; the
    #: first node's profile's ``[modbus.plc.identity]`` of earlier releases, else the defaults).
    identity: DeviceIdentity | None = None

    def __post_init__(self) -> None:
        if not self.node:
            raise ValueError("node: expected at least one [[node]] table")

    def output_kinds(self, default_output: bool = True) -> dict[str, Any]:
        """The outputs to open: the configured ones, or the default one."""
        if self.outputs or not default_output:
            return {k: self.outputs[k] for k in sink_kinds() if k in self.outputs}
        return {DEFAULT_OUTPUT: output_kind(DEFAULT_OUTPUT).default_options()}


@dataclass(frozen=True)
class ResolvedNode:
    """A node with its profile loaded and the node's overrides applied."""

    config: NodeConfig
    profile: Profile

    @property
    def name(self) -> str:
        return self.config.name

    @property
    def rate_hz(self) -> float:
        return self.config.rate_hz or self.profile.sensor.rate_hz

    @property
    def options(self) -> Any:
        return self.config.options

    @property
    def kind(self) -> type[Source]:
        return source_class(self.config.source)

    @property
    def share_key(self) -> tuple | None:
        """Nodes with the same key share one transport (one CAN bus, one reader)."""
        return self.kind.share_key(self)


def load_bridge_config(path: str | Path) -> BridgeConfig:
    path = Path(path)
    text = read_toml_file(path, "bridge configuration")
    return parse_bridge_config(text, str(path))


def parse_bridge_config(text: str, source: str) -> BridgeConfig:
    """TOML text to a :class:`BridgeConfig`; any problem is one :class:`ProfileError`
    line: ``SOURCE: [section] key: what was expected``."""
    try:
        table = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ProfileError(f"{source}: not valid TOML: {exc}") from None
    nodes_raw = table.pop("node", None)
    outputs: dict[str, Any] = {}
    for kind in sink_kinds():
        if kind in table:
            outputs[kind] = _section(output_kind(kind).Options, table.pop(kind), kind, source)
    identity = _section(DeviceIdentity, table.pop("identity"), "identity", source) if "identity" in table else None
    try:
        top = build(_Top, table)
    except SchemaError as exc:
        if exc.message.startswith("unknown key") and "." not in exc.key:
            valid = ["node", *sink_kinds(), "identity", *(f.name for f in dataclasses.fields(_Top))]
            near = difflib.get_close_matches(exc.key, valid, n=1, cutoff=0.6)
            hint = f"did you mean {near[0]!r}?" if near else f"valid sections: {', '.join(valid)}"
            raise ProfileError(f"{source}: [{exc.key}]: unknown section; {hint}") from None
        section, _, key = exc.key.partition(".")
        raise ProfileError(f"{source}: [{section}]{' ' + key if key else ''}: {exc.message}") from None
    if not isinstance(nodes_raw, list) or not nodes_raw:
        raise ProfileError(f"{source}: [node]: expected at least one [[node]] table")
    nodes = tuple(_node(raw, i, source) for i, raw in enumerate(nodes_raw))
    return BridgeConfig(nodes, outputs, top.log, top.queue_frames, source, top.supervision, identity)


def _section(cls: type, raw: Any, name: str, source: str) -> Any:
    if not isinstance(raw, dict):
        raise ProfileError(f"{source}: [{name}]: expected a table")
    try:
        return build(cls, raw)
    except SchemaError as exc:
        raise ProfileError(f"{source}: [{name}] {exc}") from None


def _node(raw: Any, index: int, source: str) -> NodeConfig:
    label = f"[node[{index}]]"  # the table's place, as for any key of the file
    if not isinstance(raw, dict):
        raise ProfileError(f"{source}: {label}: expected a table")
    kind_name = raw.get("source", "can")
    try:
        kind = source_class(kind_name if isinstance(kind_name, str) else repr(kind_name))
    except ProfileError as exc:  # unknown: the nearest and the valid names
        raise ProfileError(f"{source}: {label} source: {exc}") from None
    raw = _moved_node_keys(dict(raw), label, source)
    outputs: dict[str, Any] = {}
    for out_kind in sink_kinds():
        if out_kind in raw:
            table = raw.pop(out_kind)
            if not isinstance(table, dict):
                raise ProfileError(f"{source}: {label} {out_kind}: expected a table ([node.{out_kind}])")
            try:
                outputs[out_kind] = _node_output(out_kind, table)
            except SchemaError as exc:
                raise ProfileError(f"{source}: {label} {exc}") from None
    common = {k: v for k, v in raw.items() if k in _COMMON}
    own = {k: v for k, v in raw.items() if k not in _COMMON}
    try:
        options = build(kind.Options, own)
    except SchemaError as exc:
        if exc.message.startswith("unknown key"):
            valid = _COMMON + [f.name for f in dataclasses.fields(kind.Options) if f.init]
            near = difflib.get_close_matches(exc.key, valid, n=1, cutoff=0.6)
            hint = (f"did you mean {near[0]!r}?" if near
                    else f"valid keys for source = {kind_name!r}: {', '.join(valid)}")
            raise ProfileError(f"{source}: {label} {exc.key}: unknown key; {hint}") from None
        if exc.message.startswith("missing key"):
            raise ProfileError(f"{source}: {label} {exc.key}: missing key (source = {kind_name!r} needs it)") from None
        raise ProfileError(f"{source}: {label} {exc}") from None
    try:  # the keys every node has, checked by NodeConfig's own fields
        return replace(build(NodeConfig, common), options=options, outputs=outputs)
    except SchemaError as exc:
        raise ProfileError(f"{source}: {label} {exc}") from None


def _moved_node_keys(raw: dict[str, Any], label: str, source: str) -> dict[str, Any]:
    """``[[node]]`` keys of earlier releases that an output kind now owns
    (``base_address`` -> ``[node.plc] base_address``): moved, with one warning each."""
    for kind in sink_kinds():
        for old, new in output_kind(kind).moved_node_keys.items():
            if old not in raw:
                continue
            table = raw.setdefault(kind, {})
            if not isinstance(table, dict):
                continue  # the kind's entry is not a table: said when it is read
            if new in table:
                raise ProfileError(f"{source}: {label} {old}: deprecated, and [node.{kind}] {new} is given too; "
                                   f"keep [node.{kind}] {new} only")
            table[new] = raw.pop(old)
            warnings.warn(DeprecatedKey(f"{source}: {label} {old} is deprecated: write [node.{kind}] {new}"),
                          stacklevel=2)
    return raw


def resolve(config: BridgeConfig) -> list[ResolvedNode]:
    """Load every node's profile, apply the overrides, and check the nodes and the
    outputs against each other; the first problem is one :class:`ProfileError` line."""
    base = Path(config.source).parent if config.source != COMMAND_LINE else Path(".")
    nodes: list[ResolvedNode] = []
    for nc in config.node:
        where = f"{config.source}: [node {nc.name!r}]"
        try:  # a path relative to this file's folder, or a built-in name
            loaded = load_profile(nc.profile, base)
        except ProfileError as exc:
            # The profile's own message names its file; prefix the configuration file
            # and the node, so that the line says which [[node]] table points at it.
            raise ProfileError(f"{where} profile: {exc}") from None
        try:
            prof = _apply_overrides(loaded, nc)
        except ValueError as exc:  # the override broke the profile's own rules
            raise ProfileError(f"{where}: {exc}") from None
        # dataclasses.replace() resets the init=False ``source``: keep the profile's path.
        object.__setattr__(prof, "source", loaded.source)
        nodes.append(ResolvedNode(nc, prof))
    _check_together(config, nodes)
    return nodes


def device_identity(config: BridgeConfig, nodes: Sequence[ResolvedNode]) -> DeviceIdentity:
    """The identity the outputs name: ``[identity]``, else the first node's profile's
    ``[modbus.plc.identity]`` (deprecated; its defaults when it has none)."""
    return config.identity or nodes[0].profile.modbus.plc.identity


def check_sources(config: BridgeConfig, nodes: list[ResolvedNode]) -> None:
    """What each source kind can check before anything opens (``--check``, and the
    bridge before it starts): a missing log file, an unknown scene."""
    base = str(Path(config.source).parent) if config.source != COMMAND_LINE else "."
    for n in nodes:
        try:
            n.kind.check(n, base)
        except ValueError as exc:
            raise ProfileError(f"{config.source}: [node {n.name!r}] {exc}") from None


def probe_outputs(config: BridgeConfig, nodes: list[ResolvedNode]) -> None:
    """``--check`` only: what each output kind finds by trying on this machine (a
    server's port is free); the run meets the same when it opens the output."""
    for kind, options in config.output_kinds().items():
        try:
            output_kind(kind).probe(options, nodes)
        except ValueError as exc:
            raise ProfileError(f"{config.source}: [{kind}] {exc}") from None


def _apply_overrides(prof: Profile, nc: NodeConfig) -> Profile:
    prof = source_class(nc.source).adapt_profile(prof, nc.options)
    for kind, node_options in nc.outputs.items():
        prof = output_kind(kind).adapt_profile(prof, node_options)
    if nc.rate_hz is not None:
        # A stale limit the profile did not set was derived from the profile's rate;
        # a node running slower must get its own, or it reads stale between two scans.
        poll = prof.modbus.node.poll_hz
        if prof.output.stale_s == derived_stale_s(prof.sensor.rate_hz, poll):
            # (and its ceiling, when that was derived too: re-derived from the new limit)
            derived_max = prof.output.stale_max_s == STALE_MAX_FACTOR * prof.stale_s
            prof = replace(prof, output=replace(prof.output, stale_s=derived_stale_s(nc.rate_hz, poll),
                                                stale_max_s=None if derived_max else prof.output.stale_max_s))
    return prof


def _check_together(config: BridgeConfig, nodes: list[ResolvedNode]) -> None:
    src = config.source
    names = [n.name for n in nodes]
    for name in names:
        if names.count(name) > 1:
            raise ProfileError(f"{src}: [node] name: {name!r} is used by two nodes")
    by_kind: dict[type[Source], list[ResolvedNode]] = {}
    for n in nodes:
        by_kind.setdefault(n.kind, []).append(n)
    for source_kind, members in by_kind.items():
        try:
            source_kind.check_together(members)
        except ValueError as exc:  # the kind's message starts with "[node ...]"
            raise ProfileError(f"{src}: {exc}") from None
    for kind, options in config.output_kinds().items():
        try:
            output_kind(kind).check(options, nodes)
        except ValueError as exc:  # about one node ("[node ...] key: ..."), or the section
            where = "" if str(exc).startswith("[node ") else f"[{kind}] "
            raise ProfileError(f"{src}: {where}{exc}") from None


def output_classes(config: BridgeConfig, default_output: bool = True) -> list[tuple[type[OutputKind[Any]], Any]]:
    return [(output_kind(kind), options) for kind, options in config.output_kinds(default_output).items()]


def explain(config: BridgeConfig, node: ResolvedNode) -> list[tuple[str, Any, str]]:
    """The node's settings as resolved, each with where it came from (``--explain``):
    the command line or the bridge configuration, the profile, or the default."""
    given = "command line" if config.source == COMMAND_LINE else config.source
    prof = f"profile {node.profile.source}"
    out: list[tuple[str, Any, str]] = []

    def from_profile(key: str) -> Any:
        value: Any = node.profile
        for part in key.split("."):
            value = getattr(value, part)
        return value

    def add(prefix: str, options: Any, profile_keys: dict[str, str], origin: str) -> None:
        for f in dataclasses.fields(options):
            value = getattr(options, f.name)
            default = None if f.default is dataclasses.MISSING else f.default
            name = f"{prefix}{f.name}"
            if value is not None and (f.default is dataclasses.MISSING or value != default):
                out.append((name, value, origin))
            elif f.name in profile_keys:
                out.append((name, from_profile(profile_keys[f.name]), prof))
            elif value is not None:
                out.append((name, value, "default"))

    c = node.config
    out.append(("rate_hz", node.rate_hz, given if c.rate_hz is not None else prof))
    out.append(("source", c.source, given))
    add("", c.options, node.kind.profile_keys, given)
    for kind in sink_kinds():  # the output kinds' keys of this node, as the profile resolves them
        cls = output_kind(kind)
        for key, profile_key in cls.node_profile_keys.items():
            mine = c.outputs.get(kind)
            value = from_profile(profile_key)
            set_here = mine is not None and getattr(mine, key, None) is not None
            out.append((f"node.{kind}.{key}", value, given if set_here else prof))
    for kind, options in config.output_kinds().items():
        add(f"{kind}.", options, output_kind(kind).explain_keys(options, [node]),
            given if kind in config.outputs else "default output")
    return out
