"""Sparkplug B 3.0 on MQTT as an output kind (``[sparkplug]`` in the bridge
configuration, ``--sparkplug mqtt://HOST:PORT`` on the command line).

The bridge process is one edge node (``group_id``, ``edge_node_id``) over one MQTT
connection; each sensor node is a device named after the node.  The metrics are the
register image as the PLC reads it (:func:`~eskin_industrial.plc.image.decode_registers`
of each publication), so that the plant and the PLC see the same state.

The loop's thread only encodes and enqueues: paho-mqtt's network thread
(``loop_start``) writes to the broker, reconnects, and calls back on connect (births)
and on an NCMD (rebirth).  One lock orders the ``seq`` numbers with the messages.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, NamedTuple
from urllib.parse import urlsplit

from .. import __version__
from ..detect.state import LABELS
from ..errors import EskinError
from ..plc.image import Status, decode_registers
from ..netaddr import check_host
from ..schema import in_range
from ..sinks.base import CliOption, Publication, Sink, SinkHealth
from . import payload as pb

if TYPE_CHECKING:
    from ..bus.source import NodeLike, OpenContext

NAMESPACE = "spBv1.0"
REBIRTH = "Node Control/Rebirth"
_FORBIDDEN = set("+#/")


def parse_broker(url: str) -> tuple[str, int]:
    """``mqtt://HOST[:PORT]`` -> (host, port); ValueError, one line, when malformed."""
    parts = urlsplit(url)
    try:
        port = parts.port
    except ValueError:
        port = -1
    if parts.scheme != "mqtt" or not parts.hostname or port in (-1, 0) or parts.path not in ("", "/"):
        raise ValueError(f"expected mqtt://HOST:PORT, got {url!r}")
    check_host(parts.hostname, "broker host")  # the one host parser (999.1.1.1 is refused here, not retried)
    return parts.hostname, port or 1883


def check_id(key: str, value: str) -> None:
    if not value or _FORBIDDEN & set(value):
        raise ValueError(f"{key}: {value!r} is not a Sparkplug id (not empty, no '+', '#' or '/')")


@dataclass(frozen=True)
class SparkplugOptions:
    """``[sparkplug]``: the broker and this edge node's ids, and report by exception."""

    broker: str  #: ``mqtt://HOST:PORT``
    group_id: str
    edge_node_id: str
    qos: int = field(default=0, metadata=in_range(0, 1))
    keepalive_s: int = field(default=30, metadata=in_range(5, 3600))
    #: An analog value is published when it moved by more than this (its own unit).
    deadband: float = field(default=0.01, metadata=in_range(0, 1e9))
    #: An analog value is published at most this often (a state change goes at once).
    min_interval_s: float = field(default=0.5, metadata=in_range(0, 3600))

    def __post_init__(self) -> None:
        parse_broker(self.broker)
        check_id("group_id", self.group_id)
        check_id("edge_node_id", self.edge_node_id)


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
    MetricDef("R_coe", pb.FLOAT, "", True, "decorrelation indicator (R_COE / r_scale)"),
    MetricDef("R_dw", pb.FLOAT, "", True, "wavelet indicator (R_DW / r_scale)"),
    MetricDef("Total Force", pb.FLOAT, "N", True, "total force of the newest frame"),
    MetricDef("CoF X", pb.FLOAT, "mm", True, "centre of force, x"),
    MetricDef("CoF Y", pb.FLOAT, "mm", True, "centre of force, y"),
    MetricDef("Frame Age", pb.UINT32, "ms", True, "age of the newest frame, 65535 = none"),
    MetricDef("Counters/Slip Events", pb.UINT32, "count", True, "entries into slip since start"),
    MetricDef("Counters/State Changes", pb.UINT32, "count", True, "state changes since start"),
    MetricDef("Counters/Lost Scans", pb.UINT32, "count", True, "failed polls and sequence gaps"),
    MetricDef("Counters/Bus Errors", pb.UINT32, "count", True, "timeouts, CRC and exception responses"),
)
_ANALOG = tuple(m.analog for m in DEVICE_METRICS)
_FLOATS = tuple(m.datatype == pb.FLOAT for m in DEVICE_METRICS)
#: Node metrics (aliases 1..); a device's metrics start at 1000 x (its index + 1).
NODE_METRICS = ("bdSeq", REBIRTH, "Node Info/Version", "Node Info/Uptime")


def metric_values(pub: Publication, r_scale: float, word_order: str) -> tuple[Any, ...]:
    """The device metrics of one publication, from the registers as the PLC reads them."""
    v = decode_registers(pub.registers, word_order)  # type: ignore[arg-type]
    st = v["STATUS"]
    return (LABELS[v["STATE"]] if v["STATE"] < len(LABELS) else str(v["STATE"]), v["STATE"],
            bool(st & Status.SLIP), bool(st & Status.SLIP_LATCHED), bool(st & Status.DATA_VALID),
            bool(st & Status.SENSOR_STALE), bool(st & Status.BUS_FAULT), bool(st & Status.CONTACT),
            bool(st & Status.ENABLED), v["R_COE"] / r_scale, v["R_DW"] / r_scale, v["F_SUM"] / 1000.0,
            v["XC"] / 100.0, v["YC"] / 100.0, v["FRAME_AGE"], v["SLIP_EVENTS"], v["STATE_CHANGES"],
            v["LOST_SCANS"], v["BUS_ERRORS"])


def _now_ms() -> int:
    return int(time.time() * 1000)


class EdgeNode:
    """One MQTT connection, the edge node's births and deaths, ``seq`` and ``bdSeq``."""

    def __init__(self, options: SparkplugOptions, client_factory: Any) -> None:
        self.options = options
        self.host, self.port = parse_broker(options.broker)
        g, e = options.group_id, options.edge_node_id
        self.topic = {kind: f"{NAMESPACE}/{g}/{kind}/{e}" for kind in ("NBIRTH", "NDEATH", "NDATA", "NCMD")}
        self.devices: list[SparkplugDevice] = []
        self.lock = threading.RLock()
        self.seq = 0
        self.bd_seq = 0
        self.started = time.monotonic()
        self.connected = False
        self.stopping = False
        self.published = self.dropped = self.connects = self.failures = self.bad_commands = self.rebirths = 0
        self.last_error = ""
        self.client = client_factory
        self.client.on_connect = self._on_connect
        self.client.on_disconnect = self._on_disconnect
        self.client.on_message = self._on_message
        self.client.reconnect_delay_set(0.2, 5)
        self._set_will()

    # -- messages -----------------------------------------------------------------------
    def _death(self) -> bytes:
        return pb.encode(pb.Payload(_now_ms(), (pb.Metric("bdSeq", None, None, pb.INT64, self.bd_seq),)))

    def _set_will(self) -> None:
        self.client.will_set(self.topic["NDEATH"], self._death(), qos=1, retain=False)

    def _next_seq(self) -> int:
        s = self.seq
        self.seq = (s + 1) & 0xFF
        return s

    def send(self, topic: str, payload: pb.Payload, *, seq: bool = True) -> None:
        """Stamp ``seq`` and enqueue (under the lock: the wire order is the seq order)."""
        with self.lock:
            if seq:
                payload = pb.Payload(payload.timestamp, payload.metrics, self._next_seq())
            info = self.client.publish(topic, pb.encode(payload), qos=self.options.qos)
            if info.rc == 0:
                self.published += 1
            else:
                self.dropped += 1

    def births(self) -> None:
        """NBIRTH (seq 0) and every device's DBIRTH."""
        with self.lock:
            self.seq = 0
            now = _now_ms()
            metrics = (pb.Metric("bdSeq", 1, now, pb.INT64, self.bd_seq),
                       pb.Metric(REBIRTH, 2, now, pb.BOOLEAN, False),
                       pb.Metric("Node Info/Version", 3, now, pb.STRING, __version__),
                       pb.Metric("Node Info/Uptime", 4, now, pb.UINT64, int(time.monotonic() - self.started),
                                 properties=(("engUnit", (pb.STRING, "s")),)))
            self.send(self.topic["NBIRTH"], pb.Payload(now, metrics))
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
        client.subscribe(self.topic["NCMD"], qos=1)
        with self.lock:
            self.births()
            self.connected = True

    def _on_disconnect(self, client: Any, userdata: Any, flags: Any, reason: Any, properties: Any) -> None:
        with self.lock:
            self.connected = False
            if self.stopping:
                return
            self.failures += 1
            self.last_error = str(reason)
            # A new session, a new death certificate: the next NBIRTH repeats it.
            self.bd_seq = (self.bd_seq + 1) & 0xFF
            self._set_will()

    def _on_message(self, client: Any, userdata: Any, message: Any) -> None:
        try:
            cmd = pb.decode(message.payload)
        except EskinError:  # malformed: counted and dropped, never a crash
            self.bad_commands += 1
            return
        rebirth = any((m.name == REBIRTH or m.alias == 2) and m.value is True for m in cmd.metrics)
        if not rebirth:
            self.bad_commands += 1
            return
        self.rebirths += 1
        with self.lock:
            if self.connected:
                self.births()

    # -- life ----------------------------------------------------------------------------
    def start(self) -> EdgeNode:
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
            for d in self.devices:
                d.death()
            info = None
            if self.connected:
                info = self.client.publish(self.topic["NDEATH"], self._death(), qos=1)
                self.published += 1
            self.stopping = True
        if info is not None:
            try:
                info.wait_for_publish(timeout_s)
            except (RuntimeError, ValueError):
                pass
        self.client.disconnect()
        self.client.loop_stop()

    def counters(self) -> dict[str, int]:
        return {"sparkplug_published": self.published, "sparkplug_dropped": self.dropped,
                "sparkplug_connects": self.connects, "sparkplug_failures": self.failures,
                "sparkplug_bad_commands": self.bad_commands, "sparkplug_rebirths": self.rebirths}


class SparkplugDevice(Sink):
    """One sensor node as a Sparkplug device of the edge node."""

    kind = "sparkplug"
    Options = SparkplugOptions
    cli_options = (
        CliOption("--sparkplug", "sparkplug", "Publish as a Sparkplug B edge node to this MQTT broker "
                  "(mqtt://HOST:PORT); needs --group-id and --edge-node-id.", metavar="URL"),
        CliOption("--group-id", "group_id", "Sparkplug group id (with --sparkplug).", metavar="ID"),
        CliOption("--edge-node-id", "edge_node_id", "Sparkplug edge node id (with --sparkplug).", metavar="ID"),
    )

    def __init__(self, node: EdgeNode, device_id: str, index: int, r_scale: float, word_order: str) -> None:
        super().__init__()
        self.node = node
        self.device_id = device_id
        self.where = f"mqtt {node.host}:{node.port} {node.options.group_id}/{node.options.edge_node_id}/{device_id}"
        g, e = node.options.group_id, node.options.edge_node_id
        self.topic = {k: f"{NAMESPACE}/{g}/{k}/{e}/{device_id}" for k in ("DBIRTH", "DDATA", "DDEATH")}
        self.base = 1000 * (index + 1)
        self.r_scale, self.word_order = r_scale, word_order
        self.current: tuple[Any, ...] | None = None  #: the newest values (births declare them)
        self.sent: list[Any] = [None] * len(DEVICE_METRICS)  #: the values last sent, per metric
        self.sent_at = [float("-inf")] * len(DEVICE_METRICS)
        self.dead = False

    def birth(self) -> None:
        """DBIRTH: every metric with name, alias, datatype, unit and its newest value."""
        now = _now_ms()
        values = self.current
        metrics = []
        for i, m in enumerate(DEVICE_METRICS):
            props = (("engUnit", (pb.STRING, m.unit)),) if m.unit else ()
            value = None if values is None else values[i]
            metrics.append(pb.Metric(m.name, self.base + i, now, m.datatype, value, is_null=True if value is None
                                     else None, properties=props))
        self.sent = list(values) if values is not None else [None] * len(DEVICE_METRICS)
        self.sent_at = [time.monotonic()] * len(DEVICE_METRICS)
        self.node.send(self.topic["DBIRTH"], pb.Payload(now, tuple(metrics)))

    def death(self) -> None:
        with self.node.lock:
            if self.dead:
                return
            self.dead = True
            if self.node.connected:
                self.node.send(self.topic["DDEATH"], pb.Payload(_now_ms()))

    def _publish(self, publication: Publication) -> None:
        if publication.offline:
            self.death()
            return
        values = metric_values(publication, self.r_scale, self.word_order)
        now = time.monotonic()
        node = self.node
        with node.lock:
            self.current = values
            if not node.connected or self.dead:
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
                metrics.append(pb.Metric(None, self.base + i, None, DEVICE_METRICS[i].datatype, values[i]))
            node.send(self.topic["DDATA"], pb.Payload(ms, tuple(metrics)))

    def health(self) -> SinkHealth:
        return SinkHealth(self.node.connected, self.node.failures, self.node.last_error)

    def counters(self) -> dict[str, int]:
        return self.node.counters()

    def _close(self) -> None:
        self.death()

    # -- the kind ----------------------------------------------------------------------
    @classmethod
    def options_from_cli(cls, values: dict[str, Any]) -> SparkplugOptions | None:
        url = values.get("sparkplug")
        if url is None:
            if values.get("group_id") is not None or values.get("edge_node_id") is not None:
                raise ValueError("--group-id/--edge-node-id: give --sparkplug URL too")
            return None
        if not values.get("group_id") or not values.get("edge_node_id"):
            raise ValueError("give --group-id and --edge-node-id with --sparkplug")
        return SparkplugOptions(url, values["group_id"], values["edge_node_id"])

    @classmethod
    def describe(cls, options: SparkplugOptions, node: NodeLike) -> str:
        host, port = parse_broker(options.broker)
        return f"Sparkplug B {NAMESPACE}/{options.group_id}/DDATA/{options.edge_node_id}/{node.name} at {host}:{port}"

    @classmethod
    def check(cls, options: SparkplugOptions, nodes: Sequence[NodeLike]) -> None:
        for n in nodes:
            check_id("device id (node name)", n.name)

    @classmethod
    def open_nodes(cls, options: SparkplugOptions, nodes: Sequence[NodeLike], context: OpenContext) -> list[Sink]:
        try:
            import paho.mqtt.client as mqtt
        except ImportError:  # pragma: no cover - a runtime dependency
            from ..errors import MissingExtra

            # a dependency of the package itself: only a damaged install lacks it
            raise MissingExtra("the sparkplug output needs paho-mqtt: pip install 'paho-mqtt>=2.1,<2.3'") from None
        client = mqtt.Client(callback_api_version=mqtt.CallbackAPIVersion.VERSION2,
                             client_id=f"{options.group_id}-{options.edge_node_id}", clean_session=True)
        edge = EdgeNode(options, client)
        context.closers.append(edge.close)  # closers run last first: the devices' DDEATH, then NDEATH
        sinks: list[Sink] = []
        for i, n in enumerate(nodes):
            plc = n.profile.modbus.plc
            dev = cls(edge, n.name, i, plc.r_scale, plc.word_order)
            edge.devices.append(dev)
            context.closers.append(dev.close)
            sinks.append(dev)
        edge.start()
        return sinks


_TYPE_NAMES = {pb.INT8: "Int8", pb.INT16: "Int16", pb.INT32: "Int32", pb.INT64: "Int64", pb.UINT8: "UInt8",
               pb.UINT16: "UInt16", pb.UINT32: "UInt32", pb.UINT64: "UInt64", pb.FLOAT: "Float",
               pb.DOUBLE: "Double", pb.BOOLEAN: "Boolean", pb.STRING: "String"}


def metric_table() -> list[str]:
    """The device metric table of ``docs/plant.md`` (Markdown lines), from :data:`DEVICE_METRICS`."""
    rows = ["| alias | metric | datatype | unit | sent | meaning |", "|---|---|---|---|---|---|"]
    for i, m in enumerate(DEVICE_METRICS):
        sent = "deadband, min interval" if m.analog else "at once"
        rows.append(f"| base+{i} | `{m.name}` | {_TYPE_NAMES[m.datatype]} | {m.unit or '-'} | {sent} | {m.doc} |")
    return rows
