"""The PLC as an output kind (``[plc]`` in the bridge configuration, ``--plc`` on the
command line): each node's register image, written into the PLC (client mode, one
:class:`~eskin_industrial.outputs.plc.client.PlcWriter` per node) or served to it (server
mode, one :class:`~eskin_industrial.outputs.plc.server.PlcServer` with one block per node).

Where a setting can come from, the first that gives it wins: the command line
(``--plc``), the bridge configuration's ``[plc]``, the defaults (a node profile's
``[modbus.plc]`` of earlier releases, deprecated, before them: :mod:`.legacy`).  The
register image of a node's block is its profile's (``[modbus.plc] base_address``,
``word_order``, ``r_scale``), the block's place ``[node.plc] base_address`` when given.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, Any

from ...netaddr import listen_problem
from ...preflight import check_serial
from ...profile import Profile
from ..base import CliOption, OutputKind, Sink
from .image import IMAGE_COUNT
from .legacy import block_settings, explain_keys, plc_mode, serve_address
from .options import PlcNodeOptions, PlcOptions, parse_plc_spec

if TYPE_CHECKING:
    from ...seam import NodeLike, OpenContext


class PlcKind(OutputKind[PlcOptions]):
    """The output kind "plc"; its sinks are :class:`PlcWriter` (client mode) and
    :class:`PlcBlockSink` (one node's block of the server)."""

    name = "plc"
    Options = PlcOptions
    #: server mode's Modbus server (the writer's thread is ``plc-writer``)
    thread_names = ("modbus-server", "modbus-rtu-server")
    NodeOptions = PlcNodeOptions
    moved_node_keys = {"base_address": "base_address"}
    node_profile_keys = {"base_address": "modbus.plc.base_address"}
    node_cli_options = (CliOption("--base-address", "base_address", "One node: its register block (default: the "
                                  "profile's [modbus.plc] base_address).", type=int, metavar="N"),)
    profile_keys = explain_keys("client")
    cli_options = (
        CliOption("--plc", "plc", "tcp:HOST:PORT (write into the PLC), rtu:PORT (PLC as RTU slave), serve:HOST:PORT "
                  "or serve:PORT (serve, the PLC reads; the host: 127.0.0.1), serve-rtu:PORT; IPv6 in "
                  "brackets ([::1]:1502); default: serve on 127.0.0.1:502.", metavar="SPEC"),
        CliOption("--plc-baud", "plc_baud", "Baud rate for rtu: and serve-rtu:.", type=int, default=115200),
        CliOption("--plc-timeout", "plc_timeout", "Client mode: seconds the PLC has to answer a write "
                  "(0.01 to 30); default: [plc] timeout_s, else 0.5.", metavar="S", type=float),
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
        mode = plc_mode(options, nodes)
        for n in nodes:
            block_settings(options, n.profile.modbus.plc, mode)  # the back-off bounds, with a profile's

    @classmethod
    def explain_keys(cls, options: PlcOptions, nodes: Sequence[NodeLike[Any]]) -> dict[str, str]:
        return explain_keys(plc_mode(options, nodes))

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
    def _open_nodes(cls, options: PlcOptions, nodes: Sequence[NodeLike[Any]], context: OpenContext) -> list[Sink]:
        from ...modbus.serial_line import SerialSettings
        from .client import PlcWriter
        from .server import PlcServer, identity_of, policy_of

        mode = plc_mode(options, nodes)
        blocks = [block_settings(options, n.profile.modbus.plc, mode) for n in nodes]
        serial = None
        if options.transport == "rtu":
            assert options.serial_port is not None  # PlcOptions requires it over RTU
            serial = SerialSettings(options.serial_port, options.baudrate)
        if mode == "server":
            tcp = None if serial else serve_address(options, nodes)
            first = blocks[0]  # the connection's settings: the first node's, with [plc]'s
            server = PlcServer(first, tcp=tcp, serial=serial, blocks=blocks, linger_s=options.offline_linger_s,
                               policy=policy_of(first, blocks),
                               identity=identity_of(context.identity, nodes[0].profile.name)).start()
            context.closers.append(server.stop)
            return [server.block(i) for i in range(len(nodes))]
        sinks: list[Sink] = []
        for n, settings in zip(nodes, blocks):
            w = PlcWriter(settings, options.host, options.port, serial=serial,
                          refresh_s=n.profile.output.refresh_s).start()
            context.closers.append(w.close)
            sinks.append(w)
        return sinks
