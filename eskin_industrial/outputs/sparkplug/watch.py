"""What ``eskin-bus plant`` shows: every edge node and device of a Sparkplug B
namespace, from the messages alone (pure: topic and bytes in, events out; the clock
is handed in).

Online and offline come from the births and deaths (an NDEATH closes the session
whose ``bdSeq`` it names, and no other); a device's state, data valid, slip count and
last slip from its metrics, named by its DBIRTH's aliases; the largest taxel force and
the total of its newest taxel frame (``Taxels/Frame``, when the node sends it); the
message rate over the last :data:`RATE_WINDOW_S`; and gaps in each edge node's ``seq``.
"""

from __future__ import annotations

import collections
import math
import time
from dataclasses import dataclass, field
from typing import Any

from ...errors import EskinError
from . import payload as pb

RATE_WINDOW_S = 10.0
_WANTED = {"State": "state", "Data Valid": "valid", "Slip": "slip", "Counters/Slip Events": "slips"}
FRAME = "Taxels/Frame"


@dataclass
class DeviceView:
    name: str
    online: bool = False
    state: str | None = None
    valid: bool | None = None
    slip: bool | None = None
    slips: int | None = None
    last_slip_ms: int | None = None  #: the timestamp of the message that set Slip
    frame_max: float | None = None  #: of the newest taxel frame (N; NaN taxels left out)
    frame_sum: float | None = None
    method: str | None = None  #: the deciding method, from the DBIRTH's ``Score A`` properties
    last_seen: float | None = None  #: the clock handed in, at its newest birth or data
    aliases: dict[int, str] = field(default_factory=dict)
    arrivals: collections.deque[float] = field(default_factory=lambda: collections.deque(maxlen=10000))

    def rate(self, now: float) -> float:
        while self.arrivals and now - self.arrivals[0] > RATE_WINDOW_S:
            self.arrivals.popleft()
        return len(self.arrivals) / RATE_WINDOW_S


@dataclass
class EdgeView:
    group: str
    edge: str
    online: bool = False
    bd_seq: int | None = None
    next_seq: int | None = None
    seq_gaps: int = 0
    unborn: bool = False  #: data seen before any birth (a rebirth would tell its aliases)
    devices: dict[str, DeviceView] = field(default_factory=dict)


class PlantModel:
    def __init__(self) -> None:
        self.edges: dict[tuple[str, str], EdgeView] = {}
        self.messages = self.malformed = 0

    def take(self, topic: str, data: bytes, now: float) -> list[dict[str, Any]]:
        """One message; the events it makes (births, deaths, state changes, slips)."""
        parts = topic.split("/")
        if len(parts) < 4 or parts[0] != "spBv1.0" or parts[1] == "STATE":
            return []
        group, kind, edge_id = parts[1], parts[2], parts[3]
        device_id = parts[4] if len(parts) > 4 else None
        if kind in ("NCMD", "DCMD"):
            return []
        self.messages += 1
        try:
            p = pb.decode(data)
        except EskinError:
            self.malformed += 1
            return [{"event": "malformed", "topic": topic}]
        edge = self.edges.setdefault((group, edge_id), EdgeView(group, edge_id))
        where = {"group": group, "edge": edge_id}
        out: list[dict[str, Any]] = []
        if kind in ("NDATA", "DDATA", "DBIRTH", "DDEATH") and edge.bd_seq is None and not edge.unborn:
            edge.unborn = True  # a node born before we looked: its aliases are unknown
            out.append({"event": "unborn", **where})
        if kind != "NDEATH" and p.seq is not None:
            if kind == "NBIRTH":
                edge.next_seq = p.seq
            elif edge.next_seq is not None and p.seq != edge.next_seq:
                edge.seq_gaps += 1
                out.append({"event": "seq_gap", **where, "expected": edge.next_seq, "seq": p.seq})
            edge.next_seq = (p.seq + 1) & 0xFF
        if kind == "NBIRTH":
            edge.bd_seq = _named(p, "bdSeq")
            if not edge.online:
                out.append({"event": "online", **where, "bdSeq": edge.bd_seq})
            edge.online = True
        elif kind == "NDEATH":
            bd = _named(p, "bdSeq")
            if edge.online and (bd is None or bd == edge.bd_seq):
                edge.online = False
                out.append({"event": "offline", **where, "bdSeq": bd})
                for d in edge.devices.values():
                    d.online = False
        elif device_id is not None:
            dev = edge.devices.setdefault(device_id, DeviceView(device_id))
            dwhere = {**where, "device": device_id}
            if kind == "DBIRTH":
                dev.aliases = {m.alias: m.name for m in p.metrics if m.alias is not None and m.name is not None}
                dev.method = next((str(v) for m in p.metrics if m.name == "Score A"
                                   for k, (_, v) in m.properties if k == "method"), dev.method)
                dev.last_seen = now
                if not dev.online:
                    out.append({"event": "online", **dwhere})
                dev.online = True
                out += self._values(dev, p, dwhere)
            elif kind == "DDATA":
                dev.arrivals.append(now)
                dev.last_seen = now
                out += self._values(dev, p, dwhere)
            elif kind == "DDEATH":
                if dev.online:
                    out.append({"event": "offline", **dwhere})
                dev.online = False
        return out

    @staticmethod
    def _values(dev: DeviceView, p: pb.Payload, where: dict[str, Any]) -> list[dict[str, Any]]:
        before = (dev.state, dev.valid)
        slip_before = dev.slip
        history = []
        for m in p.metrics:
            name = m.name if m.name is not None else dev.aliases.get(m.alias or -1)
            if m.is_historical:  # the past, sent after an outage: shown as such, never as now
                if name == "State" and m.value is not None:
                    history.append({"event": "historical", **where, "state": m.value, "timestamp": m.timestamp})
                elif name == "Slip" and m.value and m.timestamp is not None:
                    dev.last_slip_ms = max(dev.last_slip_ms or 0, m.timestamp)  # a slip while away is the latest
                continue
            if name == FRAME:
                _frame(dev, m.value)
                continue
            key = _WANTED.get(name or "")
            if key is None or m.value is None:
                continue
            setattr(dev, key, m.value)
            if key == "slip" and m.value and not slip_before:
                dev.last_slip_ms = m.timestamp or p.timestamp
        out = history
        if (dev.state, dev.valid) != before and dev.state is not None:
            out.append({"event": "state", **where, "state": dev.state, "valid": dev.valid, "slips": dev.slips,
                        "timestamp": p.timestamp})
        return out

    def rows(self, now: float) -> list[dict[str, Any]]:
        """One row per edge node and device, for the live table (and ``--json`` at the end)."""
        out: list[dict[str, Any]] = []
        for (group, edge_id), e in sorted(self.edges.items()):
            out.append({"group": group, "edge": edge_id, "online": e.online, "bdSeq": e.bd_seq,
                        "seq_gaps": e.seq_gaps})
            for name, d in sorted(e.devices.items()):
                out.append({"group": group, "edge": edge_id, "device": name, "online": d.online, "state": d.state,
                            "valid": d.valid, "last_slip_ms": d.last_slip_ms, "slips": d.slips,
                            "rate": round(d.rate(now), 2), "frame_max": d.frame_max, "frame_sum": d.frame_sum,
                            "method": d.method, "age_s": None if d.last_seen is None else now - d.last_seen})
        return out


def _frame(dev: DeviceView, value: Any) -> None:
    """The newest frame's largest force and total; a value that is not whole 32-bit
    floats (another publisher's) leaves the last ones."""
    if not isinstance(value, bytes):
        return
    try:
        forces = [f for f in pb.unpack_floats(value) if not math.isnan(f)]
    except pb.PayloadError:
        return
    dev.frame_max = max(forces) if forces else None
    dev.frame_sum = math.fsum(forces) if forces else None


def _named(p: pb.Payload, name: str) -> Any:
    for m in p.metrics:
        if m.name == name:
            return m.value
    return None


def rebirth_command(now_ms: int | None = None) -> bytes:
    """An NCMD payload asking an edge node for its births again."""
    ts = int(time.time() * 1000) if now_ms is None else now_ms
    return pb.encode(pb.Payload(ts, (pb.Metric("Node Control/Rebirth", None, ts, pb.BOOLEAN, True),)))
