"""The OPC UA server: one per bridge, on a thread and an asyncio event loop of its
own, so that the node loops never wait for it.

The loops' side is :class:`.handover.Handover` (a snapshot or a frame put, a command
taken); everything else runs on the server's loop: asyncua (sessions, subscriptions,
security), the snapshots turned into values with their status and source timestamp
(only what changed is written), the methods (judged under
:func:`~eskin_industrial.node.refusal`, queued for the loop), the slip alarm's
events.  What asyncua itself logs (a connection refused at the cap, a client that
never activated its session, a session timed out, a malformed message) is counted
and reported as events of the output, at most one line a second each.
"""

from __future__ import annotations

import asyncio
import collections
import datetime
import logging
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

from asyncua import Server, ua
from asyncua.common.events import get_event_obj_from_type_node

from ... import __version__
from ...errors import ProfileError, TransportError
from ...netaddr import listen_error
from ...node import Command, NodeSnapshot, refusal
from . import model, status
from .access import Logins, Permissions
from .alarm import AlarmState
from .build import NodeHandles, NodeInfo, TypeIds, build_machines, build_node, build_types, variant_type
from .handover import Handover, Waker
from .options import OpcuaOptions, Role
from .pki import TrustList, certificate_problem, default_application_uri, make_certificate, own_paths
from .uaconv import data_value, node_id, status_code
from .users import Directory, UserEntry

#: Commands held for a node's loop at most; past it a call is answered BadTooManyOperations.
COMMANDS_MAX = 64
#: The longest a start may take (a new certificate, the standard address space).
START_TIMEOUT_S = 60.0
_POLICY_TYPES = {
    "None": ua.SecurityPolicyType.NoSecurity,
    "Basic256Sha256_Sign": ua.SecurityPolicyType.Basic256Sha256_Sign,
    "Basic256Sha256_SignAndEncrypt": ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt,
    "Aes128_Sha256_RsaOaep_Sign": ua.SecurityPolicyType.Aes128Sha256RsaOaep_Sign,
    "Aes128_Sha256_RsaOaep_SignAndEncrypt": ua.SecurityPolicyType.Aes128Sha256RsaOaep_SignAndEncrypt,
}
_METHOD_COMMAND = {"Tare": "tare", "AcknowledgeSlip": "ack"}
_VALUE = ua.AttributeIds.Value
_OFFLINE = model.INDEX["Health/Offline"]
_GROUP_INDEX = {"decision": 0, "measurement": 1, "fact": 2}
_GROUPS = tuple(_GROUP_INDEX[g] for g in model.GROUPS)
_VTYPES = tuple(variant_type(v.datatype) for v in model.VARIABLES)
_UTC = datetime.UTC
_VARIANT_NONE = ua.Variant(None)
_REQUESTS = {ua.ObjectIds.CallRequest_Encoding_DefaultBinary: "Call",
             ua.ObjectIds.WriteRequest_Encoding_DefaultBinary: "Write"}
#: asyncua's log lines that are news, by what they start with: (counter, event).
_STACK_LINES = (
    ("Refusing connection", "connections_refused", "opcua_connection_refused"),
    ("Closing idle connection", "activation_timeouts", "opcua_activation_timeout"),
    ("Session ", "sessions_timed_out", "opcua_session_timeout"),
    ("Got malformed header", "malformed", "opcua_malformed"),
    ("Exception raised while processing message", "malformed", "opcua_malformed"),  # a message that does not decode
    ("sending service fault", "service_faults", ""),
)


class _NodeState:
    """What the server keeps of one node."""

    def __init__(self, index: int, info: NodeInfo) -> None:
        self.index = index
        self.info = info
        self.handles: NodeHandles | None = None
        self.last: list[tuple[Any, int]] = [(None, -1)] * len(model.VARIABLES)  #: (value, status) written
        self.machinery = ""
        self.snapshot: NodeSnapshot | None = None  #: the newest applied
        self.source_end: status.SourceEnd = ""
        self.alarm = AlarmState()
        self.event: Any = None  #: the alarm's event object (asyncua), its fields the condition's state
        self.applied = 0
        self.offline_applied = threading.Event()


class OpcuaServer:
    """One server, every node's object; started and stopped from the bridge's thread."""

    def __init__(self, options: OpcuaOptions, infos: Sequence[NodeInfo], users: tuple[UserEntry, ...] = (),
                 on_event: Callable[..., None] | None = None, refresh_s: float = 0.05) -> None:
        self.options = options
        #: How often the server takes the nodes' periodic refreshes (the shortest
        #: ``[output] refresh_s`` of the nodes): a change is taken at once.
        self.refresh_s = refresh_s
        self.nodes = [_NodeState(i, info) for i, info in enumerate(infos)]
        self.users = Directory(users)
        self.on_event: Callable[..., None] = on_event or (lambda *args, **fields: None)
        self.waker = Waker()
        self.handovers = [Handover(self.waker) for _ in infos]
        #: The newest snapshot each node's loop published (a command is judged on it).
        self.published: list[NodeSnapshot | None] = [None] * len(infos)
        self.commands: list[collections.deque[Command]] = [collections.deque() for _ in infos]
        self.counts: collections.Counter[str] = collections.Counter()
        self.node_counts: list[collections.Counter[str]] = [collections.Counter() for _ in infos]
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._wake: asyncio.Event | None = None
        self._ready = threading.Event()
        self._start_error: BaseException | None = None
        self._stopping = False
        self.server: Server | None = None
        self.types: TypeIds | None = None
        self._by_object: dict[ua.NodeId, int] = {}
        self._by_condition: dict[ua.NodeId, int] = {}
        self._logged: dict[str, tuple[float, int]] = {}
        self._log_handler: _StackLog | None = None
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
        q = self.commands[index]
        out = []
        while q:
            out.append(q.popleft())
        return out

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
        cert = key = None
        if any(p != "None" for p in o.policies()):
            assert o.pki_dir is not None  # OpcuaOptions requires it
            problem = certificate_problem(o.pki_dir, uri)
            if problem is not None:
                raise ProfileError(f"[opcua] {problem}")
            cert, key = own_paths(o.pki_dir)
            if not cert.exists():
                make_certificate(o.pki_dir, uri, o.application_name, [o.host])
                self.certificate_made = str(cert)
        anonymous: Role | None = o.anonymous_role if o.anonymous and o.anonymous_role != "none" else None
        server = Server(user_manager=Logins(self.users, anonymous, self._on_login))
        self.server = server
        iserver = server.iserver
        iserver.bind_condition_methods = True  # ConditionRefresh
        iserver.max_connections = o.max_sessions
        iserver.max_pending_activation_seconds = o.activation_timeout_s
        iserver.max_session_timeout_ms = o.session_timeout_s * 1000.0
        iserver.min_session_timeout_ms = min(iserver.min_session_timeout_ms, o.session_timeout_s * 1000.0)
        iserver.max_subscriptions = o.max_subscriptions
        await server.init()
        server.set_endpoint(o.endpoint)
        server.set_server_name(o.application_name)
        await server.set_application_uri(uri)
        server.product_uri = "urn:eskin-industrial:eskin-bus"
        server.manufacturer_name = "eskin-industrial"
        await server.set_build_info(server.product_uri, server.manufacturer_name, "eskin-bus", __version__,
                                    __version__, datetime.datetime.now(_UTC))
        tokens: list[type] = [ua.UserNameIdentityToken] if self.users.users else []
        if anonymous is not None:
            tokens.insert(0, ua.AnonymousIdentityToken)
        server.set_identity_tokens(tokens)
        # (asyncua types the ruleset as its SimpleRoleRuleset; any PermissionRuleset is called the same)
        server.set_security_policy([_POLICY_TYPES[p] for p in o.policies()],
                                   permission_ruleset=Permissions(self._on_denied))  # type: ignore[arg-type]
        if cert is not None and key is not None:
            await server.load_certificate(str(cert))
            await server.load_private_key(str(key))
            assert o.pki_dir is not None
            server.set_certificate_validator(TrustList(o.pki_dir, self._on_rejected))
        idx = await server.register_namespace(model.NAMESPACE_URI)
        self.types = await build_types(server, idx, self._method)
        machines = await build_machines(server, idx)
        for i, n in enumerate(self.nodes):
            n.handles = await build_node(server, idx, self.types, machines, n.info, self._method)
            self._by_object[n.handles.obj] = i
            self._by_condition[n.handles.alarm] = i
            n.event = await self._alarm_event(n)
            await self._condition_variables(n, datetime.datetime.now(_UTC))
            await self._write_initial(n)
        ack = server.get_node(ua.ObjectIds.AcknowledgeableConditionType_Acknowledge)
        server.link_method(ack, self._acknowledge)
        for n in self.nodes:
            assert n.handles is not None
            if "Acknowledge" in n.handles.alarm_methods:
                server.link_method(server.get_node(n.handles.alarm_methods["Acknowledge"]), self._acknowledge)
        try:
            await server.start()
        except OSError as exc:
            raise ProfileError(f"[opcua] endpoint: {listen_error(o.host, o.port, exc)}") from None
        self.url = o.endpoint
        fields: dict[str, Any] = dict(endpoint=o.endpoint, policies=",".join(o.policies()),
                                      anonymous=anonymous or "none", users=len(self.users.users))
        if self.certificate_made:
            self._event("opcua_certificate_made", "info", certificate=self.certificate_made, uri=uri)
        self._event("opcua_listening", "info", **fields)
        insecure = o.insecure()
        if insecure:
            self._event("opcua_insecure", "warning", endpoint=o.endpoint, open=", ".join(insecure))
        return server

    # -- values ---------------------------------------------------------------------
    async def _write_initial(self, n: _NodeState) -> None:
        """Before the first snapshot: every variable BadWaitingForInitialData."""
        assert self.server is not None and n.handles is not None
        now = datetime.datetime.now(_UTC)
        dv = data_value(ua.Variant(None), status.BAD_WAITING_FOR_INITIAL_DATA, now, now)
        for j, nodeid in enumerate(n.handles.variables):
            await self.server.write_attribute_value(nodeid, dv)
            n.last[j] = (None, status.BAD_WAITING_FOR_INITIAL_DATA)

    async def _turn(self) -> None:
        """Everything the loops handed over since the last turn."""
        self.waker.arm()
        for i, h in enumerate(self.handovers):
            n = self.nodes[i]
            for s in h.take():
                await self._apply(n, s)
            frame = h.take_frame()
            if frame is not None and n.handles is not None and n.handles.frame is not None:
                await self._write_frame(n, *frame)

    async def _apply(self, n: _NodeState, s: NodeSnapshot) -> None:
        server, handles = self.server, n.handles
        assert server is not None and handles is not None
        n.snapshot = s
        n.applied += 1
        q = status.quality(s, n.source_end, self.options.bad_after_s)
        source_ts = datetime.datetime.fromtimestamp(s.wall_time_s, _UTC)
        now = datetime.datetime.now(_UTC)
        last = n.last
        writes = 0
        aspace = server.iserver.aspace  # (what Server.write_attribute_value calls, two calls down)
        for j, value in enumerate(model.values(s)):
            code = status.GOOD if j == _OFFLINE else q[_GROUPS[j]]  # Offline is known even when stopped
            if status.is_bad(code):
                value = None
            elif value is None:
                if status.is_uncertain(code) and last[j][0] is not None:
                    value = last[j][0]  # the last usable value, with its new status
                else:
                    code = status.BAD_WAITING_FOR_INITIAL_DATA
            if last[j] == (value, code):
                continue
            last[j] = (value, code)
            variant = _VARIANT_NONE if value is None else ua.Variant(value, _VTYPES[j])
            await aspace.write_attribute_value(handles.variables[j], _VALUE, data_value(variant, code,
                                                                                  source_ts, now))
            writes += 1
        self.counts["writes"] += writes
        machinery = status.machinery_state(s, n.source_end)
        if machinery != n.machinery:
            n.machinery = machinery
            await server.write_attribute_value(handles.machinery_state, data_value(
                ua.Variant(ua.LocalizedText(machinery), ua.VariantType.LocalizedText), status.GOOD, source_ts, now))
        transition = n.alarm.observe(s)
        if transition is not None:
            await self._alarm(n, transition, s)
        if s.offline:
            n.offline_applied.set()

    async def _write_frame(self, n: _NodeState, forces: Any, wall_time_s: float) -> None:
        assert self.server is not None and n.handles is not None and n.handles.frame is not None
        s = n.snapshot
        code = status.GOOD if s is None else status.quality(s, n.source_end, self.options.bad_after_s).measurement
        shape = list(n.info.frame_shape or (0, 0))
        variant = (ua.Variant(None) if status.is_bad(code) else
                   ua.Variant(forces.tolist(), ua.VariantType.Float, Dimensions=[ua.Int32(d) for d in shape]))
        now = datetime.datetime.now(_UTC)
        await self.server.write_attribute_value(n.handles.frame, data_value(
            variant, code, datetime.datetime.fromtimestamp(wall_time_s, _UTC), now))
        self.node_counts[n.index]["frames"] += 1

    def source_ended(self, index: int, error: str) -> None:
        """The node's source is gone (the loops' thread): its values say so at once."""
        self.nodes[index].source_end = "failed" if error else "ended"
        snapshot = self.published[index]
        if snapshot is not None:
            self.handovers[index].put(snapshot._replace(urgent=True))

    # -- the slip alarm ---------------------------------------------------------------
    async def _alarm_event(self, n: _NodeState) -> Any:
        assert self.server is not None and self.types is not None and n.handles is not None
        ev: Any = await get_event_obj_from_type_node(self.server.get_node(self.types.alarm))
        ev.add_property("NodeId", n.handles.alarm, ua.VariantType.NodeId)  # the ConditionId
        for name, dtype, _ in model.ALARM_FIELDS:
            ev.add_property(name, 0.0 if dtype == "Double" else "" if dtype == "String" else 0,
                            {"Double": ua.VariantType.Double, "String": ua.VariantType.String,
                             "UInt32": ua.VariantType.UInt32}[dtype])
        for state in ("ActiveState", "AckedState", "EnabledState"):
            ev.add_property(f"{state}/TransitionTime", None, ua.VariantType.DateTime)
        ev.SourceNode = n.handles.obj
        ev.SourceName = n.info.name
        ev.ConditionName = "SlipAlarm"
        ev.ConditionClassId = node_id(ua.ObjectIds.BaseConditionClassType)
        ev.ConditionClassName = ua.LocalizedText("BaseConditionClassType")
        ev.BranchId = ua.NodeId()
        ev.EnabledState = ua.LocalizedText("Enabled")
        setattr(ev, "EnabledState/Id", True)
        ev.Quality = status_code(0)
        ev.Severity = self.options.alarm_severity
        ev.LastSeverity = self.options.alarm_severity
        ev.Retain = False
        ev.ActiveState = ua.LocalizedText("Inactive")
        setattr(ev, "ActiveState/Id", False)
        ev.AckedState = ua.LocalizedText("Acknowledged")
        setattr(ev, "AckedState/Id", True)
        ev.ConfirmedState = None
        ev.SuppressedOrShelved = False
        ev.Comment = ua.LocalizedText("")
        ev.ClientUserId = ""
        ev.Message = ua.LocalizedText("")
        return ev

    async def _alarm(self, n: _NodeState, transition: str, s: NodeSnapshot | None, comment: str = "") -> None:
        """The condition's new state as an event (on the node's object, then on the Server
        object: where a SCADA subscribes), and on the condition's own variables."""
        assert self.server is not None and n.handles is not None
        ev, a = n.event, n.alarm
        now = datetime.datetime.now(_UTC)
        ev.EventId = a.event_id
        ev.Retain = a.retain
        ev.ActiveState = ua.LocalizedText("Active" if a.active else "Inactive")
        setattr(ev, "ActiveState/Id", a.active)
        ev.AckedState = ua.LocalizedText("Acknowledged" if a.acked else "Unacknowledged")
        setattr(ev, "AckedState/Id", a.acked)
        ev.ReceiveTime = now
        if transition == "acknowledged":
            ev.Time = now
            setattr(ev, "AckedState/TransitionTime", now)
            ev.Comment = ua.LocalizedText(comment)
            ev.Message = ua.LocalizedText(f"slip on {n.info.name} acknowledged")
        else:
            assert s is not None
            ev.Time = datetime.datetime.fromtimestamp(s.wall_time_s, _UTC)
            setattr(ev, "ActiveState/TransitionTime", ev.Time)
        if transition == "raised":
            assert s is not None
            delay = max(time.perf_counter() - s.t_event, 0.0)
            names = s.score_names
            ev.ScoreA, ev.ScoreB = float(s.score_a or 0.0), float(s.score_b or 0.0)
            ev.ScoreNames = ",".join(names)
            ev.R_coe, ev.R_dw = float(s.r_coe or 0.0), float(s.r_dw or 0.0)
            ev.Delay = delay
            ev.SensorTime = float(s.t or 0.0)
            ev.SlipEvents = s.slip_events & 0xFFFFFFFF
            ev.Message = ua.LocalizedText(
                f"slip on {n.info.name}: {names[0]} {ev.ScoreA:.2f}, {names[1]} {ev.ScoreB:.2f}, "
                f"raised {delay * 1000:.1f} ms after the deciding scan")
            self.node_counts[n.index]["alarms"] += 1
            self._event("opcua_alarm", "info", node_event=n.info.name, transition=transition,
                        severity=self.options.alarm_severity, delay_ms=round(delay * 1000, 2))
        elif transition == "cleared":
            ev.Message = ua.LocalizedText(f"slip on {n.info.name} over"
                                          + ("" if a.acked else ", not acknowledged"))
        # ConditionRefresh replays the retained conditions with the node they were last
        # emitted from: the Server object, where a SCADA subscribes, last
        subs = self.server.iserver.subscription_service
        for emitter in (n.handles.obj, node_id(ua.ObjectIds.Server)):
            ev.emitting_node = emitter
            await subs.trigger_event(ev)
        await self._condition_variables(n, now)

    async def _condition_variables(self, n: _NodeState, now: datetime.datetime) -> None:
        """The condition object's variables, as its newest event says (a client that
        browses to SlipAlarm reads what a subscriber was told)."""
        assert self.server is not None and n.handles is not None
        ev = n.event
        for path, nodeid in n.handles.alarm_vars.items():
            value = getattr(ev, path, None)
            if value is None:
                continue
            dtype = ev.data_types.get(path)
            vtype = dtype if isinstance(dtype, ua.VariantType) else ua.VariantType.DateTime
            await self.server.write_attribute_value(nodeid, data_value(ua.Variant(value, vtype), status.GOOD,
                                                                         now, now))

    async def _acknowledge(self, parent: ua.NodeId, *args: Any) -> Any:
        """AcknowledgeableConditionType.Acknowledge(EventId, Comment) on a node's SlipAlarm."""
        i = self._by_condition.get(parent)
        if i is None:
            return status_code(ua.StatusCodes.BadNodeIdInvalid)
        if len(args) < 2:
            return status_code(ua.StatusCodes.BadArgumentsMissing)
        event_id, comment = args[0].Value, args[1].Value
        if not isinstance(event_id, bytes):
            return status_code(ua.StatusCodes.BadTypeMismatch)
        n = self.nodes[i]
        code = n.alarm.acknowledge(event_id)
        if code != status.GOOD:
            self.node_counts[i]["alarm_acks_refused"] += 1
            return status_code(code)
        self.node_counts[i]["alarm_acks"] += 1
        text = comment.Text if isinstance(comment, ua.LocalizedText) else str(comment or "")
        await self._alarm(n, "acknowledged", n.snapshot, text or "")
        self._event("opcua_alarm", "info", node_event=n.info.name, transition="acknowledged", comment=text or "-")
        return []

    # -- methods --------------------------------------------------------------------
    def _method(self, name: str) -> Callable[..., Any]:
        async def call(parent: ua.NodeId, *args: Any) -> Any:
            return self._call(name, parent, args)

        return call

    def _call(self, name: str, parent: ua.NodeId, args: tuple[Any, ...]) -> Any:
        """A method of a node (the server's thread): judged under the one refusal rule
        on the newest snapshot its loop published, then queued for the loop."""
        i = self._by_object.get(parent)
        if i is None:  # called on the type, or on another object
            return status_code(ua.StatusCodes.BadMethodInvalid)
        counts = self.node_counts[i]
        counts["method_calls"] += 1
        if name == "Enable":
            if not args:
                return status_code(ua.StatusCodes.BadArgumentsMissing)
            value = args[0].Value
            if not isinstance(value, bool):
                return status_code(ua.StatusCodes.BadTypeMismatch)
            command = Command("enable" if value else "disable")
        else:
            command = Command(_METHOD_COMMAND[name])  # type: ignore[arg-type]
        why = refusal(command, self.published[i], read_only=self.options.read_only)
        if why is not None:
            counts["commands_refused"] += 1
            self._event("opcua_command_refused", "warning", node_index=i, command=command.name, reason=why)
            return status_code(status.BAD_USER_ACCESS_DENIED if why == "read_only" else status.BAD_INVALID_STATE)
        queue = self.commands[i]
        if len(queue) >= COMMANDS_MAX:
            counts["commands_busy"] += 1
            self._log_once("opcua_commands_busy", "warning", command=command.name)
            return status_code(status.BAD_TOO_MANY_OPERATIONS)
        queue.append(command)
        counts["commands"] += 1
        self._event("opcua_command", "info", node_index=i, command=command.name)
        return []

    # -- what asyncua tells -------------------------------------------------------------
    def _on_login(self, user: str, ok: bool) -> None:
        if ok:
            self.counts["logins"] += 1
            return
        self.counts["logins_refused"] += 1
        self._log_once("opcua_login_refused", "warning", user=user)

    def _on_denied(self, user: str, request: int) -> None:
        self.counts["denied"] += 1
        self._log_once("opcua_access_denied", "warning", user=user, request=_REQUESTS.get(request, str(request)))

    def _on_rejected(self, thumbprint: str, reason: str) -> None:
        self.counts["certificates_rejected"] += 1
        assert self.options.pki_dir is not None
        self._log_once("opcua_certificate_rejected", "warning", thumbprint=thumbprint, reason=reason,
                       kept=f"{self.options.pki_dir}/rejected/{thumbprint}.der")

    def _on_stack(self, record: logging.LogRecord) -> None:
        """One of asyncua's log lines (the server's thread, or another in-process one)."""
        message = record.getMessage()
        for head, counter, event in _STACK_LINES:
            if message.startswith(head):
                if head == "Session " and "idle past" not in message:
                    return
                self.counts[counter] += 1
                if event:
                    self._log_once(event, "warning", detail=message[:200])
                return
        if record.levelno >= logging.ERROR:
            self.counts["stack_errors"] += 1
            self._log_once("opcua_stack_error", "error", detail=message[:200])
        elif record.levelno >= logging.WARNING:
            self.counts["stack_warnings"] += 1
            self._log_once("opcua_stack_warning", "warning", detail=message[:200])

    def _attach_log(self) -> None:
        self._log_handler = _StackLog(self._on_stack)
        self._log_handler.attach()

    def _detach_log(self) -> None:
        if self._log_handler is not None:
            self._log_handler.detach()
            self._log_handler = None

    def _log_once(self, event: str, level: str, **fields: Any) -> None:
        """At most one line a second per event; the next says how many were not logged."""
        now = time.monotonic()
        last, quiet = self._logged.get(event, (float("-inf"), 0))
        if now - last < 1.0:
            self._logged[event] = (last, quiet + 1)
            return
        self._logged[event] = (now, 0)
        self._event(event, level, not_logged=quiet, **fields)

    def _event(self, name: str, level: str, **fields: Any) -> None:
        i = fields.pop("node_index", None)
        node = fields.pop("node_event", None)
        if i is not None:
            node = self.nodes[i].info.name
        self.on_event(name, level, node, **fields)

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
                    "stack_errors", "writes"):
            out[f"opcua_{key}"] = c[key]
        for key in ("method_calls", "commands", "commands_refused", "commands_busy", "alarms", "alarm_acks",
                    "alarm_acks_refused"):
            out[f"opcua_{key}"] = own[key]
        out["opcua_handover_dropped"] = h.dropped
        if self.nodes[index].info.frame_shape is not None:
            out["opcua_frames"] = own["frames"]
            out["opcua_frames_replaced"] = h.frames_replaced
        return out


class _StackLog(logging.Handler):
    """asyncua's warnings and errors, and its session timeouts (logged at INFO), to the
    server's counters and events instead of stderr; while attached, nothing of asyncua
    reaches the root logger (a JSON log stays JSON)."""

    _LOGGERS = {"asyncua": logging.WARNING, "asyncua.server.internal_session": logging.INFO}

    def __init__(self, on_record: Callable[[logging.LogRecord], None]) -> None:
        super().__init__(logging.INFO)
        self.on_record = on_record
        self._saved: dict[str, tuple[int, bool]] = {}

    def emit(self, record: logging.LogRecord) -> None:
        try:
            self.on_record(record)
        except Exception:  # noqa: BLE001 - a log line must not break the server
            pass

    def attach(self) -> None:
        for name, level in self._LOGGERS.items():
            log = logging.getLogger(name)
            self._saved[name] = (log.level, log.propagate)
            log.setLevel(level)
        root = logging.getLogger("asyncua")
        root.addHandler(self)
        root.propagate = False

    def detach(self) -> None:
        logging.getLogger("asyncua").removeHandler(self)
        for name, (level, propagate) in self._saved.items():
            log = logging.getLogger(name)
            log.setLevel(level)
            log.propagate = propagate
        self._saved.clear()
