"""The input seam: what every source of raw scans does, and the registry of kinds.

A :class:`Source` hands out one :class:`~eskin_industrial.frames.RawScan` per
:meth:`Source.poll` and tells its health and counters; the per-node loop
(:mod:`eskin_industrial.bridge.loop`) asks nothing else of it.  As in python-can's
``BusABC.recv`` over ``_recv_internal``, the public method is written once here and
a kind overrides one private hook, :meth:`Source._poll`; the receipt time, the frame
age and a safe double :meth:`Source.close` come with the base.

A *kind* is one module plus one entry in :data:`SOURCES` (name -> ``module:Class``,
imported only when used), or a plug-in: an entry point of the group
``eskin_industrial.sources`` in another distribution (:mod:`eskin_industrial.registry`).  The class declares everything the bridge configuration,
the command line and ``--check`` need, so that none of them branches on the kind:

- ``kind`` and ``spec``: its name in ``[[node]] source = ...`` and in
  ``--source KIND:WHERE``;
- ``Options``: a frozen dataclass of its own ``[[node]]`` keys (typed, checked, unknown
  keys refused with the nearest valid one, like every TOML section);
- :meth:`Source.options_from_spec`: those options from ``--source`` and the shared
  bus options;
- :meth:`Source.describe` and :meth:`Source.check`: the ``--check`` line and the
  problems that can be found before anything starts;
- :meth:`Source.open_nodes`: open the sources of every node of this kind (a CAN bus
  shared by several nodes is opened once).

An example of a new kind, run by ``tests/test_seams.py``: ``docs/architecture.md``.
"""

from __future__ import annotations

import abc
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar, Generic, Protocol, TypeVar

from ..frames import RawScan
from ..registry import SOURCE_GROUP, kinds, load_kind
from ..seam import NodeLike, OpenContext

if TYPE_CHECKING:
    from ..profile import Profile

#: name -> "module:Class", imported on first use (a kind's dependencies load only
#: when a node uses it).
SOURCES: dict[str, str] = {
    "can": "eskin_industrial.bus.can.source:CanSource",
    "can-log": "eskin_industrial.bus.can.log:CanLogSource",
    "modbus-rtu": "eskin_industrial.bus.modbus.rtu:RtuSource",
    "scene": "eskin_industrial.bus.replay:SceneSource",
    "recording": "eskin_industrial.bus.replay:RecordingSource",
}

#: Shorter spellings accepted on ``--source`` (``log:FILE``, ``rtu:PORT``).
ALIASES: dict[str, str] = {"log": "can-log", "rtu": "modbus-rtu"}


def frame_age(last_rx: float | None, now: float | None = None) -> float | None:
    """Seconds since ``last_rx`` (``time.monotonic``), None when nothing came yet:
    the one definition of a frame's age (sources, the loop, the register image)."""
    if last_rx is None:
        return None
    return (time.monotonic() if now is None else now) - last_rx


@dataclass(frozen=True)
class SourceHealth:
    """What a source knows of itself, for the register image and the logs."""

    frame_age_s: float | None  #: None: no scan yet
    bus_fault: bool = False  #: the bus or the node fails now
    bus_errors: int = 0  #: counted since start
    last_error: str = ""
    done: bool = False  #: a finite source (a log, a recording played once) has ended


#: A source kind's options (its ``Options``, the ``[[node]]`` keys of its own).
OptionsT = TypeVar("OptionsT")


class Source(abc.ABC, Generic[OptionsT]):
    """Raw scans from one sensor node, polled by one loop thread; a kind is generic
    over its ``Options``, which its class methods are handed (``node.options``)."""

    #: The kind's name (``[[node]] source``, ``--source KIND:...``).
    kind: ClassVar[str] = ""
    #: ``--source`` syntax, for help and messages.
    spec: ClassVar[str] = ""
    #: The kind's own ``[[node]]`` keys (a frozen dataclass).
    Options: ClassVar[type] = type(None)
    #: Option -> the profile key (dotted) it falls back to when unset, for ``--explain``.
    profile_keys: ClassVar[dict[str, str]] = {}

    #: Set when this source is fed by a transport shared with other nodes' sources.
    feeder: Feeder | None = None

    def __init__(self) -> None:
        self._last_rx: float | None = None
        self._closed = False

    # -- the one public surface -------------------------------------------------------
    def poll(self, timeout_s: float | None = None) -> RawScan | None:
        """The next scan, or None after waiting up to ``timeout_s`` (None: the kind's
        own pace) for one."""
        scan = self._poll(timeout_s)
        if scan is not None:
            self._last_rx = time.monotonic()
        return scan

    @abc.abstractmethod
    def _poll(self, timeout_s: float | None) -> RawScan | None:
        """The kind's hook: one scan or None; must not block much past ``timeout_s``."""

    def frame_age(self, now: float | None = None) -> float | None:
        return frame_age(self._last_rx, now)

    @property
    def pending(self) -> bool:
        """Another :meth:`poll` would return a scan at once (frames already queued)."""
        return False

    @property
    def bus_fault(self) -> bool:
        return False

    @property
    def done(self) -> bool:
        """A finite source has nothing more to give (never, for a live bus)."""
        return False

    @property
    def last_error(self) -> str:
        return ""

    @property
    def failed(self) -> bool:
        """A finite source ended on an error (a corrupt log, or one of another layout):
        what it gave up to then cannot be trusted to be all there is."""
        return self.done and bool(self.last_error)

    @property
    def fault_reason(self) -> str:
        """What the transport saw when it marked its scans with a sensor fault (FLAGS
        STREAM: frames not one node's, an answer repeated), for the log; "" for none."""
        return ""

    def bus_errors(self) -> int:
        """Bus errors counted since start (the register image's BUS_ERRORS)."""
        return 0

    def lost_pending(self) -> int:
        """Scans known lost in an outage under way, that no scan has confirmed yet (the
        pipeline counts a gap only when the next scan arrives; LOST_SCANS must grow
        while the outage lasts)."""
        return 0

    def health(self, now: float | None = None) -> SourceHealth:
        return SourceHealth(self.frame_age(now), self.bus_fault, self.bus_errors(), self.last_error, self.done)

    def counters(self) -> dict[str, int]:
        """The kind's own counters (names unique across kinds: ``rtu_timeouts``, ...)."""
        return {}

    def describe_where(self) -> str:
        """Where the scans come from, for the start log line."""
        return self.kind

    def start(self) -> Source:
        """Start what runs in the background (a reader thread); default: nothing."""
        return self

    def close(self) -> None:
        """Release the transport; safe to call twice."""
        if self._closed:
            return
        self._closed = True
        self._close()

    def _close(self) -> None:
        pass

    def __enter__(self) -> Source:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- what the configuration, the CLI and --check ask of a kind ---------------------
    @classmethod
    def options_from_spec(cls, where: str, bus: dict[str, Any]) -> dict[str, Any]:
        """``[[node]]`` keys from ``--source KIND:WHERE`` and python-can's shared
        options (``interface``, ``channel``, ``bitrate_bps``, ``fd``,
        ``data_bitrate_bps``; None when not given).  ValueError names what is wrong."""
        return {}

    @classmethod
    def adapt_profile(cls, profile: Profile, options: OptionsT) -> Profile:
        """The node's profile with the kind's overrides applied (a CAN node's
        ``base_id``, an RTU node's ``unit_id``); ValueError when they break it."""
        return profile

    @classmethod
    def describe(cls, node: NodeLike[OptionsT]) -> str:
        """One line for ``--check`` and the start log: where this node's scans come from."""
        return cls.kind

    @classmethod
    def check(cls, node: NodeLike[OptionsT], base_dir: str) -> None:
        """Problems found before anything opens (a missing file, an unknown scene);
        ValueError ``key: what is wrong``."""

    @classmethod
    def check_together(cls, nodes: Sequence[NodeLike[OptionsT]]) -> None:
        """Problems between the nodes of this kind (one serial line, two nodes);
        ValueError ``key: what is wrong``."""

    @classmethod
    def share_key(cls, node: NodeLike[OptionsT]) -> tuple[object, ...] | None:
        """Nodes of this kind with the same key share one transport (one CAN bus); None:
        each node has its own."""
        return None

    @classmethod
    def open_nodes(cls, nodes: Sequence[NodeLike[OptionsT]], context: OpenContext) -> list[Source[OptionsT]]:
        """Open one source per node (a kind that shares a transport overrides this)."""
        out = []
        for n in nodes:
            src = cls.open_node(n, context)
            context.closers.append(src.close)
            out.append(src)
        return out

    @classmethod
    def open_node(cls, node: NodeLike[OptionsT], context: OpenContext) -> Source[OptionsT]:
        raise NotImplementedError(f"source kind {cls.kind!r} opens no single node")


class Feeder(Protocol):
    """Several nodes' sources fed by one transport read (a CAN bus shared by ID): the
    loop waits on the feeder once a round, then steps each node's loop under ``lock``;
    ``serve_arrivals`` lets the reading thread run that round itself when the loop
    thread is idle (its failure is kept in ``serve_error`` for the loop to raise)."""

    lock: threading.Lock
    serve_error: BaseException | None

    def wait(self, timeout_s: float) -> None: ...

    def route(self, timeout_s: float) -> int: ...

    def serve_arrivals(self, serve: Callable[[], None]) -> None: ...

    @property
    def done(self) -> bool: ...

    def start(self) -> Any: ...


def source_kinds() -> dict[str, str]:
    """Every source kind: :data:`SOURCES`, then the plug-ins (entry-point group
    ``eskin_industrial.sources``)."""
    return kinds(SOURCES, SOURCE_GROUP)


def source_class(kind: str) -> type[Source[Any]]:
    """The class of a kind by name or alias; an unknown one is one line with the valid names."""
    cls: type[Source[Any]] = load_kind(SOURCES, ALIASES.get(kind, kind), "source kind", Source, SOURCE_GROUP)
    return cls
