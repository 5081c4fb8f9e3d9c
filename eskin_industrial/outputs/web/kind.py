"""The web console as an output kind (``[web]`` in the bridge configuration, ``--web
HOST:PORT`` on the command line): one server for the bridge (:mod:`.server`), one
page per node, each node's :class:`.sink.WebSink`.

Where a setting can come from, the first that gives it wins: the command line, the
bridge configuration's ``[web]``, the defaults (:class:`.options.WebOptions`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from ...errors import MissingExtra, ProfileError
from ...netaddr import listen_problem
from ...preflight import check_readable
from ...schema import SchemaError, build
from ..base import CliOption, OutputKind, Sink
from .hub import NodeFeed, Truth
from .options import WebOptions
from .sink import WebSink

if TYPE_CHECKING:
    from ...profile import Profile
    from ...seam import NodeLike, OpenContext
    from .server import NodeView


def need_aiohttp(what: str = "the web output") -> None:
    """The one missing-extra error of this output (exit 4)."""
    try:
        import aiohttp  # noqa: F401
    except ImportError:
        raise MissingExtra.of(what, "aiohttp", "web") from None


def thresholds(profile: Profile) -> tuple[tuple[float | None, float | None], tuple[float | None, float | None]]:
    """The deciding method's slip and varying-force thresholds on its two scores (the
    paper's: ``slip_r_*``, ``variable_r_*`` with ``evidence = "method"``; cof-track's
    scores are normalised: 1)."""
    d = profile.detector
    if d.method.startswith("paper"):
        variable = ((d.variable_r_coe, d.variable_r_dw) if d.varying_force.evidence == "method" else (None, None))
        return (d.slip_r_coe, d.slip_r_dw), variable
    if d.method == "cof-track":
        return (1.0, 1.0), (None, None)
    return (None, None), (None, None)


def node_view(node: NodeLike[Any]) -> NodeView:
    from ...methods import get_method
    from .server import NodeView

    p = node.profile
    x, y = p.layout.coordinates_mm()
    slip, variable = thresholds(p)
    scores = get_method(p.detector.method).scores
    names = tuple(getattr(p.layout, "row_names", None) or ())
    return NodeView(node.name, p.layout.rows, p.layout.cols, [float(v) for v in x], [float(v) for v in y],
                    [str(n) for n in names], p.detector.method, (scores[0].name, scores[1].name), slip, variable,
                    float(node.rate_hz))


def scene_truth(node: NodeLike[Any]) -> Truth | None:
    """The onsets a scene node's own scene gives (its slides and force changes), for
    the detection delay; None for any other source."""
    scene = getattr(node.options, "scene", None)
    if not isinstance(scene, str):
        return None
    from ...scenes import load_scene

    try:
        spec = load_scene(scene)
    except Exception:  # noqa: BLE001 - no truth is no error: the delay is left out
        return None
    onsets = []
    for e in spec.events:
        if e.kind in ("press", "release"):
            continue
        onsets.append((float(e.t_s), "slip" if e.kind in ("slide", "rotate") else "variable_force"))
    period = float(spec.scene.duration_s) if getattr(node.options, "loop", False) else None
    return Truth(onsets, period)


class WebKind(OutputKind[WebOptions]):
    """The output kind "web": one console server for the bridge, one :class:`WebSink` per node."""

    name = "web"
    Options = WebOptions
    cli_options = (
        CliOption("--web", "web", "Serve the commissioning console at HOST:PORT (open only on loopback; "
                  "docs/web.md).", metavar="HOST:PORT"),
        CliOption("--web-users-file", "web_users_file", "Web console: the users and their roles (the file "
                  "'eskin-bus opcua user add' writes); without it the console is read-only.", metavar="FILE"),
        CliOption("--web-tls-cert", "web_tls_cert", "Web console: the server's certificate (PEM): HTTPS.",
                  metavar="FILE"),
        CliOption("--web-tls-key", "web_tls_key", "Web console: the certificate's private key (PEM).",
                  metavar="FILE"),
    )
    _CLI_KEYS = {"web_users_file": "users_file", "web_tls_cert": "tls_cert", "web_tls_key": "tls_key"}

    @classmethod
    def options_from_cli(cls, values: dict[str, Any]) -> WebOptions | None:
        bind = values.get("web")
        given = {key: values[dest] for dest, key in cls._CLI_KEYS.items() if values.get(dest) is not None}
        if bind is None:
            if given:
                flags = [o.flag for o in cls.cli_options[1:] if values.get(o.dest) is not None]
                raise ValueError(f"{'/'.join(flags)}: give --web HOST:PORT too")
            return None
        by_key = {key: o.flag for o in cls.cli_options for dest, key in cls._CLI_KEYS.items() if o.dest == dest}
        by_key["bind"] = "--web"
        try:
            options: WebOptions = build(WebOptions, {"bind": bind, **given})
        except SchemaError as exc:
            key = exc.key.partition("[")[0]
            raise ValueError(f"{by_key.get(key, exc.key)}: {exc.message}") from None
        return options

    @classmethod
    def describe(cls, options: WebOptions, node: NodeLike[Any]) -> str:
        users = f"users from {options.users_file}" if options.users_file else "no users: read-only"
        return (f"web console {options.url} ({'TLS' if options.tls else 'no TLS'}; {users}; capture "
                f"-{options.capture_pre_s:g}/+{options.capture_post_s:g} s)")

    @classmethod
    def check(cls, options: WebOptions, nodes: Sequence[NodeLike[Any]]) -> None:
        from .users import load_users

        for key in ("users_file", "tls_cert", "tls_key"):
            path = getattr(options, key)
            if path is not None:
                check_readable(path, key)
        if options.users_file is not None:
            load_users(options.users_file)  # ValueError "users_file: ...": one line
        if options.tls:
            import ssl

            context = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
            try:
                assert options.tls_cert is not None
                context.load_cert_chain(options.tls_cert, options.tls_key)
            except (ssl.SSLError, OSError) as exc:
                raise ValueError(f"tls_cert: {options.tls_cert}: cannot load with its key: {exc}") from None

    @classmethod
    def probe(cls, options: WebOptions, nodes: Sequence[NodeLike[Any]]) -> None:
        problem = listen_problem(options.host, options.port)
        if problem:
            raise ValueError(f"bind: {problem}")

    @classmethod
    def _open_nodes(cls, options: WebOptions, nodes: Sequence[NodeLike[Any]], context: OpenContext) -> list[Sink]:
        need_aiohttp()
        from .server import WebServer, Wiring
        from .users import load_users

        try:
            cls.check(options, nodes)  # a users file or a certificate changed since --check
            users = load_users(options.users_file) if options.users_file else ()
        except ValueError as exc:
            raise ProfileError(f"[web] {exc}") from None
        # what the console was handed after the first open (register blocks, truths,
        # sessions): a restart's fresh instance is given it again
        wiring = context.kept.setdefault(cls.name, Wiring())
        feeds = [NodeFeed(i, float(n.rate_hz), options.capture_pre_s, options.capture_post_s,
                          options.frame_interval_s, truth=wiring.truths.get(i) or scene_truth(n))
                 for i, n in enumerate(nodes)]
        server = WebServer(options, [node_view(n) for n in nodes], feeds, users, wiring)
        sinks: list[WebSink] = []
        held: list[tuple[str, str, dict[str, Any]]] = []

        def on_event(name: str, level: str, **fields: Any) -> None:
            if sinks:
                sinks[0]._event(name, level, **fields)
            else:
                held.append((name, level, fields))

        server.on_event = on_event
        server.start()
        context.closers.append(server.stop)
        sinks.extend(WebSink(server, i, n.name) for i, n in enumerate(nodes))
        for name, level, fields in held:
            sinks[0]._event(name, level, **fields)
        return list(sinks)
