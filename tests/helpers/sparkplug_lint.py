"""What a capture shows of an edge node against Sparkplug 3.0's MUST, MUST NOT and
SHOULD NOT statements, each finding named by its tck-id.

The input is what a subscriber of ``spBv1.0/#`` saw, in the broker's order: each
message's topic, QoS and retain flag as published, and its payload decoded by the
``protobuf`` package from the specification's schema (:mod:`tests.helpers.sparkplug`).
Only what the messages themselves show is judged (the will as the broker sent it, not
the CONNECT that registered it; subscriptions are the broker log's, elsewhere).
Commands and STATE messages are left out: they are the host's.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from tests.helpers import sparkplug as spb

Record = tuple[str, int, bool, Any]  #: topic, QoS, retain, payload (decoded)

#: The tck-ids a finding can carry, and what the capture showed against each.
RULES: dict[str, str] = {
    "tck-id-topic-structure": "topic not spBv1.0/group/TYPE/edge[/device]",
    "tck-id-topics-nbirth-mqtt": "NBIRTH not at QoS 0 without retain",
    "tck-id-topics-dbirth-mqtt": "DBIRTH not at QoS 0 without retain",
    "tck-id-topics-ndata-mqtt": "NDATA not at QoS 0 without retain",
    "tck-id-topics-ddata-mqtt": "DDATA not at QoS 0 without retain",
    "tck-id-topics-ddeath-mqtt": "DDEATH not at QoS 0 without retain",
    "tck-id-payloads-ndeath-will-message-qos": "NDEATH not at QoS 1",
    "tck-id-payloads-ndeath-will-message-retain": "NDEATH retained",
    "tck-id-topics-nbirth-timestamp": "NBIRTH without a payload timestamp",
    "tck-id-topics-dbirth-timestamp": "DBIRTH without a payload timestamp",
    "tck-id-topics-ndata-timestamp": "NDATA without a payload timestamp",
    "tck-id-topics-ddata-timestamp": "DDATA without a payload timestamp",
    "tck-id-payloads-ddeath-timestamp": "DDEATH without a payload timestamp",
    "tck-id-payloads-timestamp-in-UTC": "payload timestamp outside the capture's time (not UTC milliseconds)",
    "tck-id-payloads-metric-timestamp-in-UTC": "metric timestamp outside the capture's time (not UTC milliseconds)",
    "tck-id-topics-ndeath-seq": "NDEATH with a seq",
    "tck-id-topics-ndeath-payload": "NDEATH payload not the bdSeq metric alone",
    "tck-id-topics-nbirth-seq-num": "NBIRTH seq not 0",
    "tck-id-payloads-sequence-num-always-included": "no seq",
    "tck-id-payloads-sequence-num-incrementing": "seq not one more than the previous message's (mod 256)",
    "tck-id-principles-birth-certificates-order": "a message of the edge node before its NBIRTH",
    "tck-id-message-flow-device-birth-publish-nbirth-wait": "DBIRTH without an NBIRTH in the session",
    "tck-id-payloads-dbirth-order": "DBIRTH after data of the session",
    "tck-id-payloads-ddata-order": "DDATA of a device not born in the session",
    "tck-id-payloads-nbirth-bdseq": "NBIRTH without an Int64 bdSeq metric",
    "tck-id-payloads-nbirth-rebirth-req": "NBIRTH without Node Control/Rebirth, Boolean false",
    "tck-id-operational-behavior-data-commands-rebirth-name-aliases": "Node Control/Rebirth born with an alias",
    "tck-id-payloads-ndeath-bdseq": "NDEATH bdSeq not the session's NBIRTH's",
    "tck-id-topics-nbirth-bdseq-increment": "a new session's bdSeq not one more than the last (mod 256)",
    "tck-id-payloads-nbirth-bdseq-repeat": "a rebirth's bdSeq not its session's",
    "tck-id-payloads-alias-birth-requirement": "birth metric without its name or alias",
    "tck-id-payloads-metric-datatype-req": "birth metric without a datatype",
    "tck-id-payloads-metric-datatype-value": "datatype not one of the specification's",
    "tck-id-payloads-name-birth-data-requirement": "metric without a timestamp in a birth or data message",
    "tck-id-operational-behavior-data-publish-nbirth-values": "NBIRTH metric without a value and not is_null, or both",
    "tck-id-operational-behavior-data-publish-dbirth-values": "DBIRTH metric without a value and not is_null, or both",
    "tck-id-payloads-alias-uniqueness": "an alias given twice in the edge node's births",
    "tck-id-payloads-propertyset-keys-array-size": "property keys and values of different lengths",
    "tck-id-payloads-metric-propertyvalue-type-req": "property value without a type",
    "tck-id-case-sensitivity-metric-names": "birth metric names equal but for case",
    "tck-id-payloads-alias-data-cmd-requirement": "data metric with a name or without an alias",
    "tck-id-topics-nbirth-metric-reqs": "NDATA metric whose alias no NBIRTH of the session gave",
    "tck-id-topics-dbirth-metric-reqs": "DDATA metric whose alias the device's DBIRTH did not give",
    "tck-id-payloads-metric-datatype-not-req": "data metric with a datatype",
    "tck-id-principles-rbe-recommended": "live data message in which no value changed",
}

_QOS0 = {"NBIRTH": "tck-id-topics-nbirth-mqtt", "DBIRTH": "tck-id-topics-dbirth-mqtt",
         "NDATA": "tck-id-topics-ndata-mqtt", "DDATA": "tck-id-topics-ddata-mqtt", "DDEATH": "tck-id-topics-ddeath-mqtt"}
_STAMPED = {"NBIRTH": "tck-id-topics-nbirth-timestamp", "DBIRTH": "tck-id-topics-dbirth-timestamp",
            "NDATA": "tck-id-topics-ndata-timestamp", "DDATA": "tck-id-topics-ddata-timestamp",
            "DDEATH": "tck-id-payloads-ddeath-timestamp"}
_KINDS = {"NBIRTH", "NDEATH", "DBIRTH", "DDEATH", "NDATA", "DDATA"}
DATATYPES = range(1, 35)  #: Int8 (1) .. DateTimeArray (34)
REBIRTH = "Node Control/Rebirth"


class _Session:
    def __init__(self, bd: int | None) -> None:
        self.bd = bd
        self.seq: int | None = 0
        self.aliases: set[int] = set()  #: every alias the session's births gave
        self.node_aliases: set[int] = set()
        self.device_aliases: dict[str, set[int]] = {}
        self.data_seen = False
        self.last: dict[tuple[str, int], Any] = {}  #: (device, alias) -> value last sent


def findings(records: Iterable[Record], t0_ms: int, t1_ms: int) -> list[str]:
    """Every MUST, MUST NOT or SHOULD NOT statement the capture shows broken, one line
    each: ``tck-id [words]: what (message #i, topic)``; empty for a conforming edge node."""
    words = spb.tck_ids()
    out: list[str] = []
    session: _Session | None = None
    last_bd: int | None = None

    def bad(tck: str, i: int, topic: str, detail: str = "") -> None:
        out.append(f"{tck} [{words[tck]}]: {RULES[tck]}{' ' + detail if detail else ''} (message {i}, {topic})")

    for i, (topic, qos, retain, p) in enumerate(records):
        parts = topic.split("/")
        if parts[0] != "spBv1.0" or len(parts) < 4 or parts[1] == "STATE" or parts[2] not in _KINDS:
            if parts[0] == "spBv1.0" and parts[1] != "STATE" and (len(parts) < 3 or parts[2] not in ("NCMD", "DCMD")):
                bad("tck-id-topic-structure", i, topic)
            continue
        kind = parts[2]
        if len(parts) != (5 if kind[0] == "D" else 4) or not all(parts):
            bad("tck-id-topic-structure", i, topic)
            continue
        device = parts[4] if kind[0] == "D" else ""
        if kind == "NDEATH":
            if qos != 1:
                bad("tck-id-payloads-ndeath-will-message-qos", i, topic, f"(QoS {qos})")
            if retain:
                bad("tck-id-payloads-ndeath-will-message-retain", i, topic)
        elif qos != 0 or retain:
            bad(_QOS0[kind], i, topic, f"(QoS {qos}, retain {int(retain)})")
        if kind in _STAMPED and not p.HasField("timestamp"):
            bad(_STAMPED[kind], i, topic)
        if p.HasField("timestamp") and not t0_ms <= p.timestamp <= t1_ms:
            bad("tck-id-payloads-timestamp-in-UTC", i, topic, f"({p.timestamp})")
        for m in p.metrics:
            if m.HasField("timestamp") and not t0_ms <= m.timestamp <= t1_ms:
                bad("tck-id-payloads-metric-timestamp-in-UTC", i, topic, f"({m.timestamp})")

        if kind == "NDEATH":
            if p.HasField("seq"):
                bad("tck-id-topics-ndeath-seq", i, topic)
            bd = [spb.value(m) for m in p.metrics if m.name == "bdSeq" and m.datatype == 4]
            if len(p.metrics) != 1 or len(bd) != 1:
                bad("tck-id-topics-ndeath-payload", i, topic)
            elif session is not None and bd[0] != session.bd:
                bad("tck-id-payloads-ndeath-bdseq", i, topic, f"({bd[0]}, born with {session.bd})")
            session = None
            continue

        if not p.HasField("seq"):
            bad("tck-id-payloads-sequence-num-always-included", i, topic)
        if kind == "NBIRTH":
            if p.HasField("seq") and p.seq != 0:
                bad("tck-id-topics-nbirth-seq-num", i, topic, f"({p.seq})")
            bd_metrics = [m for m in p.metrics if m.name == "bdSeq" and m.datatype == 4]
            bd = spb.value(bd_metrics[0]) if bd_metrics else None
            if bd is None:
                bad("tck-id-payloads-nbirth-bdseq", i, topic)
            if session is not None:  # a rebirth within the session
                if bd != session.bd:
                    bad("tck-id-payloads-nbirth-bdseq-repeat", i, topic, f"({bd}, session {session.bd})")
            elif last_bd is not None and bd is not None and bd != (last_bd + 1) % 256:
                bad("tck-id-topics-nbirth-bdseq-increment", i, topic, f"({bd} after {last_bd})")
            last_bd = bd if bd is not None else last_bd
            session = _Session(bd)
            rebirth = [m for m in p.metrics if m.name == REBIRTH]
            if len(rebirth) != 1 or rebirth[0].datatype != 11 or rebirth[0].boolean_value is not False:
                bad("tck-id-payloads-nbirth-rebirth-req", i, topic)
            elif rebirth[0].HasField("alias"):
                bad("tck-id-operational-behavior-data-commands-rebirth-name-aliases", i, topic)
        elif session is None:
            bad("tck-id-principles-birth-certificates-order", i, topic, f"({kind})")
            continue
        elif p.HasField("seq"):
            want = ((session.seq if session.seq is not None else -1) + 1) % 256
            if p.seq != want:
                bad("tck-id-payloads-sequence-num-incrementing", i, topic, f"({p.seq}, expected {want})")
        session.seq = p.seq if p.HasField("seq") else None

        if kind in ("NBIRTH", "DBIRTH"):
            if kind == "DBIRTH" and session.data_seen:
                bad("tck-id-payloads-dbirth-order", i, topic)
            values = "tck-id-operational-behavior-data-publish-" + ("nbirth" if kind == "NBIRTH" else "dbirth") + "-values"
            born: set[int] = set()
            others = session.aliases - session.device_aliases.get(device, set()) if kind == "DBIRTH" else set()
            for m in p.metrics:
                named_only = kind == "NBIRTH" and m.name == REBIRTH
                if not m.HasField("name") or (not m.HasField("alias") and not named_only):
                    bad("tck-id-payloads-alias-birth-requirement", i, topic, f"({m.name or m.alias})")
                if not m.HasField("datatype"):
                    bad("tck-id-payloads-metric-datatype-req", i, topic, f"({m.name})")
                elif m.datatype not in DATATYPES:
                    bad("tck-id-payloads-metric-datatype-value", i, topic, f"({m.name}: {m.datatype})")
                if not m.HasField("timestamp"):
                    bad("tck-id-payloads-name-birth-data-requirement", i, topic, f"({m.name})")
                if (spb.value(m) is not None) == m.is_null:
                    bad(values, i, topic, f"({m.name})")
                if m.HasField("alias"):
                    if m.alias in born or m.alias in others:
                        bad("tck-id-payloads-alias-uniqueness", i, topic, f"({m.alias})")
                    born.add(m.alias)
                    session.last[(device, m.alias)] = spb.value(m)
                if m.HasField("properties"):
                    ps = m.properties
                    if len(ps.keys) != len(ps.values):
                        bad("tck-id-payloads-propertyset-keys-array-size", i, topic, f"({m.name})")
                    for v in ps.values:
                        if not v.HasField("type"):
                            bad("tck-id-payloads-metric-propertyvalue-type-req", i, topic, f"({m.name})")
                        elif v.type not in DATATYPES:
                            bad("tck-id-payloads-metric-datatype-value", i, topic, f"({m.name}: property {v.type})")
            names = [m.name.lower() for m in p.metrics]
            if len(names) != len(set(names)):
                bad("tck-id-case-sensitivity-metric-names", i, topic)
            if kind == "NBIRTH":
                session.node_aliases = born
            else:  # (a device born again within the session gives its own aliases again)
                session.device_aliases[device] = born
            session.aliases = others | born if kind == "DBIRTH" else born
        elif kind in ("NDATA", "DDATA"):
            session.data_seen = True
            declared = session.node_aliases if kind == "NDATA" else session.device_aliases.get(device)
            if declared is None:
                bad("tck-id-payloads-ddata-order", i, topic, f"({device})")
                continue
            news = 0  #: live metrics whose value differs from the last sent
            live = 0
            for m in p.metrics:
                if m.HasField("name") or not m.HasField("alias"):
                    bad("tck-id-payloads-alias-data-cmd-requirement", i, topic, f"({m.name or m.alias})")
                elif m.alias not in declared:
                    bad("tck-id-topics-nbirth-metric-reqs" if kind == "NDATA" else "tck-id-topics-dbirth-metric-reqs",
                        i, topic, f"({m.alias})")
                if m.HasField("datatype"):
                    bad("tck-id-payloads-metric-datatype-not-req", i, topic, f"({m.alias})")
                if not m.HasField("timestamp"):
                    bad("tck-id-payloads-name-birth-data-requirement", i, topic, f"({m.alias})")
                if not m.is_historical:
                    key = (device, m.alias)
                    live += 1
                    news += key not in session.last or session.last[key] != spb.value(m)
                    session.last[key] = spb.value(m)
            if live and not news:  # published with nothing changed: periodic, not by exception
                bad("tck-id-principles-rbe-recommended", i, topic)
        elif kind == "DDEATH":
            session.device_aliases.pop(device, None)
    return out
