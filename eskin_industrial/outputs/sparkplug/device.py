"""One sensor node as a Sparkplug device of the edge node: its sink.

With ``frame_interval_s`` the device also publishes the calibrated taxel frame as a
``FloatArray`` metric (``Taxels/Frame``): the node's loop hands it the newest frame
once that interval has passed (:attr:`~eskin_industrial.outputs.base.Sink.frame_every_s`),
and it goes out as a DDATA of its own, QoS 0, or not at all while the node cannot
publish (a frame is a sample of now: the store keeps the states, not stale frames).
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any

from ...node import Command, NodeSnapshot, refusal
from ..base import Sink, SinkHealth
from . import payload as pb
from .commands import BadCommand, Mailbox, birth_metrics, parse_device_command, summary
from .edge import NAMESPACE, EdgeNode, now_ms
from .metrics import ANALOG, DEVICE_METRICS, ENABLE_COMMAND, ENABLED, FLOATS, FRAME_ALIAS, FRAME_METRIC, metric_values
from .properties import Property

if TYPE_CHECKING:
    from ...frames import Frame


class SparkplugDevice(Sink):
    """One sensor node as a Sparkplug device of the edge node (opened by :class:`.kind.SparkplugKind`)."""

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
        #: What the loop has yet to apply: one command of each kind at most (a flood
        #: of DCMDs never reaches the scan path as a flood).
        self._commands = Mailbox()
        self.frame_every_s = node.options.frame_interval_s or None
        self.frame: bytes | None = None  #: the newest frame handed, packed (births declare it)
        self.frame_sent: bytes | None = None  #: the frame last sent (a DBIRTH or a DDATA)
        self.frames = self.frames_not_sent = self.frames_lost = 0

    def command(self, payload: pb.Payload, topic: str) -> None:
        """A DCMD for this device (paho's thread): posted for the loop (the newest of
        each kind wins, the ones it replaces counted as dropped), or refused as a whole
        under the PLC's rule, or counted as malformed; its line names a few commands."""
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
        node.commands_dropped += self._commands.put(cmds)
        self._logged("sparkplug_command", "info", commands=summary([c.name for c in cmds]), count=len(cmds))

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
        return self._commands.take()

    def birth(self) -> None:
        """DBIRTH: every metric with name, alias, datatype, unit and its newest value."""
        now = now_ms()
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
        metrics += birth_metrics(self.base, now, None if values is None else values[ENABLED])
        self.sent = list(values) if values is not None else [None] * len(DEVICE_METRICS)
        self.sent_at = [time.monotonic()] * len(DEVICE_METRICS)
        self.node.send(self.topic["DBIRTH"], pb.Payload(now, tuple(metrics)), birth=True)

    def death(self) -> None:
        with self.node.lock:
            if self.dead:
                return
            self.dead = True
            if self.node.connected:
                self.node.send(self.topic["DDEATH"], pb.Payload(now_ms()))

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
            changed = [i for i, v in enumerate(values) if v != sent[i] and not ANALOG[i]]
            interval = node.options.min_interval_s
            for i, v in enumerate(values):
                if not ANALOG[i] or v == sent[i] or (now - sent_at[i] < interval and not changed):
                    continue
                if FLOATS[i] and sent[i] is not None and abs(v - sent[i]) <= node.options.deadband:
                    continue
                changed.append(i)
            if not changed:
                return
            ms = now_ms()
            metrics = []
            for i in sorted(changed):
                sent[i], sent_at[i] = values[i], now
                metrics.append(pb.Metric(None, self.base + i, ms, DEVICE_METRICS[i].datatype, values[i]))
            if ENABLED in changed:
                metrics.append(pb.Metric(None, self.base + ENABLE_COMMAND, ms, pb.BOOLEAN, values[ENABLED]))
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
