"""The bridge's configuration: which nodes, from which source, into which PLC block.

One TOML file (``eskin-bus bridge --config FILE``), or the same built from the
command line for a single node.  Like profiles, it is validated into frozen
dataclasses before anything starts: an unknown key, a wrong type, a node profile
that does not load, two nodes on the same CAN IDs or the same register block are
each one line naming the file and the key.

Example (two grippers on one CAN bus, written into the PLC over Modbus TCP)::

    [log]
    format = "json"

    [plc]
    mode = "client"
    host = "192.168.0.10"
    port = 502

    [[node]]
    name = "left"
    profile = "profiles/paper-5x5.toml"
    interface = "socketcan"
    channel = "can0"
    base_address = 0

    [[node]]
    name = "right"
    profile = "profiles/paper-5x5.toml"
    interface = "socketcan"
    channel = "can0"
    base_id = 0x210
    node_id = 2
    base_address = 100
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Literal

from ..errors import ProfileError
from ..profile import Profile, derived_stale_s, load_profile
from ..schema import in_range, parse_toml, positive, read_toml_file

SourceKind = Literal["can", "can-log", "modbus-rtu", "scene"]


@dataclass(frozen=True)
class NodeConfig:
    """One sensor node: where its scans come from and where its register block goes."""

    #: A short name, used in logs and counters.
    name: str
    #: The node's profile; a relative path is taken from the configuration file's folder.
    profile: str
    source: SourceKind = "can"
    # -- source = "can": python-can's own names; unset ones are left to python-can's
    # configuration (file, CAN_INTERFACE, CAN_CHANNEL)
    interface: str | None = None
    channel: str | None = None
    bitrate_bps: int | None = field(default=None, metadata=positive())
    fd: bool | None = None
    data_bitrate_bps: int | None = field(default=None, metadata=positive())
    #: Override the profile's ``[can] base_id`` / ``node_id`` (several nodes, one bus).
    base_id: int | None = field(default=None, metadata=in_range(0, 0x1FFFFFFF))
    node_id: int | None = field(default=None, metadata=in_range(0, 255))
    # -- source = "can-log": a candump/asc/blf log replayed at its own pace, once
    path: str | None = None
    # -- source = "scene": a built-in scene (or scene .toml) played in real time
    scene: str | None = None
    seed: int = 0
    loop: bool = True
    # -- source = "modbus-rtu": the node's serial port; unit id and baud rate
    # default to the profile's [modbus.node]
    serial_port: str | None = None
    unit_id: int | None = field(default=None, metadata=in_range(1, 247))
    baudrate: int | None = field(default=None, metadata=positive())
    #: Scan rate; default: the profile's ``[sensor] rate_hz``.
    rate_hz: float | None = field(default=None, metadata=positive())
    #: The node's register block in the PLC; default: the profile's ``[modbus.plc] base_address``.
    base_address: int | None = field(default=None, metadata=in_range(0, 65000))

    def __post_init__(self) -> None:
        need = {"can-log": "path", "scene": "scene", "modbus-rtu": "serial_port"}.get(self.source)
        if need is not None and getattr(self, need) is None:
            raise ValueError(f"{need}: missing key (source = {self.source!r} needs it)")


@dataclass(frozen=True)
class PlcOutput:
    """Where the register blocks go; unset keys come from the first node's profile."""

    #: ``client``: write into the PLC; ``server``: serve the blocks, the PLC reads.
    mode: Literal["client", "server"] | None = None
    transport: Literal["tcp", "rtu"] = "tcp"
    #: Client over TCP: the PLC.  Server over TCP: ``host`` is the address to listen on.
    host: str | None = None
    port: int | None = field(default=None, metadata=in_range(1, 65535))
    #: Over RTU: the serial port (client: the PLC is the slave; server: we are).
    serial_port: str | None = None
    baudrate: int = field(default=115200, metadata=positive())
    #: Server mode, on shutdown: keep serving the "bridge offline" image this long,
    #: so that a polling PLC reads it before the connection goes.
    offline_linger_s: float = field(default=0.5, metadata=in_range(0, 60))

    def __post_init__(self) -> None:
        if self.transport == "rtu" and self.serial_port is None:
            raise ValueError("serial_port: missing key (transport = 'rtu' needs it)")


@dataclass(frozen=True)
class LogSettings:
    format: Literal["plain", "json"] = "plain"
    level: Literal["debug", "info", "warning", "error"] = "info"
    #: Every so often, one line with every counter (0: only at the end).
    status_every_s: float = field(default=60.0, metadata=in_range(0, 86400))


@dataclass(frozen=True)
class BridgeConfig:
    node: tuple[NodeConfig, ...]
    plc: PlcOutput = field(default_factory=PlcOutput)
    log: LogSettings = field(default_factory=LogSettings)
    #: Received CAN frames held per bus before the oldest are dropped (counted).
    queue_frames: int = field(default=200_000, metadata=positive("an integer >= 1"))
    #: The file it came from, for messages (not a TOML key).
    source: str = field(default="<command line>", init=False, compare=False)

    def __post_init__(self) -> None:
        if not self.node:
            raise ValueError("node: expected at least one [[node]] table")


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
    def bus_key(self) -> tuple:
        """Nodes with the same key share one CAN bus (one reader)."""
        c = self.config
        if c.source == "can-log":
            return ("can-log", c.path)
        return ("can", c.interface, c.channel, c.bitrate_bps, self.fd, c.data_bitrate_bps)

    @property
    def fd(self) -> bool:
        return self.profile.can.fd if self.config.fd is None else self.config.fd


def load_bridge_config(path: str | Path) -> BridgeConfig:
    path = Path(path)
    text = read_toml_file(path, "bridge configuration")
    config = parse_toml(BridgeConfig, text, str(path))
    object.__setattr__(config, "source", str(path))
    return config


def resolve(config: BridgeConfig) -> list[ResolvedNode]:
    """Load every node's profile, apply the overrides, and check the nodes against
    each other; the first problem is one :class:`ProfileError` line."""
    base = Path(config.source).parent if config.source != "<command line>" else Path(".")
    nodes: list[ResolvedNode] = []
    for i, nc in enumerate(config.node):
        where = f"{config.source}: [node {nc.name!r}]"
        path = Path(nc.profile)
        try:
            loaded = load_profile(path if path.is_absolute() else base / path)
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


def _apply_overrides(prof: Profile, nc: NodeConfig) -> Profile:
    can = prof.can
    if nc.base_id is not None or nc.node_id is not None:
        can = replace(can, base_id=can.base_id if nc.base_id is None else nc.base_id,
                      node_id=can.node_id if nc.node_id is None else nc.node_id)
    node = prof.modbus.node
    if nc.unit_id is not None or nc.baudrate is not None:
        node = replace(node, unit_id=nc.unit_id or node.unit_id, baudrate=nc.baudrate or node.baudrate)
    plc = prof.modbus.plc
    if nc.base_address is not None:
        plc = replace(plc, base_address=nc.base_address)
    if nc.rate_hz is not None:
        # A stale limit the profile did not set was derived from the profile's rate;
        # a node running slower must get its own, or it reads stale between two scans.
        poll = prof.modbus.node.poll_hz
        if plc.stale_s == derived_stale_s(prof.sensor.rate_hz, poll):
            plc = replace(plc, stale_s=derived_stale_s(nc.rate_hz, poll))
    return replace(prof, can=can, modbus=replace(prof.modbus, node=node, plc=plc))


def _check_together(config: BridgeConfig, nodes: list[ResolvedNode]) -> None:
    from ..bus.can.layout import ID_RANGE
    from ..plc.image import IMAGE_COUNT

    src = config.source
    names = [n.name for n in nodes]
    for name in names:
        if names.count(name) > 1:
            raise ProfileError(f"{src}: [node] name: {name!r} is used by two nodes")
    blocks = sorted((n.profile.modbus.plc.base_address, n.name) for n in nodes)
    for (lo, a), (hi, b) in zip(blocks, blocks[1:]):
        if hi - lo < IMAGE_COUNT:
            raise ProfileError(f"{src}: [node {b!r}] base_address: {hi} overlaps the block of node {a!r} at {lo} "
                               f"(a block takes {IMAGE_COUNT} registers)")
    ports = [n.config.serial_port for n in nodes if n.config.source == "modbus-rtu"]
    for port in ports:
        if ports.count(port) > 1:
            raise ProfileError(f"{src}: [node] serial_port: {port!r} is used by two nodes (one node per line)")
    by_bus: dict[tuple, list[ResolvedNode]] = {}
    for n in nodes:
        if n.config.source in ("can", "can-log"):
            by_bus.setdefault(n.bus_key, []).append(n)
    for group in by_bus.values():
        spans = sorted((n.profile.can.base_id, n.profile.can.extended_id, n.name) for n in group)
        for (lo, ext_a, a), (hi, ext_b, b) in zip(spans, spans[1:]):
            if ext_a == ext_b and hi - lo < ID_RANGE:
                raise ProfileError(f"{src}: [node {b!r}] base_id: {hi:#x} overlaps node {a!r} at {lo:#x} on the same "
                                   f"bus (a node takes {ID_RANGE} IDs; set base_id)")
    out = config.plc
    if out.transport == "rtu" and _mode(config, nodes) == "client" and len(nodes) > 1:
        raise ProfileError(f"{src}: [plc] transport: a PLC on a serial line takes one node in client mode "
                           f"(use server mode, or TCP)")


def _mode(config: BridgeConfig, nodes: list[ResolvedNode]) -> str:
    return config.plc.mode or nodes[0].profile.modbus.plc.mode


def plc_mode(config: BridgeConfig, nodes: list[ResolvedNode]) -> Literal["client", "server"]:
    return "client" if _mode(config, nodes) == "client" else "server"
