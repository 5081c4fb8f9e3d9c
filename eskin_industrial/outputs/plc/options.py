"""The PLC output's settings: ``[plc]`` of the bridge configuration (or ``--plc``)
and ``[node.plc]`` of a node (how a node profile's deprecated ``[modbus.plc]`` keys
still fill what ``[plc]`` leaves unset: :mod:`.legacy`).

A module of its own so that the writer (:mod:`.client`), the server (:mod:`.server`)
and the kind (:mod:`.kind`) all read them without importing one another.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal

from ...netaddr import check_host, parse_endpoint
from ...schema import in_range, ip_network, positive

if TYPE_CHECKING:
    pass


@dataclass(frozen=True)
class PlcOptions:
    """``[plc]``: where the register blocks go and how the PLC is served or written;
    an unset key is its default (or, deprecated, the first node's profile's
    ``[modbus.plc]`` key: :mod:`.legacy`)."""

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
    #: Server mode: the unit id answered (and the server id of FC17); client mode:
    #: the unit id written to (default 1).
    unit_id: int | None = field(default=None, metadata=in_range(0, 255))
    #: Server mode: access and connections (defaults: 8 connections, 60 s idle, any
    #: client may read and write, unit ids ``unit_id``, 0 and 255); see
    #: docs/operations.md, "Who may talk to the server".
    max_connections: int | None = field(default=None, metadata=in_range(1, 1024))
    idle_timeout_s: float | None = field(default=None, metadata=in_range(0.1, 86400))
    allow_read: tuple[str, ...] | None = field(default=None, metadata=ip_network())
    allow_write: tuple[str, ...] | None = field(default=None, metadata=ip_network())
    read_only: bool | None = None
    unit_ids: tuple[int, ...] | None = field(default=None, metadata=in_range(0, 255))
    #: Client mode: how long the PLC has to answer (default 0.5 s; an answer up to as
    #: long again is still taken, and counted as late), and the back-off after a
    #: failure (doubling from ``backoff_s`` to ``backoff_max_s``, defaults 0.1 and 2 s).
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


@dataclass(frozen=True)
class PlcNodeOptions:
    """``[node.plc]`` of one ``[[node]]``: where that node's block lies."""

    #: The node's register block in the PLC; default: the profile's ``[modbus.plc] base_address``.
    base_address: int | None = field(default=None, metadata=in_range(0, 65000))


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
