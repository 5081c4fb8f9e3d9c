"""Sparkplug B 3.0 on MQTT as an output kind (``[sparkplug]`` in the bridge
configuration, ``--sparkplug mqtt://HOST:PORT`` on the command line).

The bridge process is one edge node (``group_id``, ``edge_node_id``) over one MQTT
connection; each sensor node is a device named after the node.  The metrics are the
node's snapshot (:class:`~eskin_industrial.node.NodeSnapshot`), the same the PLC's
register image is rendered from, so that the plant and the PLC see the same state.

The loop's thread only encodes and enqueues: paho-mqtt's network thread
(``loop_start``) writes to the broker, reconnects, and calls back on connect (births),
on a command (NCMD rebirth; DCMDs, queued for the loop: :mod:`.commands`) and on the
primary host's STATE (offline: NDEATH, DISCONNECT, a new session), and on our own
DDATA handed back by the broker (what it has: at QoS 0 the only way to know).  While
the node cannot publish (no broker, no primary host) its data messages go to the store
(:mod:`.store`), whose own thread writes them to SQLite and sends them, historical,
after the next births; so do those a lost connection took with it.  One lock orders the
``seq`` numbers with the messages.  The connection's security: :mod:`.transport`;
``bdSeq`` across restarts: :mod:`.bdseq`.

Sparkplug 3.0 to the letter by default (``docs/plant.md``, Conformance, and
``tests/test_sparkplug_conformance.py``, one test per tck-id): births, data and DDEATH
at QoS 0, every metric with its timestamp, no datatype after the birth; QoS 1 for them
only by the opt-in ``nonconforming_qos1``, warned about.

With ``frame_interval_s`` the device also publishes the calibrated taxel frame as a
``FloatArray`` metric (``Taxels/Frame``): the node's loop hands it the newest frame
once that interval has passed (:attr:`~eskin_industrial.outputs.base.Sink.frame_every_s`),
and it goes out as a DDATA of its own, QoS 0, or not at all while the node cannot
publish (a frame is a sample of now: the store keeps the states, not stale frames).
"""

from __future__ import annotations

import collections
import itertools
import json
import math
import os
import sys
import threading
import time
import unicodedata
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

from ... import __version__
from ...detect.state import LABELS
from ...errors import EskinError, ProfileError
from ...node import Command, NodeSnapshot, refusal
from ...ratelimit import Throttle
from ...schema import SchemaError, build, in_range
from ..base import CliOption, OutputKind, Sink, SinkHealth
from . import payload as pb
from .bdseq import BdSeqFile, bdseq_path, writable
from .commands import COMMAND_ALIAS, COMMANDS, BadCommand, birth_metrics, parse_device_command
from .properties import Property, frame_properties, layout_properties, method_properties, score_properties
from .store import Forwarder, Held, store_path
from .transport import check_files, check_security, configure, parse_broker

if TYPE_CHECKING:
    from ...frames import Frame
    from ...seam import NodeLike, OpenContext

NAMESPACE = "spBv1.0"
FRAME_INTERVAL_MIN_S = 0.05
REBIRTH = "Node Control/Rebirth"
_FORBIDDEN = set("+#/")


#: An id's length at most, in UTF-8 bytes: three of them make a topic and two the
#: client id, each an MQTT string of at most 65,535 bytes (a longer one ended paho's
#: thread); ids are names, not texts.
MAX_ID_BYTES = 256


def check_id(key: str, value: str) -> None:
    """A group, edge node or device id: a UTF-8 string of the characters an MQTT topic
    allows, without a level separator or a wildcard (tck-id-intro-group-id-chars and its
    siblings, tck-id-topic-structure-namespace-valid-group-id and its siblings)."""
    if not value or _FORBIDDEN & set(value):
        raise ValueError(f"{key}: {value!r} is not a Sparkplug id (not empty, no '+', '#' or '/')")
    size = len(value.encode("utf-8", "surrogatepass"))
    if size > MAX_ID_BYTES:
        raise ValueError(f"{key}: {size} bytes long (UTF-8); a Sparkplug id here is at most {MAX_ID_BYTES}")
    bad = next((c for c in value if unicodedata.category(c) in ("Cc", "Cs")), None)
    if bad is not None:  # MQTT strings: no U+0000, no control characters, valid UTF-8
        raise ValueError(f"{key}: {value!r} holds the character U+{ord(bad):04X}, which an MQTT topic may not")


@dataclass(frozen=True)
class SparkplugOptions:
    """``[sparkplug]``: the broker and this edge node's ids, and report by exception."""

    broker: str  #: ``mqtt://HOST:PORT``, or ``mqtts://HOST:PORT`` (TLS)
    group_id: str
    edge_node_id: str
    #: The MQTT QoS of NBIRTH, DBIRTH, NDATA, DDATA and DDEATH: 0, as Sparkplug requires
    #: (tck-id-topics-ddata-mqtt and its siblings); QoS 1 is :attr:`nonconforming_qos1`.
    qos: int = field(default=0, metadata={"check": (
        lambda v: v == 0, "0, Sparkplug's QoS for births and data (nonconforming_qos1 = true publishes them "
        "at QoS 1, against the specification)")})
    #: Publish NBIRTH, DBIRTH, NDATA, DDATA and DDEATH at QoS 1, where the specification
    #: requires 0: for a broker known to lose QoS 0 messages; a strict host may flag it.
    #: Warned about at start and by ``--check``.
    nonconforming_qos1: bool = False
    keepalive_s: int = field(default=30, metadata=in_range(5, 3600))
    #: An analog value is published when it moved by more than this (its own unit).
    deadband: float = field(default=0.01, metadata=in_range(0, 1e9))
    #: An analog value is published at most this often (a state change goes at once).
    min_interval_s: float = field(default=0.5, metadata=in_range(0, 3600))
    #: The taxel frame (``Taxels/Frame``) is published at most this often; 0: never
    #: (the metric is not declared).  Faster than 20 a second is a stream, not a plant
    #: metric: a CAN log of the node keeps every scan.
    frame_interval_s: float = field(default=0.0, metadata={"check": (
        lambda v: v == 0 or FRAME_INTERVAL_MIN_S <= v <= 3600,
        f"0 (off) or a value in [{FRAME_INTERVAL_MIN_S:g}, 3600]")})
    #: Back-off between connection attempts: from this, doubling up to ``reconnect_max_s``.
    reconnect_min_s: float = field(default=0.2, metadata=in_range(0.05, 60))
    reconnect_max_s: float = field(default=5.0, metadata=in_range(0.05, 600))
    #: Store-and-forward: the folder of the on-disk queue of an outage's data messages
    #: (``<group_id>-<edge_node_id>.sqlite3``); unset: the queue is in memory.
    store_dir: str | None = None
    #: Data messages held at most (0: none); past it they are counted and dropped.
    store_max: int = field(default=10000, metadata=in_range(0, 10_000_000))

    #: mqtts: the CA certificates (PEM) the broker's certificate must chain to (unset: the system's).
    ca_file: str | None = None
    #: mqtts: this edge node's client certificate and its key (PEM), for a broker that asks for one.
    cert_file: str | None = None
    key_file: str | None = None
    username: str | None = None
    #: The password: the first line of this file, or this environment variable (never
    #: a command-line value).
    password_file: str | None = None
    password_env: str | None = None
    #: Sparkplug 3.0 primary host awareness: births (and data) only while the host
    #: application of this id says online on ``spBv1.0/STATE/<id>``; held while it is
    #: away, births again when it comes back.
    primary_host_id: str | None = None

    def __post_init__(self) -> None:
        check_security(self)
        check_id("group_id", self.group_id)
        check_id("edge_node_id", self.edge_node_id)
        if self.primary_host_id is not None:
            check_id("primary_host_id", self.primary_host_id)
        if self.reconnect_max_s < self.reconnect_min_s:
            raise ValueError(f"reconnect_max_s: {self.reconnect_max_s:g} is below reconnect_min_s "
                             f"({self.reconnect_min_s:g})")


class MetricDef(NamedTuple):
    name: str
    datatype: int
    unit: str
    analog: bool  #: deadband and minimum interval (else: published at once on change)
    doc: str


#: The device metrics, in alias order (alias = device base + index).
DEVICE_METRICS: tuple[MetricDef, ...] = (
    MetricDef("State", pb.STRING, "", False, "no_contact, stable, variable_force, slip (STATE)"),
    MetricDef("State Code", pb.UINT8, "code", False, "0 no_contact, 1 stable, 2 variable_force, 3 slip"),
    MetricDef("Slip", pb.BOOLEAN, "", False, "slip now (STATUS bit SLIP)"),
    MetricDef("Slip Latched", pb.BOOLEAN, "", False, "a slip since the last acknowledge"),
    MetricDef("Data Valid", pb.BOOLEAN, "", False, "the state is a verdict"),
    MetricDef("Sensor Stale", pb.BOOLEAN, "", False, "no scan for longer than stale_s"),
    MetricDef("Bus Fault", pb.BOOLEAN, "", False, "the sensor bus fails"),
    MetricDef("Contact", pb.BOOLEAN, "", False, "total force at or above the contact threshold"),
    MetricDef("Enabled", pb.BOOLEAN, "", False, "detection enabled"),
    MetricDef("R_coe", pb.FLOAT, "", True, "the paper's R_coe, whatever method decides (0 while no state is claimed)"),
    MetricDef("R_dw", pb.FLOAT, "", True, "the paper's R_dw, whatever method decides (0 while no state is claimed)"),
    MetricDef("Total Force", pb.FLOAT, "N", True, "total force of the newest frame"),
    MetricDef("CoF X", pb.FLOAT, "mm", True, "centre of force, x"),
    MetricDef("CoF Y", pb.FLOAT, "mm", True, "centre of force, y"),
    # No UInt32: the specification carries it in int_value, Tahu's JavaScript codec and
    # hosts that followed Tahu before 2022 in long_value; UInt16 and UInt64 read alike
    # everywhere (docs/plant.md, A second host).
    MetricDef("Frame Age", pb.UINT16, "ms", True, "age of the newest frame, 65535 = none"),
    MetricDef("Counters/Slip Events", pb.UINT64, "count", True, "entries into slip since start"),
    MetricDef("Counters/State Changes", pb.UINT64, "count", True, "state changes since start"),
    MetricDef("Counters/Lost Scans", pb.UINT64, "count", True, "failed polls and sequence gaps"),
    MetricDef("Counters/Bus Errors", pb.UINT64, "count", True, "timeouts, CRC and exception responses"),
    MetricDef("Counters/Scans", pb.UINT64, "count", True, "scans the node's loop has taken since start"),
    MetricDef("Score A", pb.FLOAT, "", True, "the deciding method's first score (0 while no state is claimed); "
              "DBIRTH properties: method, score (its name), description"),
    MetricDef("Score B", pb.FLOAT, "", True, "the deciding method's second score, likewise"),
    MetricDef("Turn Unseen", pb.BOOLEAN, "", False, "in contact, but a turn about the normal would go unseen: "
              "read stable (FLAGS bit TURN_UNSEEN)"),
    MetricDef("Sensor Fault", pb.UINT16, "bits", False, "the sensor's faults (FLAGS bits DEAD_TAXELS 1024, FROZEN "
              "2048, RATE 4096; 0 none): while one is set no state is claimed and Data Valid is false"),
)
#: The taxel frame: declared (and sent) only with ``frame_interval_s``; its alias is
#: the device's base + :data:`FRAME_ALIAS`.
FRAME_METRIC = MetricDef("Taxels/Frame", pb.FLOAT_ARRAY, "N", False,
                         "the calibrated taxel frame, row-major (rows x cols), NaN for a refused reading")
FRAME_ALIAS = 50
#: The metric whose DBIRTH properties describe the method (``method_properties``) and
#: the one with the layout (``layout_properties``).
METHOD_METRIC, LAYOUT_METRIC = "State", "CoF X"
_ANALOG = tuple(m.analog for m in DEVICE_METRICS)
_ENABLED = next(i for i, m in enumerate(DEVICE_METRICS) if m.name == "Enabled")
#: ``Device Control/Enable`` (its alias offset) reads what ``Enabled`` reads, and changes with it.
_ENABLE_COMMAND = COMMAND_ALIAS + next(i for i, c in enumerate(COMMANDS) if c.on_false is not None)
_FLOATS = tuple(m.datatype == pb.FLOAT for m in DEVICE_METRICS)
#: Node metrics (aliases 1..); a device's metrics start at 1000 x (its index + 1).
NODE_METRICS = ("bdSeq", REBIRTH, "Node Info/Version", "Node Info/Uptime", "Store/Pending", "Store/Overflow")


def metric_values(s: NodeSnapshot) -> tuple[Any, ...]:
    """The device metrics of one snapshot, in :data:`DEVICE_METRICS` order.  While no
    state is claimed (disabled, stale), State reads ``no_contact`` (code 0), with Data
    Valid false, and the indicators and scores read 0, as the PLC's registers do."""
    code = 0 if s.state is None else s.state
    age = s.frame_age_s
    return (LABELS[code] if code < len(LABELS) else str(code), code, s.state == _SLIP, s.slip_latched, s.valid,
            s.stale, s.bus_fault, s.contact, s.enabled, _real(s.r_coe), _real(s.r_dw), _real(s.f_sum_n),
            _real(s.xc_mm), _real(s.yc_mm), _FRAME_AGE_NONE if age is None else min(_ms(age), _FRAME_AGE_NONE),
            s.slip_events, s.state_changes, s.lost_scans, s.bus_errors, s.scans, _real(s.score_a), _real(s.score_b),
            s.turn_unseen, s.sensor_fault)


_SLIP = 3  #: GraspState.SLIP
_FRAME_AGE_NONE = 0xFFFF  #: Frame Age when there is no scan (as the PLC's FRAME_AGE)


def _real(v: float | None) -> float:
    """A metric's float: 0 for none (no state claimed) and for a value that is not
    finite, so that a host never reads NaN as news at every publication."""
    return float(v) if v is not None and math.isfinite(v) else 0.0


def _ms(age_s: float) -> int:
    return round(age_s * 1000.0) if math.isfinite(age_s) else _FRAME_AGE_NONE


def _trailing_seq(data: bytes) -> int | None:
    """The ``seq`` of a payload this edge node encoded: its last field (key 0x18, a
    varint of one or two bytes); any other payload is decoded."""
    n = len(data)
    if n >= 2 and data[-2] == 0x18 and data[-1] < 0x80:
        return data[-1]
    if n >= 3 and data[-3] == 0x18 and data[-2] & 0x80 and data[-1] < 0x80:
        return (data[-2] & 0x7F) | data[-1] << 7
    try:
        return pb.decode(data).seq
    except EskinError:
        return None


def _now_ms() -> int:
    return int(time.time() * 1000)


class EdgeNode:
    """One MQTT connection, the edge node's births and deaths, ``seq`` and ``bdSeq``."""

    #: A data message written at QoS 0 and not seen back from the broker after this
    #: long stops being tracked and is counted (``sparkplug_unconfirmed``): the broker
    #: does not hand this edge node its own DDATA (an access rule, say).
    ECHO_WAIT_S = 10.0

    def __init__(self, options: SparkplugOptions, client_factory: Any) -> None:
        self.options = options
        self.host, self.port, _ = parse_broker(options.broker)
        g, e = options.group_id, options.edge_node_id
        self.topic = {kind: f"{NAMESPACE}/{g}/{kind}/{e}" for kind in ("NBIRTH", "NDEATH", "NDATA", "NCMD")}
        #: Our own DDATA, handed back by the broker: a QoS 0 message seen here has
        #: reached the broker (what a dying broker took with it is sent again).
        self.topic["ECHO"] = f"{NAMESPACE}/{g}/DDATA/{e}/+"
        self.qos = 1 if options.nonconforming_qos1 else 0  #: births, data, DDEATH
        self.devices: list[SparkplugDevice] = []
        self.lock = threading.RLock()
        self.seq = 0
        self.bd_file = BdSeqFile(bdseq_path(options.store_dir, g, e))
        self.bd_seq = self.bd_file.first()
        self.bd_error = self.bd_file.error  #: why bdSeq is not kept across restarts (None: it is)
        self.started = time.monotonic()
        self.connected = False  #: publishing: a session, the births sent (and the primary host online)
        self.session = False  #: an MQTT session
        self.host_online = False
        self._host_ts = -1  #: timestamp of the newest STATE taken (older ones are stale)
        host = options.primary_host_id
        self.state_topic = None if host is None else f"{NAMESPACE}/STATE/{host}"
        self.stopping = False
        self._host_left = False  #: the session ends because the primary host went offline
        self._life = threading.Lock()  #: start, a new session after the host left, close
        self.published = self.dropped = self.connects = self.failures = self.bad_commands = self.rebirths = 0
        self.unknown_devices = self.commands = self.commands_refused = self.bad_states = 0
        self.resent = self.unconfirmed = self.host_sessions_ended = 0
        self._bad_logged: dict[str, tuple[float, int]] = {}
        self.commands_logged = Throttle()  #: the DCMD lines, per device and event
        self.last_error = ""
        self.client = client_factory
        self.client.on_connect = self._on_connect
        self.client.on_disconnect = self._on_disconnect
        self.client.on_connect_fail = self._on_connect_fail
        self.client.on_pre_connect = self._on_pre_connect
        self.client.on_message = self._on_message
        self.client.reconnect_delay_set(options.reconnect_min_s, options.reconnect_max_s)
        self._set_will()
        self.forwarder = Forwarder(store_path(options.store_dir, g, e), options.store_max, self._send_held,
                                   lambda: self.connected and not self.stopping, self._event, self._store_drained)
        self.serial = self.forwarder.next_serial  #: of the next data message (the replay order)
        #: Data messages handed to paho and not yet known to be at the broker: (its
        #: MessageInfo, the message as held, its seq, when).  At QoS 0 a message is
        #: known there when the broker hands it back (our subscription to our own
        #: DDATA), at QoS 1 when acknowledged.  A lost connection sends the rest
        #: through the store, historical, after the next births (paho would drop them
        #: at QoS 0, and resend them before the births at QoS 1: out of Sparkplug's order).
        #: A frame's entry names its device instead (never held: counted if the connection
        #: takes it unconfirmed, ``sparkplug_frames_lost``).
        self.inflight: collections.deque[tuple[Any, Held | SparkplugDevice, int, float]] = collections.deque()

    def _event(self, name: str, level: str = "info", **fields: Any) -> None:
        """An event of the edge node, logged with its first device."""
        if self.devices:
            self.devices[0]._event(name, level, **fields)

    def nonconforming(self) -> list[str]:
        """What departs from the specification, one line each (start and ``--check``)."""
        return nonconforming(self.options, self.bd_error, str(self.bd_file.path))

    # -- messages -----------------------------------------------------------------------
    def _death(self) -> bytes:
        return pb.encode(pb.Payload(_now_ms(), (pb.Metric("bdSeq", None, _now_ms(), pb.INT64, self.bd_seq),)))

    def _set_will(self) -> None:
        """The will of the next CONNECT."""
        self.client.will_set(self.topic["NDEATH"], self._death(), qos=1, retain=False)

    def _on_pre_connect(self, client: Any, userdata: Any) -> None:
        """Just before each connection attempt (paho's thread): the bdSeq its CONNECT
        carries is kept on disk, so that the next run goes on from the last one used
        (:mod:`.bdseq`)."""
        error = self.bd_file.write(self.bd_seq)
        if error is not None and error != self.bd_error:
            self.bd_error = error
            self._event("sparkplug_bdseq_not_kept", "warning", file=str(self.bd_file.path), error=error)

    def _next_seq(self) -> int:
        s = self.seq
        self.seq = (s + 1) & 0xFF
        return s

    def send(self, topic: str, payload: pb.Payload, *, birth: bool = False) -> None:
        """Stamp ``seq`` and enqueue (under the lock: the wire order is the seq order);
        a birth declares its metrics' datatypes, anything else leaves them off."""
        with self.lock:
            payload = pb.Payload(payload.timestamp, payload.metrics, self._next_seq())
            info = self.client.publish(topic, pb.encode(payload, datatypes=birth), qos=self.qos)
            if info.rc == 0:
                self.published += 1
            else:
                self.dropped += 1

    def send_data(self, device: SparkplugDevice, ms: int, metrics: tuple[pb.Metric, ...]) -> None:
        """A DDATA: published when connected, else held for later (under the lock)."""
        serial = self.serial
        self.serial += 1
        held = Held(serial, device.device_id, device.base, ms, metrics)
        if not self.connected:
            self.forwarder.hold(held)
            return
        seq = self._next_seq()
        self._publish_tracked(device.topic["DDATA"], pb.encode(pb.Payload(ms, metrics, seq), datatypes=False),
                              held, seq)

    def send_frame(self, device: SparkplugDevice, data: bytes) -> None:
        """A taxel frame as a DDATA of its own when connected; else only kept for the
        next DBIRTH and counted: never held (the loop's thread)."""
        with self.lock:
            device.frame = data
            if device.dead:
                return
            if not self.connected:
                device.frames_not_sent += 1
                return
            if data == device.frame_sent:
                return  # unchanged: a DDATA carries what changed (tck-id-topics-ddata-payload)
            now = _now_ms()
            metric = pb.Metric(None, device.base + FRAME_ALIAS, now, pb.FLOAT_ARRAY, data)
            seq = self._next_seq()
            if self._publish_tracked(device.topic["DDATA"],
                                     pb.encode(pb.Payload(now, (metric,), seq), datatypes=False), device, seq):
                device.frames += 1
                device.frame_sent = data
            else:
                device.frames_not_sent += 1

    def _publish_tracked(self, topic: str, data: bytes, held: Held | SparkplugDevice, seq: int) -> bool:
        """Publish a DDATA and track it until the broker has it (under the lock); a
        message paho refuses (the connection went) is held instead.  A frame (``held``
        its device) goes at QoS 0 whatever the setting (the next one replaces a frame
        lost), tracked for the order of the echoes and counted if lost, never held."""
        data_message = isinstance(held, Held)
        info = self.client.publish(topic, data, qos=self.qos if data_message else 0)
        if info.rc != 0:
            self.dropped += 1
            if isinstance(held, Held):
                self.forwarder.hold(held)
            return False
        self.published += 1
        now = time.monotonic()
        inflight = self.inflight
        while inflight:
            first, _, _, at = inflight[0]
            if self.qos and first.is_published():
                inflight.popleft()  # acknowledged
            elif now - at > self.ECHO_WAIT_S and first.is_published():
                inflight.popleft()  # written, never seen back
                self.unconfirmed += 1
            else:
                break
        inflight.append((info, held, seq, now))
        return True

    def _echo(self, data: bytes) -> None:
        """One of our DDATA back from the broker (paho's thread): it and everything
        written before it have reached the broker.  The echoes come in the order of
        publishing, so the match is at the front; it is looked for among the first 256
        (a seq comes back once in 256 messages), never the whole queue."""
        seq = _trailing_seq(data)
        if seq is None:
            return
        with self.lock:
            inflight = self.inflight
            at = next((i for i, entry in enumerate(itertools.islice(inflight, 256)) if entry[2] == seq), None)
            if at is None:
                return  # another session's, or already confirmed
            for _ in range(at + 1):
                inflight.popleft()

    def _take_back(self) -> None:
        """The connection is gone: what the broker may not have is held again, to go
        out historical after the next births (under the lock).  What was written to the
        connection is counted (``sparkplug_resent``): it may arrive twice.  A frame not
        seen back is counted as lost (``sparkplug_frames_lost``: it may have arrived)."""
        for info, held, _, _ in self.inflight:
            published = info.is_published()  # QoS 0: written; QoS 1: acknowledged
            if not isinstance(held, Held):
                if not (self.qos and published):  # (with the opt-in a frame written counts as arrived)
                    held.frames_lost += 1
                continue
            if self.qos and published:
                continue
            if published or self.qos:  # (an unacknowledged QoS 1 message may have been written)
                self.resent += 1
            self.forwarder.hold(held)
        self.inflight.clear()

    def _send_held(self, serial: int, device_id: str, base: int, body: bytes) -> bool | None:
        """A held message as a historical DDATA (the forwarder's thread): False when not
        connected, None when its device is no longer here.  The payload's timestamp is
        the time it is sent, its metrics' the time they were produced."""
        with self.lock:
            if not self.connected or self.stopping:
                return False
            dev = next((d for d in self.devices if d.device_id == device_id), None)
            if dev is None or dev.base != base or dev.dead:
                return None
            seq = self._next_seq()
            data = body + pb.encode(pb.Payload(timestamp=_now_ms(), seq=seq))
            self._publish_tracked(dev.topic["DDATA"], data, Held(serial, device_id, base, 0, (), body), seq)
            return True

    def _store_drained(self) -> None:
        """The store is empty again: the node metrics say so (NDATA)."""
        with self.lock:
            if self.connected and not self.stopping:
                now = _now_ms()
                self.send(self.topic["NDATA"], pb.Payload(now, self._store_metrics(now, named=False)))

    def _store_metrics(self, now: int, named: bool = True) -> tuple[pb.Metric, ...]:
        f = self.forwarder
        return (pb.Metric("Store/Pending" if named else None, 5, now, pb.UINT64, f.pending),
                pb.Metric("Store/Overflow" if named else None, 6, now, pb.UINT64, f.overflow))

    def births(self) -> None:
        """NBIRTH (seq 0) and every device's DBIRTH.  ``Node Control/Rebirth`` goes by
        name alone (tck-id-operational-behavior-data-commands-rebirth-name-aliases)."""
        with self.lock:
            self.seq = 0
            now = _now_ms()
            metrics = (pb.Metric("bdSeq", 1, now, pb.INT64, self.bd_seq),
                       pb.Metric(REBIRTH, None, now, pb.BOOLEAN, False),
                       pb.Metric("Node Info/Version", 3, now, pb.STRING, __version__),
                       pb.Metric("Node Info/Uptime", 4, now, pb.UINT64, int(time.monotonic() - self.started),
                                 properties=(("engUnit", (pb.STRING, "s")),)),
                       *self._store_metrics(now))
            self.send(self.topic["NBIRTH"], pb.Payload(now, metrics), birth=True)
            for d in self.devices:
                if not d.dead:
                    d.birth()

    # -- paho's thread ---------------------------------------------------------------------
    def _on_connect(self, client: Any, userdata: Any, flags: Any, reason: Any, properties: Any) -> None:
        if reason.is_failure:
            self.failures += 1
            self.last_error = str(reason)
            return
        self.connects += 1
        # QoS 1, each device's DCMD topic of its own (tck-id-message-flow-edge-node-ncmd-subscribe,
        # tck-id-message-flow-device-dcmd-subscribe)
        topics = [(self.topic["NCMD"], 1), *((d.topic["DCMD"], 1) for d in self.devices)]
        if not self.qos:
            topics.append((self.topic["ECHO"], 0))
        if self.state_topic is not None:
            topics.append((self.state_topic, 1))
        client.subscribe(topics)
        # What the last session left unacknowledged would be resent by paho before the
        # births: it goes through the store, as historical data, after them.
        client.drop_out_messages()
        with self.lock:
            self.session = True
            self._take_back()
            if self.state_topic is None:
                self._go_live()
            else:  # births once the primary host says it is online (its retained STATE)
                self.last_error = f"waiting for the primary host {self.options.primary_host_id}"

    def _go_live(self) -> None:
        """Births, then data (live, and what the store holds) (under the lock)."""
        self.births()
        self.connected = True
        self.forwarder.wake()

    def _on_connect_fail(self, client: Any, userdata: Any) -> None:
        """No connection at all (refused, unreachable): counted; paho tries again after
        its back-off."""
        self.failures += 1
        self.last_error = "connection failed (broker unreachable)"

    def _on_disconnect(self, client: Any, userdata: Any, flags: Any, reason: Any, properties: Any) -> None:
        with self.lock:
            was = self.session
            self.connected = self.session = self.host_online = False
            self._take_back()
            if self.stopping:
                return
            left, self._host_left = self._host_left, False
            if was and not left:  # (a refused CONNECT was counted by _on_connect)
                self.failures += 1
                self.last_error = str(reason)
            # A new session, a new death certificate: the next NBIRTH repeats it.
            self.bd_seq = (self.bd_seq + 1) & 0xFF
            self._set_will()
        if left:  # paho's thread ends after a DISCONNECT of ours: a new one connects again
            threading.Thread(target=self._connect_again, name="sparkplug-reconnect", daemon=True).start()

    def _on_message(self, client: Any, userdata: Any, message: Any) -> None:
        """An NCMD, a DCMD, a STATE or our own DDATA back (paho's thread): whatever it
        holds is counted and logged, never raised (an exception would end paho's
        network thread)."""
        try:
            self._message(message)
        except Exception as exc:  # noqa: BLE001 - a bug here must not end the connection
            self.bad_commands += 1
            self._bad("sparkplug_bad_command", str(message.topic), f"{type(exc).__name__}: {exc}")

    def _message(self, message: Any) -> None:
        topic = str(message.topic)
        if topic == self.state_topic:
            self._on_state(message.payload)
            return
        parts = topic.split("/")
        if parts[2] == "DDATA":
            self._echo(message.payload)
            return
        device = None
        if parts[2] == "DCMD":
            device = next((d for d in self.devices if d.device_id == parts[-1] and len(parts) == 5), None)
            if device is None:
                self.unknown_devices += 1
                self._bad("sparkplug_unknown_device", topic, "no such device on this edge node")
                return
        try:
            cmd = pb.decode(message.payload)
        except EskinError as exc:  # malformed: counted and dropped, never a crash
            self.bad_commands += 1
            self._bad("sparkplug_bad_command", topic, str(exc), device)
            return
        if device is not None:
            device.command(cmd, topic)
            return
        # by name: the NBIRTH gives it no alias
        rebirth = any(m.name == REBIRTH and m.value is True for m in cmd.metrics)
        if not rebirth:
            self.bad_commands += 1
            self._bad("sparkplug_bad_command", topic, f"expected {REBIRTH} = true")
            return
        self.rebirths += 1
        with self.lock:
            if self.connected and not self.stopping:
                self.births()

    def _on_state(self, data: bytes) -> None:
        """The primary host's STATE (Sparkplug 3.0: JSON ``{"online": bool, "timestamp":
        ms}``, retained): births when it comes online; when it goes offline, the NDEATH,
        a disconnect, and a new session that births once the host is back, its data
        held meanwhile (tck-id-message-flow-edge-node-birth-publish-phid-offline)."""
        try:
            state = json.loads(data)
            online, ts = state["online"], state["timestamp"]
            if not isinstance(online, bool) or not isinstance(ts, int) or isinstance(ts, bool):
                raise ValueError("expected a Boolean online and an integer timestamp")
        except (ValueError, KeyError, TypeError) as exc:
            self.bad_states += 1
            self._bad("sparkplug_bad_state", str(self.state_topic), f"{type(exc).__name__}: {exc}")
            return
        with self.lock:
            if ts < self._host_ts or self.stopping:
                return  # an older STATE than one already taken
            self._host_ts = ts
            was, self.host_online = self.host_online, online
            if online and not was:
                self._event("sparkplug_primary_host", "info", host=self.options.primary_host_id, online=1)
                if self.session:
                    self._go_live()  # a rebirth when it comes back
            elif not online and was:
                self._event("sparkplug_primary_host", "warning", host=self.options.primary_host_id, online=0)
                self.connected = False  # data is held until it is back
                self.last_error = f"primary host {self.options.primary_host_id} offline"
                if self.session:
                    self._leave_for_host()

    def _leave_for_host(self) -> None:
        """The primary host went offline during our Sparkplug session: NDEATH, then a
        clean DISCONNECT (the broker drops the will), then a new session (under the lock)."""
        self.host_sessions_ended += 1
        self._host_left = True
        self.client.publish(self.topic["NDEATH"], self._death(), qos=1)
        self.published += 1
        self.client.disconnect()

    def _connect_again(self) -> None:
        """After a DISCONNECT of ours: paho's network thread ends; start another one
        that connects again (a thread of its own: paho's cannot join itself)."""
        with self._life:
            if self.stopping:
                return
            self.client.loop_stop()
            reset = getattr(self.client, "_reset_sockets", None)
            if reset is not None:  # the ended thread's wake-up socket pair (loop_start makes another)
                reset(sockpair_only=True)
            self.client.connect_async(self.host, self.port, keepalive=self.options.keepalive_s)
            self.client.loop_start()

    def _bad(self, event: str, topic: str, error: str, device: SparkplugDevice | None = None) -> None:
        """One warning per event name and second at most (a flood of bad commands must
        not flood the log); the lines left out are counted in the next one."""
        now = time.monotonic()
        last, quiet = self._bad_logged.get(event, (float("-inf"), 0))
        if now - last < 1.0:
            self._bad_logged[event] = (last, quiet + 1)
            return
        self._bad_logged[event] = (now, 0)
        target = device if device is not None else (self.devices[0] if self.devices else None)
        if target is not None:
            target._event(event, "warning", topic=topic, error=error, not_logged=quiet)

    # -- life ----------------------------------------------------------------------------
    def start(self) -> EdgeNode:
        for line in self.nonconforming():
            self._event("sparkplug_nonconforming", "warning", what=line)
        self.forwarder.start()
        with self._life:
            self.client.connect_async(self.host, self.port, keepalive=self.options.keepalive_s)
            self.client.loop_start()
        return self

    def wait_connected(self, timeout_s: float) -> bool:
        deadline = time.monotonic() + timeout_s
        while not self.connected and time.monotonic() < deadline:
            time.sleep(0.01)
        return self.connected

    def close(self, timeout_s: float = 2.0) -> None:
        """Every device's DDEATH, then NDEATH, then a clean disconnect (no will)."""
        with self.lock:
            if self.stopping:
                return
            self.stopping = True  # the forwarder sends nothing more
        self.forwarder.stop()
        with self.lock:
            for d in self.devices:
                d.death()
            info = None
            if self.session:
                info = self.client.publish(self.topic["NDEATH"], self._death(), qos=1)
                self.published += 1
        if info is not None:
            try:
                info.wait_for_publish(timeout_s)
            except (RuntimeError, ValueError):
                pass
        with self._life:
            self.client.disconnect()
            self.client.loop_stop()
        # paho's loop_start opens a socket pair to wake its thread, and loop_stop leaves it
        # open until the client is collected (a ResourceWarning then): close it now.
        reset = getattr(self.client, "_reset_sockets", None)
        if reset is not None:
            reset()
        with self.lock:
            self._take_back()
        self.forwarder.close()  # what is held stays on disk for the next start

    def counters(self) -> dict[str, int]:
        f = self.forwarder
        return {"sparkplug_published": self.published, "sparkplug_dropped": self.dropped,
                "sparkplug_connects": self.connects, "sparkplug_failures": self.failures,
                "sparkplug_bad_commands": self.bad_commands, "sparkplug_rebirths": self.rebirths,
                "sparkplug_store_held": f.held, "sparkplug_store_pending": f.pending,
                "sparkplug_store_overflow": f.overflow, "sparkplug_store_forwarded": f.forwarded,
                "sparkplug_store_discarded": f.discarded, "sparkplug_store_failures": f.failures,
                "sparkplug_resent": self.resent, "sparkplug_unconfirmed": self.unconfirmed,
                "sparkplug_commands": self.commands,
                "sparkplug_commands_refused": self.commands_refused, "sparkplug_unknown_devices": self.unknown_devices,
                "sparkplug_bad_states": self.bad_states, "sparkplug_host_online": int(self.host_online),
                "sparkplug_host_sessions_ended": self.host_sessions_ended}


def nonconforming(options: SparkplugOptions, bd_error: str | None, bd_file: str) -> list[str]:
    """What a run with these options does against the specification, one line each."""
    out = []
    if options.nonconforming_qos1:
        out.append("nonconforming_qos1: NBIRTH, DBIRTH, NDATA, DDATA and DDEATH go at QoS 1; Sparkplug requires "
                   "QoS 0 and a strict host may reject the edge node")
    if bd_error is not None:
        out.append(f"bdSeq is not kept across restarts ({bd_file}: {bd_error}): each start begins again at 0, "
                   "where Sparkplug goes on from the previous CONNECT; give store_dir a writable folder")
    return out


class SparkplugDevice(Sink):
    """One sensor node as a Sparkplug device of the edge node (opened by :class:`SparkplugKind`)."""

    def __init__(self, node: EdgeNode, device_id: str, index: int,
                 properties: dict[str, tuple[Property, ...]] | None = None) -> None:
        super().__init__()
        self.node = node
        self.device_id = device_id
        self.where = f"mqtt {node.host}:{node.port} {node.options.group_id}/{node.options.edge_node_id}/{device_id}"
        g, e = node.options.group_id, node.options.edge_node_id
        self.topic = {k: f"{NAMESPACE}/{g}/{k}/{e}/{device_id}" for k in ("DBIRTH", "DDATA", "DDEATH", "DCMD")}
        self.base = 1000 * (index + 1)
        #: Metric name -> DBIRTH properties beyond its unit (the layout, the method).
        self.properties = properties or {}
        self.current: tuple[Any, ...] | None = None  #: the newest values (births declare them)
        self.sent: list[Any] = [None] * len(DEVICE_METRICS)  #: the values last sent, per metric
        self.sent_at = [float("-inf")] * len(DEVICE_METRICS)
        self.dead = False
        self.snapshot: NodeSnapshot | None = None  #: the newest published (for a command's refusal)
        self._commands: collections.deque[Command] = collections.deque()
        self.frame_every_s = node.options.frame_interval_s or None
        self.frame: bytes | None = None  #: the newest frame handed, packed (births declare it)
        self.frame_sent: bytes | None = None  #: the frame last sent (a DBIRTH or a DDATA)
        self.frames = self.frames_not_sent = self.frames_lost = 0

    def command(self, payload: pb.Payload, topic: str) -> None:
        """A DCMD for this device (paho's thread): queued for the loop, or refused as a
        whole under the PLC's rule, or counted as malformed."""
        node = self.node
        try:
            cmds = parse_device_command(payload, self.base)
        except BadCommand as exc:
            node.bad_commands += 1
            node._bad("sparkplug_bad_command", topic, str(exc), self)
            return
        snapshot = self.snapshot
        for cmd in cmds:
            why = refusal(cmd, snapshot)
            if why is not None:
                node.commands_refused += 1
                self._logged("sparkplug_command_refused", "warning", command=cmd.name, reason=why)
                return
        node.commands += len(cmds)
        self._commands.extend(cmds)
        self._logged("sparkplug_command", "info", commands=",".join(c.name for c in cmds))

    def _logged(self, name: str, level: str, **fields: Any) -> None:
        """A DCMD's line: at most one per name per LOG_EVERY_S (a host may send them as
        fast as the broker goes), the next saying how many were held back; the
        counters count every one."""
        held = self.node.commands_logged.passes((self.device_id, name))
        if held is not None:
            self._event(name, level, held_back=held, **fields)

    def source_ended(self, error: str) -> None:
        """The node's source is gone while the bridge goes on: DDEATH (its last
        publication, with Bus Fault when it failed, went before)."""
        self.death()

    def take_commands(self) -> list[Command]:
        out = []
        commands = self._commands
        while commands:
            out.append(commands.popleft())
        return out

    def birth(self) -> None:
        """DBIRTH: every metric with name, alias, datatype, unit and its newest value."""
        now = _now_ms()
        values = self.current
        metrics = []
        for i, m in enumerate(DEVICE_METRICS):
            props = ((("engUnit", (pb.STRING, m.unit)),) if m.unit else ()) + self.properties.get(m.name, ())
            value = None if values is None else values[i]
            metrics.append(pb.Metric(m.name, self.base + i, now, m.datatype, value, is_null=True if value is None
                                     else None, properties=props))
        if self.frame_every_s is not None:
            m = FRAME_METRIC
            frame = self.frame
            self.frame_sent = frame
            metrics.append(pb.Metric(m.name, self.base + FRAME_ALIAS, now, m.datatype, frame,
                                     is_null=True if frame is None else None,
                                     properties=(("engUnit", (pb.STRING, m.unit)), *self.properties.get(m.name, ()))))
        metrics += birth_metrics(self.base, now, None if values is None else values[_ENABLED])
        self.sent = list(values) if values is not None else [None] * len(DEVICE_METRICS)
        self.sent_at = [time.monotonic()] * len(DEVICE_METRICS)
        self.node.send(self.topic["DBIRTH"], pb.Payload(now, tuple(metrics)), birth=True)

    def death(self) -> None:
        with self.node.lock:
            if self.dead:
                return
            self.dead = True
            if self.node.connected:
                self.node.send(self.topic["DDEATH"], pb.Payload(_now_ms()))

    def _publish(self, snapshot: NodeSnapshot) -> None:
        if snapshot.offline:
            self.death()
            return
        self.snapshot = snapshot
        values = metric_values(snapshot)
        now = time.monotonic()
        node = self.node
        with node.lock:
            self.current = values
            if self.dead:
                return
            sent, sent_at = self.sent, self.sent_at
            changed = [i for i, v in enumerate(values) if v != sent[i] and not _ANALOG[i]]
            interval = node.options.min_interval_s
            for i, v in enumerate(values):
                if not _ANALOG[i] or v == sent[i] or (now - sent_at[i] < interval and not changed):
                    continue
                if _FLOATS[i] and sent[i] is not None and abs(v - sent[i]) <= node.options.deadband:
                    continue
                changed.append(i)
            if not changed:
                return
            ms = _now_ms()
            metrics = []
            for i in sorted(changed):
                sent[i], sent_at[i] = values[i], now
                metrics.append(pb.Metric(None, self.base + i, ms, DEVICE_METRICS[i].datatype, values[i]))
            if _ENABLED in changed:
                metrics.append(pb.Metric(None, self.base + _ENABLE_COMMAND, ms, pb.BOOLEAN, values[_ENABLED]))
            node.send_data(self, ms, tuple(metrics))

    def on_frame(self, frame: Frame) -> None:
        """A frame the loop found due: packed (little-endian float32, the one copy) and
        sent by alias, not subject to the deadband."""
        self.node.send_frame(self, frame.forces.astype("<f4").tobytes())

    def health(self) -> SinkHealth:
        return SinkHealth(self.node.connected, self.node.failures, self.node.last_error)

    def counters(self) -> dict[str, int]:
        out = self.node.counters()
        if self.frame_every_s is not None:
            out["sparkplug_frames"] = self.frames
            out["sparkplug_frames_not_sent"] = self.frames_not_sent
            out["sparkplug_frames_lost"] = self.frames_lost
        return out

    def _close(self) -> None:
        self.death()


class SparkplugKind(OutputKind[SparkplugOptions]):
    """The output kind "sparkplug": one edge node for the bridge, one
    :class:`SparkplugDevice` per node."""

    name = "sparkplug"
    Options = SparkplugOptions
    cli_options = (
        CliOption("--sparkplug", "sparkplug", "Publish as a Sparkplug B edge node to this MQTT broker "
                  "(mqtt://HOST:PORT, or mqtts:// for TLS); needs --group-id and --edge-node-id.", metavar="URL"),
        CliOption("--group-id", "group_id", "Sparkplug group id (with --sparkplug).", metavar="ID"),
        CliOption("--edge-node-id", "edge_node_id", "Sparkplug edge node id (with --sparkplug).", metavar="ID"),
        CliOption("--sparkplug-nonconforming-qos1", "sparkplug_nonconforming_qos1", "Publish births, data and "
                  "DDEATH at MQTT QoS 1, against the specification's QoS 0 (a strict host may reject the node).",
                  type=bool),
        CliOption("--sparkplug-keepalive", "sparkplug_keepalive_s", "MQTT keepalive, seconds.", type=int,
                  metavar="S"),
        CliOption("--sparkplug-deadband", "sparkplug_deadband", "An analog metric is sent when it moved by more "
                  "than this, in its own unit (default 0.01).", type=float, metavar="X"),
        CliOption("--sparkplug-min-interval", "sparkplug_min_interval_s", "An analog metric is sent at most this "
                  "often, seconds (default 0.5; a state change goes at once).", type=float, metavar="S"),
        CliOption("--sparkplug-reconnect-min", "sparkplug_reconnect_min_s", "Back-off between connection "
                  "attempts, from this (seconds, default 0.2) ...", type=float, metavar="S"),
        CliOption("--sparkplug-reconnect-max", "sparkplug_reconnect_max_s", "... doubling up to this (seconds, "
                  "default 5).", type=float, metavar="S"),
        CliOption("--sparkplug-frame-interval", "sparkplug_frame_interval_s", "Publish each node's calibrated "
                  "taxel frame (metric Taxels/Frame, a FloatArray) at most this often, seconds (default 0: off).",
                  type=float, metavar="S"),
        CliOption("--sparkplug-store-dir", "sparkplug_store_dir", "Folder of the on-disk queue of the data "
                  "messages of a broker outage (default: in memory).", metavar="DIR"),
        CliOption("--sparkplug-store-max", "sparkplug_store_max", "Data messages held at most during an "
                  "outage (the rest are counted).", type=int, metavar="N"),
        CliOption("--sparkplug-ca-file", "sparkplug_ca_file", "mqtts: CA certificates (PEM) of the broker's "
                  "certificate (default: the system's).", metavar="FILE"),
        CliOption("--sparkplug-cert-file", "sparkplug_cert_file", "mqtts: client certificate (PEM), with "
                  "--sparkplug-key-file.", metavar="FILE"),
        CliOption("--sparkplug-key-file", "sparkplug_key_file", "mqtts: the client certificate's key (PEM).",
                  metavar="FILE"),
        CliOption("--sparkplug-primary-host", "sparkplug_primary_host_id", "Publish only while this Sparkplug "
                  "primary host application is online (its STATE topic).", metavar="ID"),
        CliOption("--sparkplug-username", "sparkplug_username", "MQTT username.", metavar="NAME"),
        CliOption("--sparkplug-password-file", "sparkplug_password_file", "MQTT password: the first line of "
                  "this file (no password option takes the secret itself).", metavar="FILE"),
        CliOption("--sparkplug-password-env", "sparkplug_password_env", "MQTT password: this environment "
                  "variable.", metavar="NAME"),
    )
    #: ``--sparkplug-*`` option -> the ``[sparkplug]`` key it sets.
    _CLI_KEYS = {"sparkplug_nonconforming_qos1": "nonconforming_qos1", "sparkplug_keepalive_s": "keepalive_s",
                 "sparkplug_deadband": "deadband", "sparkplug_min_interval_s": "min_interval_s",
                 "sparkplug_reconnect_min_s": "reconnect_min_s", "sparkplug_reconnect_max_s": "reconnect_max_s",
                 "sparkplug_frame_interval_s": "frame_interval_s",
                 "sparkplug_store_dir": "store_dir", "sparkplug_store_max": "store_max",
                 "sparkplug_ca_file": "ca_file", "sparkplug_cert_file": "cert_file", "sparkplug_key_file": "key_file",
                 "sparkplug_username": "username", "sparkplug_primary_host_id": "primary_host_id", "sparkplug_password_file": "password_file",
                 "sparkplug_password_env": "password_env"}

    @classmethod
    def options_from_cli(cls, values: dict[str, Any]) -> SparkplugOptions | None:
        url = values.get("sparkplug")
        # (a flag not given reads False: not given either)
        extra = {key: values[dest] for dest, key in cls._CLI_KEYS.items() if values.get(dest) not in (None, False)}
        if url is None:
            given = [o.flag for o in cls.cli_options[1:] if values.get(o.dest) not in (None, False)]
            if given:
                raise ValueError(f"{'/'.join(given)}: give --sparkplug URL too")
            return None
        if not values.get("group_id") or not values.get("edge_node_id"):
            raise ValueError("give --group-id and --edge-node-id with --sparkplug")
        flags = {cls._CLI_KEYS[o.dest]: o.flag for o in cls.cli_options if o.dest in cls._CLI_KEYS}
        try:
            return build(SparkplugOptions, {"broker": url, "group_id": values["group_id"],
                                            "edge_node_id": values["edge_node_id"], **extra})
        except SchemaError as exc:  # the flag, not the key, in the one line
            raise ValueError(f"{flags.get(exc.key, exc.key)}: {exc.message}") from None
        except ValueError as exc:  # a rule across keys: named by its first key
            key, sep, rest = str(exc).partition(": ")
            raise ValueError(f"{flags[key]}: {rest}" if sep and key in flags else str(exc)) from None

    @classmethod
    def describe(cls, options: SparkplugOptions, node: NodeLike[Any]) -> str:
        host, port, _ = parse_broker(options.broker)
        frames = (f", {FRAME_METRIC.name} every {options.frame_interval_s:g} s ({node.profile.layout.rows} x "
                  f"{node.profile.layout.cols})" if options.frame_interval_s else "")
        return (f"Sparkplug B {NAMESPACE}/{options.group_id}/DDATA/{options.edge_node_id}/{node.name} at "
                f"{host}:{port}{frames}")

    @classmethod
    def check(cls, options: SparkplugOptions, nodes: Sequence[NodeLike[Any]]) -> None:
        seen: dict[str, str] = {}
        for n in nodes:
            check_id("device id (node name)", n.name)
            other = seen.setdefault(n.name.lower(), n.name)
            if other != n.name:  # tck-id-case-sensitivity-sparkplug-ids: a host may fold case
                raise ValueError(f"device id (node name): {n.name!r} and {other!r} differ only in case")
        check_files(options)
        if options.store_dir is not None:
            d = Path(options.store_dir)
            while not d.exists() and d != d.parent:  # created at open: its first existing parent
                d = d.parent
            if not d.is_dir() or not os.access(d, os.W_OK | os.X_OK):
                raise ValueError(f"store_dir: {options.store_dir!r}: {str(d)!r} is not a writable folder")

    @classmethod
    def probe(cls, options: SparkplugOptions, nodes: Sequence[NodeLike[Any]]) -> None:
        """``--check``: a warning line for each departure from the specification that
        the run will make (the run logs the same as ``sparkplug_nonconforming``)."""
        path = bdseq_path(options.store_dir, options.group_id, options.edge_node_id)
        for line in nonconforming(options, writable(path), str(path)):
            sys.stderr.write(f"eskin-bus: warning: [sparkplug] {line}\n")

    @classmethod
    def _open_nodes(cls, options: SparkplugOptions, nodes: Sequence[NodeLike[Any]], context: OpenContext) -> list[Sink]:
        edge = open_edge(options, [(n.name, {METHOD_METRIC: method_properties(n.profile),
                                     LAYOUT_METRIC: layout_properties(n.profile),
                                     FRAME_METRIC.name: frame_properties(n.profile, options.frame_interval_s),
                                     **score_properties(n.profile)})
                                   for n in nodes])
        context.closers.append(edge.close)  # closers run last first: the devices' DDEATH, then NDEATH
        for dev in edge.devices:
            context.closers.append(dev.close)
        edge.start()
        return list(edge.devices)


def open_edge(options: SparkplugOptions, devices: Sequence[tuple[str, dict[str, tuple[Property, ...]]]]
              ) -> EdgeNode:
    """An edge node (not started) with one device per ``(name, properties)``."""
    try:
        import paho.mqtt.client as mqtt
    except ImportError:  # pragma: no cover - a runtime dependency
        from ...errors import MissingExtra

        # a dependency of the package itself: only a damaged install lacks it
        raise MissingExtra("the sparkplug output needs paho-mqtt: pip install 'paho-mqtt>=2.1,<2.3'") from None
    client = mqtt.Client(callback_api_version=mqtt.CallbackAPIVersion.VERSION2,
                         client_id=f"{options.group_id}-{options.edge_node_id}", clean_session=True)
    try:
        configure(client, options)
    except ValueError as exc:  # a password file emptied since --check
        raise ProfileError(f"[sparkplug] {exc}") from None
    edge = EdgeNode(options, client)
    for i, (name, props) in enumerate(devices):
        edge.devices.append(SparkplugDevice(edge, name, i, props))
    return edge


_TYPE_NAMES = {pb.INT8: "Int8", pb.INT16: "Int16", pb.INT32: "Int32", pb.INT64: "Int64", pb.UINT8: "UInt8",
               pb.UINT16: "UInt16", pb.UINT32: "UInt32", pb.UINT64: "UInt64", pb.FLOAT: "Float",
               pb.DOUBLE: "Double", pb.BOOLEAN: "Boolean", pb.STRING: "String", pb.FLOAT_ARRAY: "FloatArray"}


def metric_table() -> list[str]:
    """The device metric table of ``docs/plant.md`` (Markdown lines), from :data:`DEVICE_METRICS`."""
    rows = ["| alias | metric | datatype | unit | sent | meaning |", "|---|---|---|---|---|---|"]
    for i, m in enumerate(DEVICE_METRICS):
        sent = "deadband, min interval" if m.analog else "at once"
        rows.append(f"| base+{i} | `{m.name}` | {_TYPE_NAMES[m.datatype]} | {m.unit or '-'} | {sent} | {m.doc} |")
    m = FRAME_METRIC
    rows.append(f"| base+{FRAME_ALIAS} | `{m.name}` | {_TYPE_NAMES[m.datatype]} | {m.unit} | "
                f"every `frame_interval_s` (0: not declared) | {m.doc} |")
    for i, c in enumerate(COMMANDS):
        sent = "DBIRTH and DDATA (as `Enabled`); DCMD" if c.on_false is not None else "DBIRTH (false); DCMD"
        rows.append(f"| base+{COMMAND_ALIAS + i} | `{c.name}` | Boolean | - | {sent} | {c.doc} |")
    return rows
