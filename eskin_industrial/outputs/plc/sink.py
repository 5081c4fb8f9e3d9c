"""The PLC as an output kind (``[plc]`` in the bridge configuration, ``--plc`` on the
command line): each node's register image, written into the PLC (client mode, one
:class:`~eskin_industrial.outputs.plc.client.PlcWriter` per node) or served to it (server
mode, one :class:`~eskin_industrial.outputs.plc.server.PlcServer` with one block per node).

Where a setting can come from, the first that gives it wins: the command line
(``--plc``), the bridge configuration's ``[plc]``, the node profile's ``[modbus.plc]``
(the first node's, for the connection), the defaults.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Literal

from ...netaddr import check_host, listen_problem, parse_endpoint
from ...preflight import check_serial
from ...profile import ModbusPlcSection, Profile
from ...schema import in_range, ip_network, positive
from ..base import CliOption, Sink
from .image import IMAGE_COUNT

if TYPE_CHECKING:
    from ...seam import NodeLike, OpenContext


@dataclass(frozen=True)
class PlcOptions:
    """``[plc]``: where the register blocks go; unset keys come from the first node's
    profile ``[modbus.plc]``."""

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
    #: Server mode: access and connections, as ``[modbus.plc]`` says them (unset: the
    #: first node's profile); see docs/operations.md, "Who may talk to the server".
    max_connections: int | None = field(default=None, metadata=in_range(1, 1024))
    idle_timeout_s: float | None = field(default=None, metadata=in_range(0.1, 86400))
    allow_read: tuple[str, ...] | None = field(default=None, metadata=ip_network())
    allow_write: tuple[str, ...] | None = field(default=None, metadata=ip_network())
    read_only: bool | None = None
    unit_ids: tuple[int, ...] | None = field(default=None, metadata=in_range(0, 255))
    #: Client mode: how long the PLC has to answer, and the back-off after a failure
    #: (doubling from ``backoff_s`` to ``backoff_max_s``); unset: the profile's.
    timeout_s: float | None = field(default=None, metadata=in_range(0.01, 30))
    backoff_s: float | None = field(default=None, metadata=in_range(0.01, 60))
    backoff_max_s: float | None = field(default=None, metadata=in_range(0.01, 600))

    def __post_init__(self) -> None:
        if self.transport == "rtu" and self.serial_port is None:
            raise ValueError("serial_port: missing key (transport = 'rtu' needs it)")
        if self.host is not None:
            check_host(self.host)
        if self.backoff_s is not None and self.backoff_max_s is not None and self.backoff_max_s < self.backoff_s:
            raise ValueError("backoff_max_s: expected at least backoff_s")

    def client_settings(self, plc: ModbusPlcSection) -> ModbusPlcSection:
        """A node's ``[modbus.plc]`` with this section's timeout and back-off laid over it;
        ValueError when the two together leave ``backoff_max_s`` below ``backoff_s``."""
        keys = ("timeout_s", "backoff_s", "backoff_max_s")
        given = {k: getattr(self, k) for k in keys if getattr(self, k) is not None}
        return replace(plc, **given) if given else plc


@dataclass(frozen=True)
class PlcNodeOptions:
    """``[node.plc]`` of one ``[[node]]``: where that node's block lies."""

    #: The node's register block in the PLC; default: the profile's ``[modbus.plc] base_address``.
    base_address: int | None = field(default=None, metadata=in_range(0, 65000))


#: The ``[plc]`` keys that override the first node's ``[modbus.plc]`` for the server.
SERVER_KEYS = ("max_connections", "idle_timeout_s", "allow_read", "allow_write", "read_only", "unit_ids")


def server_settings(options: PlcOptions, nodes: Sequence[NodeLike[Any]]) -> ModbusPlcSection:
    """The first node's ``[modbus.plc]`` with what ``[plc]`` sets of :data:`SERVER_KEYS`."""
    given = {k: getattr(options, k) for k in SERVER_KEYS if getattr(options, k) is not None}
    return replace(nodes[0].profile.modbus.plc, **given)


def plc_mode(options: PlcOptions, nodes: Sequence[NodeLike[Any]]) -> Literal["client", "server"]:
    mode = options.mode or nodes[0].profile.modbus.plc.mode
    return "client" if mode == "client" else "server"


def serve_address(options: PlcOptions, nodes: Sequence[NodeLike[Any]]) -> tuple[str, int]:
    """Server mode over TCP: where to listen (``[plc]`` / ``--plc``, else the first
    node's ``[modbus.plc] bind`` and ``port``)."""
    first = nodes[0].profile.modbus.plc
    return options.host or first.bind, options.port or first.port


def parse_plc_spec(spec: str, baud: int) -> PlcOptions:
    """``tcp:HOST[:PORT]``, ``rtu:PORT``, ``serve:PORT``, ``serve::PORT``,
    ``serve:HOST:PORT``, ``serve-rtu:PORT`` (``KIND://...`` reads the same; an IPv6
    host with a port in brackets, ``serve:[::1]:1502``); ValueError names what is wrong."""
    kind, sep, where = spec.partition(":")
    where = where[2:] if where.startswith("//") else where
    if not sep:
        raise ValueError(f"expected KIND:WHERE, got {spec!r}")
    if kind in ("tcp", "serve"):
        host, port = parse_host_port(where)
        return PlcOptions(mode="client" if kind == "tcp" else "server", host=host, port=port)
    if kind in ("rtu", "serve-rtu"):
        if not where:
            raise ValueError(f"expected {kind}:PORT, got {spec!r}")
        return PlcOptions(mode="client" if kind == "rtu" else "server", transport="rtu", serial_port=where,
                          baudrate=baud)
    raise ValueError(f"unknown PLC kind {kind!r}; expected tcp:HOST:PORT, rtu:PORT, serve:HOST:PORT or "
                     f"serve-rtu:PORT")


def parse_host_port(text: str, require_port: bool = False) -> tuple[str | None, int | None]:
    """``HOST:PORT``, ``HOST``, ``:PORT`` or ``PORT`` (digits alone are a port), or
    nothing when the port is not required: None for what is left out, for the
    caller's default; ValueError when malformed (:func:`eskin_industrial.netaddr.parse_endpoint`)."""
    return parse_endpoint(text, require_port)


class PlcSink(Sink[PlcOptions]):
    """The output kind "plc"; its sinks are :class:`PlcWriter` (client mode) and
    :class:`PlcBlockSink` (one node's block of the server)."""

    kind = "plc"
    Options = PlcOptions
    #: server mode's Modbus server (the writer's thread is ``plc-writer``)
    thread_names = ("modbus-server", "modbus-rtu-server")
    NodeOptions = PlcNodeOptions
    moved_node_keys = {"base_address": "base_address"}
    node_profile_keys = {"base_address": "modbus.plc.base_address"}
    node_cli_options = (CliOption("--base-address", "base_address", "One node: its register block (default: the "
                                  "profile's [modbus.plc] base_address).", type=int, metavar="N"),)
    profile_keys = {"mode": "modbus.plc.mode", "host": "modbus.plc.host", "port": "modbus.plc.port",
                    "timeout_s": "modbus.plc.timeout_s", "backoff_s": "modbus.plc.backoff_s",
                    "backoff_max_s": "modbus.plc.backoff_max_s", **{k: f"modbus.plc.{k}" for k in SERVER_KEYS}}
    cli_options = (
        CliOption("--plc", "plc", "tcp:HOST:PORT (write into the PLC), rtu:PORT (PLC as RTU slave), serve:HOST:PORT "
                  "or serve:PORT (serve, the PLC reads; the host: the profile's bind), serve-rtu:PORT; IPv6 in "
                  "brackets ([::1]:1502); default: the profile's [modbus.plc].", metavar="SPEC"),
        CliOption("--plc-baud", "plc_baud", "Baud rate for rtu: and serve-rtu:.", type=int, default=115200),
        CliOption("--plc-timeout", "plc_timeout", "Client mode: seconds the PLC has to answer a write "
                  "(0.01 to 30); default: the profile's [modbus.plc] timeout_s.", metavar="S", type=float),
    )

    @classmethod
    def options_from_cli(cls, values: dict[str, Any]) -> PlcOptions | None:
        spec, timeout = values.get("plc"), values.get("plc_timeout")
        if spec is None and timeout is None:
            return None
        options = PlcOptions() if spec is None else parse_plc_spec(spec, values.get("plc_baud") or 115200)
        if timeout is not None:
            if not 0.01 <= timeout <= 30:
                raise ValueError(f"--plc-timeout: expected 0.01 to 30 s, got {timeout:g}")
            options = replace(options, timeout_s=timeout)
        return options

    @classmethod
    def node_options_from_cli(cls, values: dict[str, Any]) -> PlcNodeOptions | None:
        base = values.get("base_address")
        if base is None:
            return None
        if not 0 <= base <= 65000:
            raise ValueError(f"--base-address: expected 0 to 65000, got {base}")
        return PlcNodeOptions(base)

    @classmethod
    def adapt_profile(cls, profile: Profile, node_options: PlcNodeOptions | None) -> Profile:
        if node_options is None or node_options.base_address is None:
            return profile
        plc = replace(profile.modbus.plc, base_address=node_options.base_address)
        return replace(profile, modbus=replace(profile.modbus, plc=plc))

    @classmethod
    def describe(cls, options: PlcOptions, node: NodeLike[Any]) -> str:
        return f"PLC {plc_mode(options, [node])} block at {node.profile.modbus.plc.base_address}"

    @classmethod
    def check(cls, options: PlcOptions, nodes: Sequence[NodeLike[Any]]) -> None:
        blocks = sorted((n.profile.modbus.plc.base_address, n.name) for n in nodes)
        for (lo, a), (hi, b) in zip(blocks, blocks[1:]):
            if hi - lo < IMAGE_COUNT:
                raise ValueError(f"[node {b!r}] plc.base_address: {hi} overlaps the block of node {a!r} at {lo} "
                                 f"(a block takes {IMAGE_COUNT} registers)")
        if options.transport == "rtu" and plc_mode(options, nodes) == "client" and len(nodes) > 1:
            raise ValueError("transport: a PLC on a serial line takes one node in client mode "
                             "(use server mode, or TCP)")
        for n in nodes:
            options.client_settings(n.profile.modbus.plc)  # the back-off bounds, with the profile's

    @classmethod
    def explain_keys(cls, options: PlcOptions, nodes: Sequence[NodeLike[Any]]) -> dict[str, str]:
        if plc_mode(options, nodes) == "server":  # a server listens on the profile's bind, not its PLC host
            return {**cls.profile_keys, "host": "modbus.plc.bind"}
        return cls.profile_keys

    @classmethod
    def probe(cls, options: PlcOptions, nodes: Sequence[NodeLike[Any]]) -> None:
        """Server mode: the port can be listened on, the serial device is there.  (A
        client's PLC may be down at ``--check``; the writer waits for it.)"""
        if plc_mode(options, nodes) != "server":
            return
        if options.transport == "rtu":
            assert options.serial_port is not None  # PlcOptions requires it over RTU
            check_serial(options.serial_port, "serial_port")
            return
        host, port = serve_address(options, nodes)
        problem = listen_problem(host, port)
        if problem:
            raise ValueError(f"port: {problem}")

    @classmethod
    def open_nodes(cls, options: PlcOptions, nodes: Sequence[NodeLike[Any]], context: OpenContext) -> list[Sink[Any]]:
        from ...modbus.serial_line import SerialSettings
        from .client import PlcWriter
        from .server import PlcServer, identity_of, policy_of

        first = nodes[0].profile.modbus.plc
        serial = None
        if options.transport == "rtu":
            assert options.serial_port is not None  # PlcOptions requires it over RTU
            serial = SerialSettings(options.serial_port, options.baudrate)
        if plc_mode(options, nodes) == "server":
            tcp = None if serial else serve_address(options, nodes)
            blocks = [n.profile.modbus.plc for n in nodes]
            merged = server_settings(options, nodes)
            server = PlcServer(first, tcp=tcp, serial=serial, blocks=blocks, linger_s=options.offline_linger_s,
                               policy=policy_of(merged, blocks), identity=identity_of(first, nodes[0].profile.name)
                               ).start()
            context.closers.append(server.stop)
            return [server.block(i) for i in range(len(nodes))]
        sinks: list[Sink[Any]] = []
        for n in nodes:
            w = PlcWriter(options.client_settings(n.profile.modbus.plc), options.host, options.port,
                          serial=serial, refresh_s=n.profile.output.refresh_s).start()
            context.closers.append(w.close)
            sinks.append(w)
        return sinks
