"""The PLC output's settings: ``[plc]`` of the bridge configuration (or ``--plc``),
``[node.plc]`` of a node, and how they combine with a node profile's ``[modbus.plc]``.

A module of its own so that the writer (:mod:`.client`), the server (:mod:`.server`)
and the kind (:mod:`.sink`) all read them without importing one another.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Literal

from ...netaddr import check_host, parse_endpoint
from ...profile import ModbusPlcSection
from ...schema import in_range, ip_network, positive

if TYPE_CHECKING:
    from ...seam import NodeLike


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
