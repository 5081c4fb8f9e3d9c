"""The OPC UA server: one per bridge, on a thread and an asyncio event loop of its
own, so that the node loops never wait for it, in the process :mod:`.process` starts
for it (so that its heap is not the bridge's).  This module is its life: start,
the turns of its loop, stop, and its counters.

The loops' side is :class:`.handover.Handover` (a snapshot or a frame put, a command
taken); everything else runs on the server's loop, each job in a module of its own:
asyncua (sessions, subscriptions), :mod:`.logins` (security, users, certificates),
:mod:`.values` (the snapshots turned into values with their status and source
timestamp), :mod:`.calls` (the methods, judged under
:func:`~eskin_industrial.node.refusal`, queued for the loop), :mod:`.alarm_events`
(the slip alarm's events), :mod:`.itemcheck` and :mod:`.callcheck` (the clients'
monitored items and Call requests checked before asyncua takes them),
:mod:`.wire` (the first message of a connection checked, a refusal told with
an Error message), :mod:`.stacklog` (what asyncua itself logs, counted and reported as events of the
output, at most one line a second each: :mod:`.report`).
"""

from __future__ import annotations

import asyncio
import collections
import datetime
import threading
from collections.abc import Callable, Sequence
from typing import Any

from asyncua import Server, ua

from ... import __version__
from ...errors import ProfileError, TransportError
from ...netaddr import listen_error
from ...node import Command, NodeSnapshot
from . import callcheck, itemcheck, model
from .alarm_events import AlarmEvents
from .build import NodeInfo, TypeIds, build_machines, build_node, build_types
from .calls import COMMANDS_MAX, Calls
from .companions import load_companions
from .handover import Handover, Waker
from .logins import LoginSecurity
from .nodestate import NodeState
from .options import OpcuaOptions
from .pki import default_application_uri
from .report import Report
from .stacklog import StackLog
from .uaconv import node_id, status_code
from .users import Directory, UserEntry
from .values import Values
from .wire import GuardedServer, WireLimits

__all__ = ["COMMANDS_MAX", "START_TIMEOUT_S", "OpcuaServer"]

#: The longest a start may take (a new certificate, the standard address space).
START_TIMEOUT_S = 60.0
_UTC = datetime.UTC


#: The profile claimed in ServerCapabilities (Part 7; claimed, not certified: no
#: compliance test tool has been run against it).
SERVER_PROFILE = "http://opcfoundation.org/UA-Profile/Server/MicroEmbeddedDevice2017"


async def _capabilities(server: Server) -> None:
    """ServerCapabilities' values asyncua leaves null (Part 5, 6.3.2)."""
    caps = ua.ObjectIds
    for ident, value, vtype in (
            (caps.Server_ServerCapabilities_ServerProfileArray, [SERVER_PROFILE], ua.VariantType.String),
            (caps.Server_ServerCapabilities_LocaleIdArray, ["en"], ua.VariantType.String),
            # a change is written at once and a refresh each refresh_s: 0, exception-based
            (caps.Server_ServerCapabilities_MinSupportedSampleRate, 0.0, ua.VariantType.Double),
            # asyncua answers each Browse whole, with no continuation point: none is held, 0 (no limit)
            (caps.Server_ServerCapabilities_MaxBrowseContinuationPoints, 0, ua.VariantType.UInt16),
            (caps.Server_ServerCapabilities_MaxQueryContinuationPoints, 0, ua.VariantType.UInt16),
            (caps.Server_ServerCapabilities_MaxHistoryContinuationPoints, 0, ua.VariantType.UInt16)):
        await server.write_attribute_value(node_id(ident), ua.DataValue(ua.Variant(value, vtype)))


class OpcuaServer:
    """One server, every node's object; started and stopped from the bridge's thread."""

    def __init__(self, options: OpcuaOptions, infos: Sequence[NodeInfo], users: tuple[UserEntry, ...] = (),
                 on_event: Callable[..., None] | None = None, refresh_s: float = 0.05) -> None:
        self.options = options
        #: How often the server takes the nodes' periodic refreshes (the shortest
        #: ``[output] refresh_s`` of the nodes): a change is taken at once.
        self.refresh_s = refresh_s
        self.nodes = [NodeState(i, info) for i, info in enumerate(infos)]
        self.users = Directory(users)
        self.report = Report([info.name for info in infos], on_event)
        self.counts = self.report.counts
        self.node_counts = self.report.node_counts
        self.waker = Waker()
        self.handovers = [Handover(self.waker) for _ in infos]
        self.calls = Calls(options, len(infos), self.report)
        #: The newest snapshot each node's loop published (a command is judged on it).
        self.published: list[NodeSnapshot | None] = self.calls.published
        self.commands: list[collections.deque[Command]] = self.calls.commands
        self.security = LoginSecurity(options, self.users, self.report)
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._wake: asyncio.Event | None = None
        self._ready = threading.Event()
        self._start_error: BaseException | None = None
        self._stopping = False
        self.server: Server | None = None
        self.types: TypeIds | None = None
        self.values: Values | None = None
        self.alarms: AlarmEvents | None = None
        self._log_handler: StackLog | None = None
        self.certificate_made = ""
        self.url = options.endpoint

    # -- life (the bridge's thread) ---------------------------------------------------
    def start(self) -> OpcuaServer:
        """Listen; returns once clients can connect.  A port in use, a certificate that
        cannot be made or read: one line (:class:`~eskin_industrial.errors.ProfileError`
        or :class:`~eskin_industrial.errors.TransportError`)."""
        self._thread = threading.Thread(target=self._run, name="opcua-server", daemon=True)
        self._thread.start()
        if not self._ready.wait(START_TIMEOUT_S):
            self.stop()
            raise TransportError(f"[opcua] the server did not start within {START_TIMEOUT_S:g} s")
        if self._start_error is not None:
            self._thread.join(timeout=10)
            raise self._start_error
        return self

    def stop(self) -> None:
        """Serve the last values for ``offline_linger_s`` (they say BadOutOfService once
        the loops' offline snapshots are in), then close every session and the port.
        Safe to call twice."""
        thread = self._thread
        if thread is None:
            return
        self._thread = None
        self._stopping = True
        loop, wake = self._loop, self._wake
        if loop is not None and wake is not None:
            try:
                loop.call_soon_threadsafe(wake.set)
            except RuntimeError:
                pass  # already closed
        thread.join(timeout=10 + self.options.offline_linger_s)

    def wait_applied(self, index: int, timeout_s: float) -> bool:
        """The node's offline snapshot is in the address space (``flush``)."""
        return self.nodes[index].offline_applied.wait(timeout_s)

    # -- the loops' side ------------------------------------------------------------------
    def take_commands(self, index: int) -> list[Command]:
        return self.calls.take(index)

    def source_ended(self, index: int, error: str) -> None:
        """The node's source is gone (the loops' thread): its values say so at once."""
        self.nodes[index].source_end = "failed" if error else "ended"
        snapshot = self.published[index]
        if snapshot is not None:
            self.handovers[index].put(snapshot._replace(urgent=True))

    # -- the server's thread ---------------------------------------------------------
    def _run(self) -> None:
        try:
            # asyncio.run: what is still pending at the end (a vanished client's session
            # timer) is cancelled and awaited, the loop's executor shut down
            asyncio.run(self._main())
        finally:
            self._ready.set()  # (a failure before ready: start() is not left waiting)

    async def _main(self) -> None:
        self._wake = asyncio.Event()
        wake = self._wake
        loop = asyncio.get_running_loop()
        self._loop = loop

        def wake_up() -> None:
            loop.call_soon_threadsafe(wake.set)

        self.waker.attach(wake_up)
        try:
            server = await self._open()
        except BaseException as exc:  # noqa: BLE001 - handed to start(), on the bridge's thread
            self._start_error = exc
            self._detach_log()
            self._ready.set()
            return
        self._ready.set()
        try:
            tick = self.refresh_s
            while not self._stopping:
                try:  # a change at once; the periodic refreshes at every tick
                    await asyncio.wait_for(wake.wait(), tick)
                except TimeoutError:
                    pass
                wake.clear()
                await self._turn()
            await self._turn()  # the offline snapshots
            if self.options.offline_linger_s > 0:
                await asyncio.sleep(self.options.offline_linger_s)
        finally:
            try:
                await server.stop()
            finally:
                self._detach_log()

    async def _open(self) -> Server:
        o = self.options
        self._attach_log()
        uri = o.application_uri or default_application_uri()
        self.certificate_made = self.security.certificate(uri)
        server = GuardedServer(user_manager=self.security.user_manager(), on_refused=self._on_wire_refused,
                               wire=WireLimits(o.max_pending, o.hello_timeout_s))
        server.application_type = ua.ApplicationType.Server  # (asyncua's default: ClientAndServer)
        self.server = server
        iserver = server.iserver
        iserver.bind_condition_methods = True  # ConditionRefresh
        iserver.max_connections = o.max_sessions
        iserver.max_pending_activation_seconds = o.activation_timeout_s
        iserver.max_session_timeout_ms = o.session_timeout_s * 1000.0
        iserver.min_session_timeout_ms = min(iserver.min_session_timeout_ms, o.session_timeout_s * 1000.0)
        iserver.max_subscriptions = o.max_subscriptions
        await server.init()
        itemcheck.guard(iserver, self._on_filter_refused)
        callcheck.guard(iserver, self._on_call_refused)
        server.set_endpoint(o.endpoint)
        server.set_server_name(o.application_name)
        await server.set_application_uri(uri)
        server.product_uri = "urn:eskin-industrial:eskin-bus"
        server.manufacturer_name = "eskin-industrial"
        await server.set_build_info(server.product_uri, server.manufacturer_name, "eskin-bus", __version__,
                                    __version__, datetime.datetime.now(_UTC))
        await self.security.apply(server)
        await _capabilities(server)
        values = self.values = Values(server, o, self.report)
        alarms = self.alarms = AlarmEvents(server, o, self.nodes, self.report)
        # ours first, so that it keeps index 2 (a SCADA's tags), then the companion
        # specifications our model is built on
        idx = await server.register_namespace(model.NAMESPACE_URI)
        await load_companions(server)
        self.types = await build_types(server, idx, self.calls.method)
        values.machinery_ns = self.types.machinery
        machines = await build_machines(server, self.types)
        for i, n in enumerate(self.nodes):
            n.handles = await build_node(server, idx, self.types, machines, n.info, self.calls.method)
            self.calls.by_object[n.handles.obj] = i
            await alarms.attach(n, self.types.alarm)
            await values.write_initial(n)
        # the condition's methods, as the type declares them (a client may call those on
        # the condition) and as the condition's own components
        condition_methods: dict[str, tuple[int, Callable[..., Any]]] = {
            "Acknowledge": (ua.ObjectIds.AcknowledgeableConditionType_Acknowledge, alarms.acknowledge),
            "Disable": (ua.ObjectIds.ConditionType_Disable, alarms.disable),
            "Enable": (ua.ObjectIds.ConditionType_Enable, alarms.enable),
            "AddComment": (ua.ObjectIds.ConditionType_AddComment, alarms.add_comment)}
        for name, (declared, callback) in condition_methods.items():
            server.link_method(server.get_node(declared), callback)
            for n in self.nodes:
                assert n.handles is not None
                if name in n.handles.alarm_methods:
                    server.link_method(server.get_node(n.handles.alarm_methods[name]), callback)
        try:
            await server.start()
        except OSError as exc:
            raise ProfileError(f"[opcua] endpoint: {listen_error(o.host, o.port, exc)}") from None
        self.url = o.endpoint
        fields: dict[str, Any] = dict(endpoint=o.endpoint, policies=",".join(o.policies()),
                                      anonymous=self.security.anonymous or "none", users=len(self.users.users))
        if self.certificate_made:
            self.report.event("opcua_certificate_made", "info", certificate=self.certificate_made, uri=uri)
        self.report.event("opcua_listening", "info", **fields)
        insecure = o.insecure()
        if insecure:
            self.report.event("opcua_insecure", "warning", endpoint=o.endpoint, open=", ".join(insecure))
        return server

    async def _turn(self) -> None:
        """Everything the loops handed over since the last turn."""
        values, alarms = self.values, self.alarms
        assert values is not None and alarms is not None
        self.waker.arm()
        for i, h in enumerate(self.handovers):
            n = self.nodes[i]
            for s in h.take():
                transition = await values.apply(n, s)
                if transition is not None:
                    await alarms.fire(n, transition, s)
                if s.offline:
                    n.offline_applied.set()
            frame = h.take_frame()
            if frame is not None and n.handles is not None and n.handles.frame is not None:
                await values.write_frame(n, *frame)

    # -- what asyncua tells -------------------------------------------------------------
    def _on_filter_refused(self, code: int) -> None:
        self.counts["filters_refused"] += 1
        self.report.log_once("opcua_filter_refused", "warning", status=status_code(code).name)

    def _on_wire_refused(self, counter: str, event: str, detail: str) -> None:
        """A connection answered with an Error message and closed (:mod:`.wire`)."""
        self.counts[counter] += 1
        self.report.log_once(event, "warning", detail=detail[:200])

    def _on_call_refused(self, code: int) -> None:
        self.counts["calls_refused"] += 1
        self.report.log_once("opcua_call_refused", "warning", status=status_code(code).name)

    def _attach_log(self) -> None:
        self._log_handler = StackLog(self.report)
        self._log_handler.attach()

    def _detach_log(self) -> None:
        if self._log_handler is not None:
            self._log_handler.detach()
            self._log_handler = None

    # -- health ---------------------------------------------------------------------
    def connections(self) -> tuple[int, int]:
        """(connections, activated sessions) now."""
        server = self.server
        bserver = None if server is None else server.bserver
        if bserver is None:
            return 0, 0
        clients = list(bserver.clients)
        sessions = sum(1 for c in clients if c.processor is not None and c.processor.session is not None
                       and c.processor.session.is_activated())
        return len(clients), sessions

    def counters(self, index: int) -> dict[str, int]:
        connections, sessions = self.connections()
        c, own = self.counts, self.node_counts[index]
        h = self.handovers[index]
        out = {"opcua_connections": connections, "opcua_sessions": sessions}
        for key in ("logins", "logins_refused", "denied", "certificates_rejected", "connections_refused",
                    "activation_timeouts", "sessions_timed_out", "malformed", "service_faults", "stack_warnings",
                    "stack_errors", "writes", "filters_refused", "calls_refused", "hellos_refused", "hello_timeouts"):
            out[f"opcua_{key}"] = c[key]
        for key in ("method_calls", "commands", "commands_refused", "commands_busy", "alarms", "alarm_acks",
                    "alarm_acks_refused", "event_errors"):
            out[f"opcua_{key}"] = own[key]
        out["opcua_handover_dropped"] = h.dropped
        if self.nodes[index].info.frame_shape is not None:
            out["opcua_frames"] = own["frames"]
            out["opcua_frames_replaced"] = h.frames_replaced
        return out
