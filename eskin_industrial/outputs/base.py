"""The output seam: what every sink does, and the registry of output kinds.

A node's loop hands each of its sinks every detector update (:meth:`Sink.on_update`,
cheap, for a recorder), the calibrated taxel frame at the interval the sink asks for
(:attr:`Sink.frame_every_s`, :meth:`Sink.on_frame`; most sinks ask for none), and every
publication of the node's snapshot (:meth:`Sink.publish`: a
:class:`~eskin_industrial.node.NodeSnapshot`, the state, validity, health, scores,
force, counts and times in named fields and SI units, with whether it is urgent; the
PLC renders its registers from it, nothing else does).  A sink that can be commanded
(the PLC, Sparkplug: acknowledge, tare, enable) hands the commands back through
:meth:`Sink.take_commands`, each a :class:`~eskin_industrial.node.Command` it has
judged under :func:`~eskin_industrial.node.refusal`, the one rule.  Each sink reports :meth:`Sink.health` (connected,
failures, last error) and :meth:`Sink.counters`; a sink that knows when its own
episodes start and end (the PLC writer's outages) says so with :meth:`Sink._event`,
which the bridge routes to its log (:meth:`Sink.on_events`).  :meth:`Sink.flush` /
:meth:`Sink.close` end it (close is safe to call twice).

The public methods are written once here over private hooks (``_publish``,
``_close``), as python-can's ``BusABC.send`` over its backend's hook.

An *output kind* (:class:`OutputKind`) is the other half: a table of what the bridge
configuration (its own ``[SECTION]`` of ``bridge.toml``), the command line
(:attr:`OutputKind.cli_options`) and ``--check`` need, and :meth:`OutputKind.open_nodes`,
which opens one sink per node (a kind may share one connection between its nodes, as
the PLC server serves every node's block) and tells each its kind's name.  A kind is
one module plus one entry in :data:`SINKS` (section name -> ``module:Class``,
imported on first use), or a plug-in: an entry point of the group
``eskin_industrial.sinks`` in another distribution (:mod:`eskin_industrial.registry`).

An example of a new kind, run by ``tests/test_seams.py``: ``docs/architecture.md``.
"""

from __future__ import annotations

import collections
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar, Generic, TypeVar, cast

from ..registry import SINK_GROUP, kinds, load_kind

if TYPE_CHECKING:
    from ..detect.updates import Update
    from ..frames import Frame
    from ..node import Command, NodeSnapshot
    from ..profile import Profile
    from ..seam import NodeLike, OpenContext

#: section name -> "module:Class" of its :class:`OutputKind`, imported on first use.  The order is the order of
#: the outputs in logs and ``--check``.
SINKS: dict[str, str] = {
    "plc": "eskin_industrial.outputs.plc.kind:PlcKind",
    "recorder": "eskin_industrial.outputs.recorder.kind:RecorderKind",
    "sparkplug": "eskin_industrial.outputs.sparkplug.kind:SparkplugKind",
    "opcua": "eskin_industrial.outputs.opcua.sink:OpcuaKind",
    "web": "eskin_industrial.outputs.web.kind:WebKind",
}
#: A sink's own events held until a handler is attached (the first ones of a writer
#: that starts before the bridge's log is wired); beyond it the oldest are dropped.
EVENTS_HELD = 64
#: ``(name, level, fields)`` of a sink's own log event.
EventHandler = Callable[[str, str, dict[str, Any]], None]

#: With no output configured at all, the bridge publishes to this one (the PLC as
#: each node's profile describes it).
DEFAULT_OUTPUT = "plc"


@dataclass(frozen=True)
class SinkHealth:
    connected: bool | None = None  #: None: the sink has no connection to lose (a file, a server)
    failures: int = 0
    last_error: str = ""


@dataclass(frozen=True)
class CliOption:
    """One command-line option of an output kind, as plain data (the CLI turns it into
    a click option; the kind's module stays free of the CLI)."""

    flag: str  #: ``--plc``
    dest: str  #: the name its value is handed to :meth:`OutputKind.options_from_cli` under
    help: str
    metavar: str | None = None
    type: type = str  #: str, int or float; bool makes a flag
    default: Any = None
    choices: tuple[str, ...] | None = None
    secret: bool = False  #: never taken from the command line (files or environment only)


#: An output kind's options (its ``Options``, its ``[section]`` of ``bridge.toml``).
OptionsT = TypeVar("OptionsT")


class Sink:
    """Where one node's results go: the per-node half of an output, opened by its
    :class:`OutputKind` (or built by hand, as ``monitor`` builds the register image
    it shows)."""

    #: The sink logs its connection's ups and downs itself (:meth:`_event`): the
    #: bridge does not infer them from :meth:`health`.
    logs_connection: ClassVar[bool] = False

    def __init__(self) -> None:
        self._closed = False
        #: The output kind that opened it (:attr:`OutputKind.name`), for logs; told
        #: at open by :meth:`OutputKind.open_nodes` ("" for a sink built by hand).
        self.kind = ""
        #: Where the results go, for logs (``tcp 10.0.0.5:502 (client)``, a file
        #: path); the kind's name when the sink says nothing.
        self.where = ""
        #: The sink wants a calibrated frame (:meth:`on_frame`) at most this often, in
        #: seconds; None: no frames.  Read once when the sink joins a loop: the loop
        #: decides which frames are due, so a sink that wants none costs the scan nothing.
        self.frame_every_s: float | None = None
        self._events_lock = threading.Lock()
        self._events_held: collections.deque[tuple[str, str, dict[str, Any]]] = collections.deque(maxlen=EVENTS_HELD)
        self._event_handler: EventHandler | None = None

    def overrides(self, name: str) -> bool:
        """The kind has a method ``name`` of its own (the loop calls only those per
        update and for commands)."""
        return getattr(type(self), name) is not getattr(Sink, name)

    # -- the data path --------------------------------------------------------------
    def on_update(self, update: Update) -> None:
        """Every detector update, in order, on the loop's thread: keep it short."""

    def on_frame(self, frame: Frame) -> None:
        """A calibrated frame (newtons, row-major: the layout's rows x cols; NaN for a
        reading the calibration refused), when :attr:`frame_every_s` has passed since
        the last one handed, on the loop's thread: never block.  The frame is the one
        the detector saw, not a copy: never change its arrays."""

    def publish(self, snapshot: NodeSnapshot) -> None:
        """A publication of the node's snapshot, on the loop's thread: never block.
        ``snapshot.urgent``: a change to send at once; ``snapshot.offline``: the
        bridge's last one."""
        self._publish(snapshot)

    def _publish(self, snapshot: NodeSnapshot) -> None:
        """The kind's hook for :meth:`publish`; default: nothing."""

    def take_commands(self) -> list[Command]:
        """Commands received since the last call (acknowledge, tare, enable)."""
        return []

    def source_ended(self, error: str) -> None:
        """The node's source ended (``error``: why it failed, "" for a clean end) while
        the bridge may go on with other nodes; called after the node's last
        publication.  Default: nothing (the image turns stale by itself)."""

    def commands_done(self) -> None:
        """The loop has applied the commands it took."""

    # -- health -----------------------------------------------------------------------
    def health(self) -> SinkHealth:
        return SinkHealth()

    def counters(self) -> dict[str, int]:
        """The kind's counters, with names unique across kinds (``plc_writes``)."""
        return {}

    def on_events(self, handler: EventHandler) -> None:
        """Hand the sink's own events to ``handler`` (called on the thread that has
        them: it must not block); the events held until now first."""
        with self._events_lock:
            held = list(self._events_held)
            self._events_held.clear()
            self._event_handler = handler
        for name, level, fields in held:
            handler(name, level, fields)

    def _event(self, name: str, level: str = "info", **fields: Any) -> None:
        """A log event of the sink's own (``plc_unreachable``); held until a handler is attached."""
        handler = self._event_handler
        if handler is None:
            with self._events_lock:
                handler = self._event_handler
                if handler is None:
                    self._events_held.append((name, level, fields))
                    return
        handler(name, level, fields)

    # -- the end ----------------------------------------------------------------------
    def drain(self, timeout_s: float = 0.5) -> bool:
        """Wait, for up to ``timeout_s``, until what was published has been handed on,
        and go on running; True when it has.  A sink that hands on at once has nothing
        to wait for."""
        return True

    def flush(self, timeout_s: float = 1.0) -> bool:
        """Write what is still pending, for up to ``timeout_s``; True when nothing is left."""
        return True

    def close(self) -> None:
        """Stop and release; safe to call twice."""
        if self._closed:
            return
        self._closed = True
        self._close()

    def _close(self) -> None:
        pass


class OutputKind(Generic[OptionsT]):
    """An output kind: what the bridge configuration (its own ``[SECTION]`` of
    ``bridge.toml``), the command line and ``--check`` need of it, and how it opens
    one :class:`Sink` per node.  A table of class attributes and class methods, never
    instantiated (as python-can's table of interfaces beside its ``Listener``);
    generic over its ``Options``, which its class methods are handed."""

    #: The kind's name: its ``[SECTION]`` in the bridge configuration, its log events.
    name: ClassVar[str] = ""
    #: The kind's configuration section (a frozen dataclass).
    Options: ClassVar[type] = type(None)
    #: The kind's command-line options.
    cli_options: ClassVar[tuple[CliOption, ...]] = ()
    #: Option -> the (first node's) profile key it falls back to when unset.
    profile_keys: ClassVar[dict[str, str]] = {}
    #: The kind's own keys of one node (a frozen dataclass): ``[node.KIND]`` under a
    #: ``[[node]]`` table of ``bridge.toml`` (the PLC: the node's ``base_address``);
    #: None: the kind has none.  Applied to the node's profile by :meth:`adapt_profile`.
    NodeOptions: ClassVar[type | None] = None
    #: The options of a one-node bridge's command line that fill :attr:`NodeOptions`.
    node_cli_options: ClassVar[tuple[CliOption, ...]] = ()
    #: ``[[node]]`` keys of earlier releases that are now this kind's (old -> its key):
    #: still read, with a deprecation warning naming ``[node.KIND] key``.
    moved_node_keys: ClassVar[dict[str, str]] = {}
    #: A key of :attr:`NodeOptions` -> the profile key (dotted) it overrides, for ``--explain``.
    node_profile_keys: ClassVar[dict[str, str]] = {}
    #: Beginnings of the names of the threads the kind runs that are not named
    #: ``KIND-...`` (a library's own, paho's): a death of one is this output's failure
    #: (:mod:`eskin_industrial.bridge.supervise`), not the bridge's.
    thread_names: ClassVar[tuple[str, ...]] = ()

    @classmethod
    def options_from_cli(cls, values: dict[str, Any]) -> OptionsT | None:
        """The kind's options from its command-line values (None: not asked for);
        ValueError / click's BadParameter-like one line for a bad value."""
        return None

    @classmethod
    def node_options_from_cli(cls, values: dict[str, Any]) -> Any | None:
        """The kind's :attr:`NodeOptions` from a one-node command line (None: none given)."""
        return None

    @classmethod
    def adapt_profile(cls, profile: Profile, node_options: Any) -> Profile:
        """The node's profile with the kind's node options laid over it (a node's
        ``[node.plc] base_address`` over its profile's ``[modbus.plc]``)."""
        return profile

    @classmethod
    def default_options(cls) -> OptionsT:
        """The options when the kind is the default output and nothing was given."""
        return cast(OptionsT, cls.Options())

    @classmethod
    def describe(cls, options: OptionsT, node: NodeLike[Any]) -> str:
        """One line for ``--check``: where this node's results go."""
        return cls.name

    @classmethod
    def check(cls, options: OptionsT, nodes: Sequence[NodeLike[Any]]) -> None:
        """Problems across nodes found before anything opens; ValueError ``key: what``."""

    @classmethod
    def explain_keys(cls, options: OptionsT, nodes: Sequence[NodeLike[Any]]) -> dict[str, str]:
        """:attr:`profile_keys` as they apply to these options (``--explain``)."""
        return cls.profile_keys

    @classmethod
    def probe(cls, options: OptionsT, nodes: Sequence[NodeLike[Any]]) -> None:
        """``--check`` only: what can be found by trying on this machine (a port to
        listen on is free); the run meets the same at open, with the same message.
        ValueError ``key: what``."""

    @classmethod
    def open_nodes(cls, options: OptionsT, nodes: Sequence[NodeLike[Any]], context: OpenContext) -> list[Sink]:
        """One sink per node (in order), each told the kind's name; what must be
        closed goes to ``context.closers``."""
        sinks = cls._open_nodes(options, nodes, context)
        for sink in sinks:
            sink.kind = cls.name
            sink.where = sink.where or cls.name
        return sinks

    @classmethod
    def _open_nodes(cls, options: OptionsT, nodes: Sequence[NodeLike[Any]], context: OpenContext) -> list[Sink]:
        """The kind's hook for :meth:`open_nodes`: every kind has one (a kind may
        share one connection between its nodes, as the PLC server serves every
        node's block)."""
        raise NotImplementedError(f"the output kind {cls.name!r} opens no nodes")


def output_kind(name: str) -> type[OutputKind[Any]]:
    """An output kind by name; an unknown one is one line with the valid names."""
    cls: type[OutputKind[Any]] = load_kind(SINKS, name, "output kind", OutputKind, SINK_GROUP)
    return cls


def sink_kinds() -> dict[str, str]:
    """Every output kind: :data:`SINKS`, then the plug-ins (entry-point group
    ``eskin_industrial.sinks``), in the order of logs, ``--check`` and the options."""
    return kinds(SINKS, SINK_GROUP)
