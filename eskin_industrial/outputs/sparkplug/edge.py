"""The Sparkplug edge node: one MQTT session for the bridge, its births and deaths,
``seq`` and ``bdSeq``, and the store of what it could not send.

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
``tests/outputs/sparkplug/test_sparkplug_conformance.py``, one test per tck-id): births, data and DDEATH
at QoS 0, every metric with its timestamp, no datatype after the birth; QoS 1 for them
only by the opt-in ``nonconforming_qos1``, warned about.
"""

from __future__ import annotations

import collections
import itertools
import json
import threading
import time
from typing import Any, Protocol

from ... import __version__
from ...errors import EskinError
from ...ratelimit import Throttle
from . import payload as pb
from .bdseq import BdSeqFile, bdseq_path
from .commands import Budget, clip
from .metrics import FRAME_ALIAS, REBIRTH
from .options import SparkplugOptions, nonconforming
from .store import Forwarder, Held, store_path
from .transport import parse_broker

NAMESPACE = "spBv1.0"
_REBIRTH_BYTES = REBIRTH.encode()


class Device(Protocol):
    """What the edge node asks of each of its devices (:class:`.device.SparkplugDevice`)."""

    device_id: str
    #: DBIRTH, DDATA, DDEATH, DCMD -> the device's topic.
    topic: dict[str, str]
    base: int
    dead: bool
    frame: bytes | None
    frame_sent: bytes | None
    frames: int
    frames_not_sent: int
    frames_lost: int

    def birth(self) -> None: ...

    def death(self) -> None: ...

    def command(self, payload: pb.Payload, topic: str) -> None: ...

    def _event(self, name: str, level: str = "info", **fields: Any) -> None: ...


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


def now_ms() -> int:
    return int(time.time() * 1000)


class EdgeNode:
    """One MQTT connection, the edge node's births and deaths, ``seq`` and ``bdSeq``."""

    #: A device's DCMD topic that sheds more than this many times ``command_rate``
    #: within a second is a flood: it is unsubscribed for :attr:`FLOOD_PAUSE_S` (the
    #: broker drops it then, not paho's thread, whose every message costs the loop's
    #: thread the interpreter), then subscribed again.  NCMDs are never paused: a
    #: rebirth request must be answered.
    FLOOD_FACTOR = 10
    FLOOD_PAUSE_S = 1.0

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
        self.devices: list[Device] = []
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
        #: Commands folded into one of the same kind still waiting for the loop (newest wins).
        self.commands_dropped = 0
        #: Commands dropped undecoded, past ``command_rate`` on their topic; the budgets by topic.
        self.commands_shed = 0
        self._budgets: dict[str, Budget] = {}
        #: Flooded DCMD topics: (start of the second, shed in it); the paused ones' timers.
        self.command_pauses = 0
        self._shed_window: dict[str, tuple[float, int]] = {}
        self._paused: dict[str, threading.Timer] = {}
        #: STATEs not taken, per reason: "future" (stamped implausibly ahead of our
        #: clock, refused), "older" (than the newest taken), "malformed" (bad_states).
        self.states_ignored = {"future": 0, "older": 0, "malformed": 0}
        self.states_logged = Throttle()  #: the first STATE ignored of each reason, then one a LOG_EVERY_S
        #: Node Control/Rebirth: the requests, those answered by a rebirth already due.
        self.rebirth_requests = self.rebirths_coalesced = 0
        self._births_at = float("-inf")  #: when the last births went (monotonic)
        self._rebirth_timer: threading.Timer | None = None  #: a rebirth due at the end of the interval
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
        self.inflight: collections.deque[tuple[Any, Held | Device, int, float]] = collections.deque()

    def _event(self, name: str, level: str = "info", **fields: Any) -> None:
        """An event of the edge node, logged with its first device."""
        if self.devices:
            self.devices[0]._event(name, level, **fields)

    def nonconforming(self) -> list[str]:
        """What departs from the specification, one line each (start and ``--check``)."""
        return nonconforming(self.options, self.bd_error, str(self.bd_file.path))

    # -- messages -----------------------------------------------------------------------
    def _death(self) -> bytes:
        return pb.encode(pb.Payload(now_ms(), (pb.Metric("bdSeq", None, now_ms(), pb.INT64, self.bd_seq),)))

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

    def send_data(self, device: Device, ms: int, metrics: tuple[pb.Metric, ...]) -> None:
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

    def send_frame(self, device: Device, data: bytes) -> None:
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
            now = now_ms()
            metric = pb.Metric(None, device.base + FRAME_ALIAS, now, pb.FLOAT_ARRAY, data)
            seq = self._next_seq()
            if self._publish_tracked(device.topic["DDATA"],
                                     pb.encode(pb.Payload(now, (metric,), seq), datatypes=False), device, seq):
                device.frames += 1
                device.frame_sent = data
            else:
                device.frames_not_sent += 1

    def _publish_tracked(self, topic: str, data: bytes, held: Held | Device, seq: int) -> bool:
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
            data = body + pb.encode(pb.Payload(timestamp=now_ms(), seq=seq))
            self._publish_tracked(dev.topic["DDATA"], data, Held(serial, device_id, base, 0, (), body), seq)
            return True

    def _store_drained(self) -> None:
        """The store is empty again: the node metrics say so (NDATA)."""
        with self.lock:
            if self.connected and not self.stopping:
                now = now_ms()
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
            self._births_at = time.monotonic()
            now = now_ms()
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
        if not self._within_budget(topic, message.payload, device):
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
        self._rebirth_requested()

    def _within_budget(self, topic: str, data: bytes, device: Device | None) -> bool:
        """Whether a command on ``topic`` is within ``command_rate``; past it, counted,
        logged (one line per topic per LOG_EVERY_S) and dropped undecoded.  An NCMD
        that names Node Control/Rebirth is still a request (coalesced with the rebirth
        the ones before it asked for: a request is answered even in a flood, and at
        most one rebirth an interval goes whatever the requests hold)."""
        budget = self._budgets.get(topic)
        if budget is None:
            budget = self._budgets[topic] = Budget(self.options.command_rate)
        now = time.monotonic()
        if budget.take(now, len(data)):
            return True
        self.commands_shed += 1
        if device is not None:
            self._flooded(topic, now, device)
        held = self.commands_logged.passes((topic, "shed"))
        if held is not None:
            target = device if device is not None else (self.devices[0] if self.devices else None)
            if target is not None:
                target._event("sparkplug_commands_shed", "warning", topic=clip(topic),
                              rate=self.options.command_rate, held_back=held)
        if device is None and _REBIRTH_BYTES in data:
            self._rebirth_requested()
        return False

    def _flooded(self, topic: str, now: float, device: Device) -> None:
        """A DCMD shed on ``topic``: past FLOOD_FACTOR times the rate within a second,
        the topic is unsubscribed for FLOOD_PAUSE_S (paho's thread)."""
        start, n = self._shed_window.get(topic, (now, 0))
        if now - start > 1.0:
            start, n = now, 0
        n += 1
        self._shed_window[topic] = (start, n)
        if n <= self.FLOOD_FACTOR * self.options.command_rate or topic in self._paused:
            return
        del self._shed_window[topic]
        with self.lock:
            if self.stopping:
                return
            self.command_pauses += 1
            self.client.unsubscribe(topic)
            timer = self._paused[topic] = threading.Timer(self.FLOOD_PAUSE_S, self._resume, (topic,))
            timer.name, timer.daemon = "sparkplug-resume", True
            timer.start()
        held = self.commands_logged.passes((topic, "paused"))
        if held is not None:
            device._event("sparkplug_commands_paused", "warning", topic=clip(topic), pause_s=self.FLOOD_PAUSE_S,
                          held_back=held)

    def _resume(self, topic: str) -> None:
        """The pause of a flooded DCMD topic is over: subscribed again (a new session
        subscribed it already)."""
        with self.lock:
            self._paused.pop(topic, None)
            if self.session and not self.stopping:
                self.client.subscribe(topic, 1)

    def _rebirth_requested(self) -> None:
        """A Node Control/Rebirth (paho's thread): answered by births now, or, within
        ``rebirth_min_interval_s`` of the last ones, by one rebirth at its end that
        answers every request until then, counted as coalesced but the first (a host
        that floods them gets one rebirth an interval, not one each: each is every
        metric of the node and its devices)."""
        with self.lock:
            self.rebirth_requests += 1
            if not self.connected or self.stopping:
                return  # the births when the node goes live answer it
            if self._rebirth_timer is not None:
                self.rebirths_coalesced += 1
                return
            wait = self._births_at + self.options.rebirth_min_interval_s - time.monotonic()
            if wait <= 0:
                self.rebirths += 1
                self.births()
                return
            self._rebirth_timer = threading.Timer(wait, self._rebirth_due)
            self._rebirth_timer.name = "sparkplug-rebirth"
            self._rebirth_timer.daemon = True
            self._rebirth_timer.start()

    def _rebirth_due(self) -> None:
        """The interval after the last births has passed: the rebirth the requests
        since then asked for (its own thread)."""
        with self.lock:
            self._rebirth_timer = None
            if self.connected and not self.stopping:
                self.rebirths += 1
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
        except (ValueError, KeyError, TypeError, RecursionError) as exc:
            self.bad_states += 1
            self._state_ignored("malformed", None, None)
            self._bad("sparkplug_bad_state", str(self.state_topic), f"{type(exc).__name__}: {exc}")
            return
        ahead_ms = ts - now_ms()
        if ahead_ms > self.options.state_future_s * 1000:
            # Taken, it would make every genuine STATE after it look older.
            self._state_ignored("future", online, ts, ahead_s=round(ahead_ms / 1000, 3))
            return
        with self.lock:
            if self.stopping:
                return
            if ts < self._host_ts:
                self._state_ignored("older", online, ts, newest=self._host_ts)
                return
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

    def _state_ignored(self, reason: str, online: bool | None, ts: int | None, **fields: Any) -> None:
        """A STATE not taken: counted by reason; the first of each reason logged, then
        one line a LOG_EVERY_S with the count held back (malformed ones have their own
        line, ``sparkplug_bad_state``)."""
        self.states_ignored[reason] += 1
        if reason == "malformed":
            return
        held = self.states_logged.passes(reason)
        if held is not None:
            self._event("sparkplug_state_ignored", "warning", host=self.options.primary_host_id, reason=reason,
                        online=online, timestamp=ts, held_back=held, **fields)

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

    def _bad(self, event: str, topic: str, error: str, device: Device | None = None) -> None:
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
            target._event(event, "warning", topic=clip(topic), error=clip(error), not_logged=quiet)

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
            timers = [t for t in (self._rebirth_timer, *self._paused.values()) if t is not None]
            self._rebirth_timer = None
            self._paused.clear()
        for timer in timers:
            timer.cancel()
            timer.join(timeout_s)
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
                "sparkplug_rebirth_requests": self.rebirth_requests,
                "sparkplug_rebirths_coalesced": self.rebirths_coalesced,
                "sparkplug_store_held": f.held, "sparkplug_store_pending": f.pending,
                "sparkplug_store_overflow": f.overflow, "sparkplug_store_forwarded": f.forwarded,
                "sparkplug_store_discarded": f.discarded, "sparkplug_store_failures": f.failures,
                "sparkplug_store_in_memory": int(bool(f.fallback)), "sparkplug_store_left_on_disk": f.left_on_disk,
                "sparkplug_resent": self.resent, "sparkplug_unconfirmed": self.unconfirmed,
                "sparkplug_commands": self.commands,
                "sparkplug_commands_refused": self.commands_refused, "sparkplug_unknown_devices": self.unknown_devices,
                "sparkplug_commands_dropped": self.commands_dropped, "sparkplug_commands_shed": self.commands_shed,
                "sparkplug_command_pauses": self.command_pauses,
                "sparkplug_bad_states": self.bad_states, "sparkplug_host_online": int(self.host_online),
                "sparkplug_state_ignored": sum(self.states_ignored.values()),
                "sparkplug_state_future": self.states_ignored["future"],
                "sparkplug_state_older": self.states_ignored["older"],
                "sparkplug_host_sessions_ended": self.host_sessions_ended}
