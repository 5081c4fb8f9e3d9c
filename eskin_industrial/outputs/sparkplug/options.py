"""The Sparkplug output's settings (``[sparkplug]`` of the bridge configuration, or
``--sparkplug`` and its options), the ids' rules, and what a run with them departs
from in the specification."""

from __future__ import annotations

import unicodedata
from dataclasses import dataclass, field

from ...schema import in_range
from .transport import check_security

FRAME_INTERVAL_MIN_S = 0.05
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
    #: A primary host's STATE stamped more than this ahead of this node's clock is
    #: refused (counted, logged): taken, it would make every genuine STATE after it
    #: look older, and the node would wait for its host until restarted.  A minute
    #: covers the clocks of a plant kept by NTP; a host further off is the fault.
    state_future_s: float = field(default=60.0, metadata=in_range(0, 86400))
    #: Node Control/Rebirth: at most one rebirth in this time; the requests within it
    #: (or while one is pending) are answered by one rebirth at its end.
    rebirth_min_interval_s: float = field(default=1.0, metadata=in_range(0, 3600))
    #: Commands (NCMD, each device's DCMD) taken at most this many a second per topic,
    #: in bursts as many, a message of more than 256 bytes counting as one per 256;
    #: past it they are dropped before they are decoded, counted
    #: (``sparkplug_commands_shed``) and logged: a host that floods them must not take
    #: the interpreter from the scan path.
    command_rate: float = field(default=100.0, metadata=in_range(0.1, 100_000))

    def __post_init__(self) -> None:
        check_security(self)
        check_id("group_id", self.group_id)
        check_id("edge_node_id", self.edge_node_id)
        if self.primary_host_id is not None:
            check_id("primary_host_id", self.primary_host_id)
        if self.reconnect_max_s < self.reconnect_min_s:
            raise ValueError(f"reconnect_max_s: {self.reconnect_max_s:g} is below reconnect_min_s "
                             f"({self.reconnect_min_s:g})")


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
