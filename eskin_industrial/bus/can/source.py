"""The CAN source: one node's scans from a python-can bus.

Nodes on the same bus (same interface, channel and bit rates) share one reader and
one :class:`~eskin_industrial.bus.can.group.CanGroup` that routes frames by ID; each
node's :class:`CanSource` assembles its own frames into scans with the pure
:class:`~eskin_industrial.bus.can.layout.ScanAssembler`.  A node polled alone waits
on the bus through its group; several nodes on one bus are stepped by one loop
thread, which waits once a round (``feeder.route``).
"""

from __future__ import annotations

import collections
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar

import can

from ...errors import ProfileError
from ...frames import RawScan
from ...preflight import check_writable_dir
from ...profile import MAX_BITRATE_BPS, MAX_DATA_BITRATE_BPS, Profile
from ...schema import in_range, positive_at_most
from ...seam import NodeLike, OpenContext
from ..source import Source
from .busargs import make_timing, parse_filters
from .group import CanGroup
from .layout import ID_RANGE, CanLayout, ScanAssembler
from .reader import BusReader, FrameThread, bus_kwargs, open_bus


@dataclass(frozen=True)
class CanOptions:
    """``[[node]]`` keys of ``source = "can"``: python-can's own names; unset ones are
    left to python-can's configuration (file, ``CAN_INTERFACE``, ``CAN_CHANNEL``), bit
    rates to the profile's ``[can]``."""

    interface: str | None = None
    channel: str | None = None
    bitrate_bps: int | None = field(default=None, metadata=positive_at_most(MAX_BITRATE_BPS, "an integer"))
    fd: bool | None = None
    data_bitrate_bps: int | None = field(default=None, metadata=positive_at_most(MAX_DATA_BITRATE_BPS, "an integer"))
    #: Override the profile's ``[can] base_id`` / ``node_id`` (several nodes, one bus).
    base_id: int | None = field(default=None, metadata=in_range(0, 0x1FFFFFFF))
    node_id: int | None = field(default=None, metadata=in_range(0, 255))
    #: Record the bus traffic to this file (python-can writer by suffix: .log candump,
    #: .blf, .asc, ...); replaying it gives the same scans.
    log: str | None = None
    #: python-can's bit timing table (``--timing``): f_clock, brp, tseg1, ... or, for
    #: CAN FD, f_clock, nom_brp, ..., data_brp, ...; it replaces the bit rates.
    timing: dict[str, int] | None = None
    #: python-can's filters, hexadecimal ``ID:MASK`` / ``ID~MASK`` (``--filter``).
    filter: tuple[str, ...] = ()
    #: The bus class's own keyword arguments (``--bus-kwargs``): app_name, serial, ...
    bus_kwargs: dict[str, int | float | str | bool] = field(default_factory=dict)

    def __post_init__(self) -> None:
        try:
            if self.timing:
                make_timing(self.timing)
        except ValueError as exc:
            raise ValueError(f"timing: {exc}") from None
        try:
            parse_filters(self.filter)
        except ValueError as exc:
            raise ValueError(f"filter: {exc}") from None


# The live bus's options and a replayed log's (``can-log``, a subclass) share this
# class's code, each method reading the keys its kind has: ``Any`` for both.
class CanSource(Source[Any]):
    kind = "can"
    spec = "can"
    Options: ClassVar[type] = CanOptions  # (the log kind has options of its own)
    feeder: CanGroup  # always set: a CAN source is fed by its bus's group
    profile_keys = {"bitrate_bps": "can.bitrate_bps", "fd": "can.fd", "data_bitrate_bps": "can.data_bitrate_bps",
                    "base_id": "can.base_id", "node_id": "can.node_id"}

    def __init__(self, feeder: CanGroup, queue: collections.deque[can.Message], assembler: ScanAssembler,
                 idle_wait_s: float = 0.0005) -> None:
        super().__init__()
        self.feeder = feeder
        self.assembler = assembler
        self.reader: FrameThread = feeder.reader
        self._queue = queue
        self._ready: collections.deque[RawScan] = collections.deque()
        self._errors_seen = 0
        self._idle_wait_s = idle_wait_s

    def _poll(self, timeout_s: float | None) -> RawScan | None:
        q = self._queue
        if not self._ready and not q:
            self.feeder.route(self._idle_wait_s if timeout_s is None else timeout_s)
        ready = self._ready
        while not ready and q:
            scan = self.assembler.feed(q.popleft())
            if scan is not None:
                # a scan arrived: the bus works (an error frame, which also arrives, does not say so)
                self._errors_seen = self.reader.counters["bus_errors"]
                ready.append(scan)
        return ready.popleft() if ready else None

    @property
    def pending(self) -> bool:
        return bool(self._ready or self._queue)

    @property
    def bus_fault(self) -> bool:
        """The bus failed to read and no scan has arrived since, or the controller
        reports bus-off or a run of error frames and no frame of the node came since."""
        return self.reader.counters["bus_errors"] > self._errors_seen or self.assembler.error_fault

    @property
    def done(self) -> bool:
        return self.feeder.done and not self.pending

    @property
    def last_error(self) -> str:
        return self.reader.last_error or self.assembler.error_reason

    @property
    def fault_reason(self) -> str:
        stream = self.assembler.stream
        return stream.reason if stream.fault else ""

    @property
    def failed(self) -> bool:
        # only the reader ends a source on an error (a log that cannot be read further);
        # error frames say the bus fails, not that the source has
        return self.done and bool(self.reader.last_error)

    def bus_errors(self) -> int:
        """Failed reads of the bus, and the error frames the controller reported."""
        return self.reader.counters["bus_errors"] + self.assembler.counters["error_frames"]

    def counters(self) -> dict[str, int]:
        return {**self.assembler.counters, **self.feeder.counters()}

    def end_reception(self, step: Callable[[float], object]) -> None:
        """The end of a reception (``receive``): the reader stops, what it had queued is
        still decoded through ``step`` (the node loop's), and a scan the end cut short
        is counted torn."""
        self.reader.stop()
        while self.pending or self.reader.queue:
            step(0.0)
        self.assembler.flush()

    def start(self) -> CanSource:
        self.feeder.start()
        return self

    def _close(self) -> None:
        self.feeder.stop()

    # -- the kind ------------------------------------------------------------------
    @classmethod
    def options_from_spec(cls, where: str, bus: dict[str, Any]) -> dict[str, Any]:
        if where:
            raise ValueError(f"expected 'can' with -i/-c, got 'can:{where}'")
        return {k: v for k, v in bus.items() if v is not None}

    @classmethod
    def adapt_profile(cls, profile: Profile, options: Any) -> Profile:
        if options.base_id is None and options.node_id is None:
            return profile
        c = profile.can
        can_section = replace(c, base_id=c.base_id if options.base_id is None else options.base_id,
                              node_id=c.node_id if options.node_id is None else options.node_id)
        return replace(profile, can=can_section)

    @classmethod
    def fd(cls, node: NodeLike[Any]) -> bool:
        return node.profile.can.fd if node.options.fd is None else node.options.fd

    @classmethod
    def describe(cls, node: NodeLike[Any]) -> str:
        o = node.options
        return f"can {o.interface or '(configured)'} {o.channel or ''} ids {node.profile.can.base_id:#x}+{ID_RANGE}"

    @classmethod
    def check(cls, node: NodeLike[Any], base_dir: str) -> None:
        cls.check_layout(node)
        if node.options.log:
            check_writable_dir(node.options.log, "log")

    @classmethod
    def check_layout(cls, node: NodeLike[Any]) -> None:
        """The node's frames as the profile describes them can carry its raw values
        (``taxel_bits``, a scan that fits a node's IDs): the refusal the run meets when it
        opens the bus, found before."""
        try:
            CanLayout.from_profile(node.profile, fd=cls.fd(node))
        except ProfileError as exc:
            raise ValueError(f"profile: {exc}") from None

    @classmethod
    def check_together(cls, nodes: Sequence[NodeLike[Any]]) -> None:
        """Nodes on one bus must not share IDs."""
        by_bus: dict[tuple, list[NodeLike[Any]]] = {}
        for n in nodes:
            by_bus.setdefault(cls.share_key(n), []).append(n)
        for group in by_bus.values():
            spans = sorted((n.profile.can.base_id, n.profile.can.extended_id, n.name) for n in group)
            for (lo, ext_a, a), (hi, ext_b, b) in zip(spans, spans[1:]):
                if ext_a == ext_b and hi - lo < ID_RANGE:
                    raise ValueError(f"[node {b!r}] base_id: {hi:#x} overlaps node {a!r} at {lo:#x} on the same bus "
                                     f"(a node takes {ID_RANGE} IDs; set base_id)")

    @classmethod
    def share_key(cls, node: NodeLike[Any]) -> tuple:
        o = node.options
        return ("can", o.interface, o.channel, o.bitrate_bps, cls.fd(node), o.data_bitrate_bps,
                tuple(sorted((o.timing or {}).items())), o.filter, tuple(sorted(o.bus_kwargs.items())))

    @classmethod
    def open_nodes(cls, nodes: Sequence[NodeLike[Any]], context: OpenContext) -> list[Source[Any]]:
        groups: dict[tuple, list[int]] = {}
        for i, n in enumerate(nodes):
            groups.setdefault(cls.share_key(n), []).append(i)
        out: list[Source[Any] | None] = [None] * len(nodes)
        for members in groups.values():
            first = nodes[members[0]]
            reader = cls._reader(first, context)
            # (a replayed log's options have no ``log``: a replay is not recorded again)
            logs = [nodes[i].options.log for i in members if getattr(nodes[i].options, "log", None)]
            log = can.Logger(logs[0]) if logs else None
            if log is not None:
                context.closers.append(log.stop)  # after the reader has stopped (closers run in reverse)
            layouts = [CanLayout.from_profile(nodes[i].profile, fd=cls.fd(nodes[i])) for i in members]
            group = CanGroup(reader, layouts, log, context.all_frames)
            context.closers.append(group.stop)
            for i, layout, q in zip(members, layouts, group.queues):
                out[i] = cls(group, q, ScanAssembler(layout, nodes[i].rate_hz))
        return [s for s in out if s is not None]

    @classmethod
    def _reader(cls, node: NodeLike[Any], context: OpenContext) -> FrameThread:
        o = node.options
        kw = bus_kwargs(node.profile, o.interface, o.channel, o.bitrate_bps, o.fd, o.data_bitrate_bps,
                        timing=o.timing, filters=o.filter, extra=o.bus_kwargs)
        return BusReader(lambda: open_bus(**kw), context.queue_frames)

    def describe_where(self) -> str:
        bus = getattr(self.reader, "bus", None)
        return str(getattr(bus, "channel_info", None) or "can")
