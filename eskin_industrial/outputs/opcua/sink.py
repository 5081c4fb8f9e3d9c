"""OPC UA as an output kind (``[opcua]`` in the bridge configuration, ``--opcua
opc.tcp://HOST:PORT`` on the command line): one server for the bridge
(:mod:`.server`), one object per node; each node's sink hands its snapshots, frames
and source's end to the server and takes back the commands its methods queued.

Where a setting can come from, the first that gives it wins: the command line, the
bridge configuration's ``[opcua]``, the defaults (:class:`.options.OpcuaOptions`).
"""

from __future__ import annotations

import importlib.util
import math
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from ... import __version__
from ...errors import MissingExtra, ProfileError
from ...netaddr import listen_problem
from ...preflight import check_readable
from ...schema import SchemaError, build
from ..base import CliOption, OutputKind, Sink, SinkHealth
from .options import OpcuaOptions

if TYPE_CHECKING:
    from ...frames import Frame
    from ...identity import DeviceIdentity
    from ...node import Command, NodeSnapshot
    from ...seam import NodeLike, OpenContext
    from .nodeinfo import NodeInfo
    from .process import OpcuaProcess

#: What a node's name must not hold: its object's string node ids join names with '.'.
_NAME_FORBIDDEN = set("./")


def need_asyncua(what: str = "the opcua output") -> None:
    """The one missing-extra error of this output (exit 4)."""
    # found, not imported: the bridge's process leaves asyncua to the server's (.process)
    try:
        found = importlib.util.find_spec("asyncua") is not None
    except ImportError:  # a finder that refuses it: as missing as not installed
        found = False
    if not found:
        raise MissingExtra.of(what, "asyncua", "opcua")


def node_info(node: NodeLike[Any], frame_interval_s: float, ident: DeviceIdentity) -> NodeInfo:
    """What the model says about a node, from its profile, ``[identity]`` and the package."""
    from ...methods import get_method
    from .nodeinfo import NodeInfo

    p = node.profile
    model = ident.model_name or p.sensor.name
    x, y = p.layout.coordinates_mm()
    full = p.calibration.full_scale_n
    # an unbounded full scale (the default 1e300) is no range a client can draw
    per_taxel = full if math.isfinite(full) and full < 1e6 else 0.0
    scores = get_method(p.detector.method).scores
    ident_values = {
        "Manufacturer": ident.vendor_name, "Model": model, "ProductCode": ident.product_code,
        "SerialNumber": node.name,
        "ProductInstanceUri": f"urn:{ident.vendor_name}:{ident.product_code}:{node.name}".replace(" ", "-"),
        "SoftwareRevision": ident.revision or __version__, "ComponentName": node.name,
    }
    return NodeInfo(node.name, (scores[0].name, scores[1].name), (scores[0].doc, scores[1].doc), ident_values,
                    (0.0, per_taxel * p.taxels), (float(x.min()), float(x.max())), (float(y.min()), float(y.max())),
                    (p.layout.rows, p.layout.cols) if frame_interval_s else None, (0.0, per_taxel))


class OpcuaSink(Sink):
    """One node's object on the bridge's OPC UA server (opened by :class:`OpcuaKind`)."""

    def __init__(self, server: OpcuaProcess, index: int, name: str) -> None:
        super().__init__()
        self.server = server
        self.index = index
        self.handover = server.handovers[index]
        self.where = f"{server.options.endpoint} Machines/{name}"
        self.frame_every_s = server.options.frame_interval_s or None
        self._offline = False

    def _publish(self, snapshot: NodeSnapshot) -> None:
        self.server.published[self.index] = snapshot
        self._offline = snapshot.offline
        self.handover.put(snapshot)

    def on_frame(self, frame: Frame) -> None:
        # a copy as 32-bit floats (25 of them): the frame's arrays are the detector's
        self.handover.put_frame(frame.forces.astype("<f4"), time.time())

    def take_commands(self) -> list[Command]:
        return self.server.take_commands(self.index)

    def source_ended(self, error: str) -> None:
        self.server.source_ended(self.index, error)

    def flush(self, timeout_s: float = 1.0) -> bool:
        """True once the offline snapshot is in the address space (a client reads
        BadOutOfService from then on)."""
        if not self._offline:
            return True
        return self.server.wait_applied(self.index, timeout_s)

    def health(self) -> SinkHealth:
        return SinkHealth()  # a server: no connection of its own to lose (its clients are counted)

    def counters(self) -> dict[str, int]:
        return self.server.counters(self.index)


class OpcuaKind(OutputKind[OpcuaOptions]):
    """The output kind "opcua": one server for the bridge, one :class:`OpcuaSink` per node."""

    name = "opcua"
    Options = OpcuaOptions
    cli_options = (
        CliOption("--opcua", "opcua", "Serve the grasp states over OPC UA at this endpoint (opc.tcp://HOST:PORT; "
                  "security off only on loopback, docs/opcua.md).", metavar="URL"),
        CliOption("--opcua-security", "opcua_security", "OPC UA: the endpoints offered, comma-separated (None, "
                  "Basic256Sha256_Sign, Basic256Sha256_SignAndEncrypt, Aes128_Sha256_RsaOaep_Sign, "
                  "Aes128_Sha256_RsaOaep_SignAndEncrypt); default: None on loopback, the secure ones with "
                  "--opcua-pki-dir.", metavar="LIST"),
        CliOption("--opcua-pki-dir", "opcua_pki_dir", "OPC UA: the folder of the server's certificate and of "
                  "the trusted and rejected client certificates (made on first start).", metavar="DIR"),
        CliOption("--opcua-users-file", "opcua_users_file", "OPC UA: the users and their roles (eskin-bus "
                  "opcua user add).", metavar="FILE"),
        CliOption("--opcua-users-env", "opcua_users_env", "OPC UA: the users, NAME:ROLE:PASSWORD lines of this "
                  "environment variable.", metavar="NAME"),
        CliOption("--opcua-allow-insecure", "opcua_allow_insecure", "OPC UA: allow SecurityPolicy None and "
                  "anonymous sessions off loopback (a warning at start).", type=bool, default=False),
        CliOption("--opcua-frame-interval", "opcua_frame_interval_s", "OPC UA: publish each node's taxel frame "
                  "(Taxels, a Float matrix) at most this often, seconds (default 0: off).", type=float,
                  metavar="S"),
    )
    #: ``--opcua-*`` option -> the ``[opcua]`` key it sets.
    _CLI_KEYS = {"opcua_pki_dir": "pki_dir", "opcua_users_file": "users_file", "opcua_users_env": "users_env",
                 "opcua_allow_insecure": "allow_insecure", "opcua_frame_interval_s": "frame_interval_s"}

    @classmethod
    def options_from_cli(cls, values: dict[str, Any]) -> OpcuaOptions | None:
        url = values.get("opcua")
        given = {key: values[dest] for dest, key in cls._CLI_KEYS.items() if values.get(dest) not in (None, False)}
        security = values.get("opcua_security")
        if url is None:
            flags = [o.flag for o in cls.cli_options[1:] if values.get(o.dest) not in (None, False)]
            if flags:
                raise ValueError(f"{'/'.join(flags)}: give --opcua URL too")
            return None
        if security is not None:
            given["security_policies"] = [p.strip() for p in security.split(",") if p.strip()]
        by_key = {cls._CLI_KEYS[o.dest]: o.flag for o in cls.cli_options if o.dest in cls._CLI_KEYS}
        by_key["security_policies"] = "--opcua-security"
        by_key["endpoint"] = "--opcua"
        try:
            options: OpcuaOptions = build(OpcuaOptions, {"endpoint": url, **given})
        except SchemaError as exc:  # the flag, not the key, in the one line
            key = exc.key.partition("[")[0]
            raise ValueError(f"{by_key.get(key, exc.key)}: {exc.message}") from None
        return options

    @classmethod
    def describe(cls, options: OpcuaOptions, node: NodeLike[Any]) -> str:
        frames = (f", Taxels every {options.frame_interval_s:g} s ({node.profile.layout.rows} x "
                  f"{node.profile.layout.cols})" if options.frame_interval_s else "")
        users = ("users from " + (options.users_file or f"${options.users_env}")
                 if options.users_file or options.users_env else "no users")
        anonymous = f"anonymous {options.anonymous_role}" if options.anonymous else "no anonymous"
        insecure = options.insecure()
        warn = f"; WARNING: open off loopback: {', '.join(insecure)} (allow_insecure)" if insecure else ""
        return (f"OPC UA {options.endpoint} Machines/{node.name} ({', '.join(options.policies())}; {users}; "
                f"{anonymous}{frames}){warn}")

    @classmethod
    def check(cls, options: OpcuaOptions, nodes: Sequence[NodeLike[Any]]) -> None:
        for n in nodes:
            if _NAME_FORBIDDEN & set(n.name) or n.name == "Machines":
                raise ValueError(f"node {n.name!r}: an OPC UA object's name here holds no '.' or '/'")
        from .pki import certificate_problem, default_application_uri
        from .users import load_users

        if options.users_file is not None:
            check_readable(options.users_file, "users_file")
        load_users(options.users_file, options.users_env)  # ValueError "users_file: ...": one line
        if options.pki_dir is not None and any(p != "None" for p in options.policies()):
            problem = certificate_problem(options.pki_dir, options.application_uri or default_application_uri())
            if problem is not None:
                raise ValueError(problem)

    @classmethod
    def probe(cls, options: OpcuaOptions, nodes: Sequence[NodeLike[Any]]) -> None:
        problem = listen_problem(options.host, options.port)
        if problem:
            raise ValueError(f"endpoint: {problem}")

    @classmethod
    def _open_nodes(cls, options: OpcuaOptions, nodes: Sequence[NodeLike[Any]], context: OpenContext) -> list[Sink]:
        need_asyncua()
        from .process import OpcuaProcess
        from .users import load_users

        try:
            cls.check(options, nodes)  # a users file or a certificate changed since --check
            users = load_users(options.users_file, options.users_env)
        except ValueError as exc:
            raise ProfileError(f"[opcua] {exc}") from None
        sinks: list[OpcuaSink] = []

        def on_event(name: str, level: str, node: str | None, **fields: Any) -> None:
            target = next((s for s in sinks if s.server.nodes[s.index].info.name == node), None)
            if target is None and sinks:
                target = sinks[0]
            if target is not None:
                target._event(name, level, **fields)
            else:
                held.append((name, level, fields))

        held: list[tuple[str, str, dict[str, Any]]] = []
        infos = [node_info(n, options.frame_interval_s, context.identity) for n in nodes]
        server = OpcuaProcess(options, infos, users, on_event,
                             refresh_s=min(n.profile.output.refresh_s for n in nodes))
        server.start()
        context.closers.append(server.stop)
        sinks.extend(OpcuaSink(server, i, n.name) for i, n in enumerate(nodes))
        for name, level, fields in held:  # the start's own events (listening, a certificate made)
            sinks[0]._event(name, level, **fields)
        return list(sinks)
