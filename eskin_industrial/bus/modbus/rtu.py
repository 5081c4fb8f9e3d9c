"""The Modbus RTU source: poll the node's registers, one scan per poll.

Each successful read becomes a :class:`~eskin_industrial.pipeline.RawScan`
timestamped on receipt (or, when the node keeps a scan counter, on the node's
clock, with a scan polled twice used once).  A failed read is retried within the same scan period
(``[modbus.node] retries``); a poll that still fails is a lost scan (its sequence
number is skipped, so the pipeline counts it) and never blocks longer than
``(retries + 1) x timeout_s``.  Timeouts, garbled frames (bad CRC) and exception
responses are counted apart; ``bus_fault`` is set after ``fault_after_failures``
consecutive failed polls and cleared by the next good one.  The failed polls of an
outage under way are lost scans at once (:meth:`RtuSource.lost_pending`), not only
when a poll succeeds again.

Without a scan counter, an answer identical to the bit to the one before is the same
scan polled again (a live array's noise never repeats a scan): used once while it
comes within ``[modbus.node] repeat_s`` of the first of them, and past that an answer
replayed (FLAGS STREAM: no verdict until a different answer).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

from ...errors import ModbusFault
from ...frames import FrameFlag, RawScan
from ...modbus.pymodbus_io import RtuMaster
from ...modbus.serial_line import SerialSettings
from ...preflight import check_serial
from ...profile import Profile
from ...schema import in_range, positive
from ...seam import NodeLike, OpenContext
from ..source import Source
from .codec import decode_scans, register_count

_STREAM = int(FrameFlag.STREAM)


@dataclass
class RtuCounters:
    polls: int = 0
    scans: int = 0
    timeouts: int = 0
    crc_errors: int = 0
    exceptions: int = 0
    retries: int = 0
    failed_polls: int = 0
    #: the same scan polled again, not used twice: its counter again, or (without one)
    #: an answer identical to the one before, within ``repeat_s`` of the first of them
    repeats: int = 0
    counter_resets: int = 0  #: with a scan counter: the node restarted its count
    #: without a scan counter: answers identical to the one before later than
    #: ``repeat_s``, delivered with FLAGS STREAM (an answer replayed: no verdict)
    replays: int = 0
    unit_mismatches: int = 0  #: answers from another unit id than the one asked

    @property
    def bus_errors(self) -> int:
        return self.timeouts + self.crc_errors + self.exceptions + self.unit_mismatches

    def as_dict(self) -> dict[str, int]:
        return {f"rtu_{k}": v for k, v in vars(self).items()}


@dataclass(frozen=True)
class RtuOptions:
    """``[[node]]`` keys of ``source = "modbus-rtu"``: the node's serial port; unit id and
    baud rate default to the profile's ``[modbus.node]``."""

    serial_port: str
    unit_id: int | None = field(default=None, metadata=in_range(1, 247))
    baudrate: int | None = field(default=None, metadata=positive())


class RtuSource(Source["RtuOptions"]):
    """Polls one RTU sensor node at its pace; one scan per poll."""

    kind = "modbus-rtu"
    spec = "rtu:PORT[@BAUD]"
    Options = RtuOptions
    profile_keys = {"unit_id": "modbus.node.unit_id", "baudrate": "modbus.node.baudrate"}

    def __init__(self, profile: Profile, port: str, *, baudrate: int | None = None,
                 poll_hz: float | None = None) -> None:
        super().__init__()
        self.node = node = profile.modbus.node
        self.settings = SerialSettings(port, baudrate or node.baudrate, node.parity, node.stopbits)
        self.count = register_count(node, profile.taxels)
        self.poll_hz = poll_hz or node.poll_hz or profile.sensor.rate_hz
        self.master = RtuMaster(self.settings, node.unit_id, node.timeout_s)
        self.stats = RtuCounters()
        self.consecutive_failures = 0
        self.t0 = time.monotonic()
        self.node_rate_hz = profile.sensor.rate_hz
        self._seq = -1
        self._counter: int | None = None  #: the node's last scan counter
        self._last_node_seq = 0
        self._prev_regs: list[int] | None = None  # without a counter: the answer before
        self._prev_rx = 0.0  # when it came
        self._repeats = 0  # answers identical to it since
        self._replayed = False  # they outlasted repeat_s: an answer replayed
        self._replay_reason = ""
        self.repeat_s = 1.5 / profile.sensor.rate_hz if node.repeat_s is None else node.repeat_s
        self._next = time.monotonic()
        #: The newest failure, as the master reported it (the ``bus_fault`` event's
        #: ``error``); kept after a good poll, as a CAN reader keeps its last error.
        self._last_error = ""

    def open(self) -> RtuSource:
        self.master.connect()
        return self

    def _close(self) -> None:
        self.master.close()

    @property
    def bus_fault(self) -> bool:
        return self.consecutive_failures >= self.node.fault_after_failures

    @property
    def last_error(self) -> str:
        return self._last_error

    @property
    def fault_reason(self) -> str:
        return self._replay_reason if self._replayed else ""

    def poll_once(self) -> RawScan | None:
        """One poll (with retries), now; None when it failed (counted)."""
        c = self.stats
        c.polls += 1
        self._seq += 1
        for attempt in range(self.node.retries + 1):
            if attempt:
                c.retries += 1
            try:
                regs = self.master.read(self.node.function, self.node.start_address, self.count)
            except ModbusFault as exc:
                self._last_error = str(exc)
                if exc.kind == "exception":
                    c.exceptions += 1
                elif exc.kind == "crc":
                    c.crc_errors += 1
                    self.master.reset_input()
                elif exc.kind == "unit":
                    c.unit_mismatches += 1
                else:
                    c.timeouts += 1
                continue
            rx = time.monotonic()
            if len(regs) != self.count:
                c.crc_errors += 1
                self._last_error = f"{self.settings.port}: {len(regs)} registers in the answer, {self.count} asked"
                continue
            self.consecutive_failures = 0
            if self.node.counter_register:
                self._last_rx = rx  # a good answer, even a repeated scan: the node is alive
                return self._counted(regs, rx)
            flags = 0
            if regs == self._prev_regs:
                self._repeats += 1
                same_s = rx - self._prev_rx
                if same_s <= self.repeat_s and not self._replayed:
                    # the scan polled again: used once, none lost (and none fresher: a
                    # run of them ages the newest scan into stale)
                    c.repeats += 1
                    self._seq -= 1
                    return None
                c.replays += 1
                flags = _STREAM
                if not self._replayed:
                    self._replayed = True
                    self._replay_reason = (
                        f"{self.settings.port}: unit {self.node.unit_id} gave the same answer, to the bit, "
                        f"{self._repeats + 1} polls in a row over {1000 * same_s:.1f} ms (repeat_s "
                        f"{1000 * self.repeat_s:g} ms): an answer replayed, not a scan")
            else:
                self._repeats, self._replayed = 0, False
                self._prev_regs, self._prev_rx = regs, rx
            self._last_rx = rx
            c.scans += 1
            return RawScan(self._seq, rx - self.t0, decode_scans(self.node, regs), flags, rx)
        c.failed_polls += 1
        self.consecutive_failures += 1
        return None

    def _counted(self, regs: list[int], rx: float) -> RawScan | None:
        """A scan numbered by the node: node time, repeats dropped, skips lost."""
        counter = regs[0]
        if self._counter is None:
            seq = 0
        else:
            step = (counter - self._counter) & 0xFFFF
            if step == 0:
                self.stats.repeats += 1
                return None
            if step >= 0x8000:  # the counter went back: the node restarted
                self.stats.counter_resets += 1
                step = 1
            seq = self._last_node_seq + step
        self._counter, self._last_node_seq = counter, seq
        self.stats.scans += 1
        return RawScan(seq, seq / self.node_rate_hz, decode_scans(self.node, regs[1:]), 0, rx)

    def _poll(self, timeout_s: float | None) -> RawScan | None:
        """Wait for the next poll time (``poll_hz``), then poll; a late poll does not
        try to catch up.  (``timeout_s`` is for sources that wait for traffic; the
        poller keeps its own pace.)"""
        now = time.monotonic()
        period = 1.0 / self.poll_hz
        if self._next > now:
            time.sleep(self._next - now)
        else:
            self._next = now
        self._next += period
        return self.poll_once()

    def bus_errors(self) -> int:
        return self.stats.bus_errors

    def lost_pending(self) -> int:
        """The failed polls since the last good one, once a scan was delivered (the
        pipeline counts a gap from there); with a scan counter, the node scans those
        polls spanned at least (``poll_hz`` paces polls, a failed one takes longer)."""
        n = self.consecutive_failures
        if not n or not self.stats.scans:
            return 0
        if self.node.counter_register:
            return int(n * min(1.0, self.node_rate_hz / self.poll_hz))
        return n

    def counters(self) -> dict[str, int]:
        return self.stats.as_dict()

    def describe_where(self) -> str:
        return f"rtu {self.settings.port}"

    # -- the kind ------------------------------------------------------------------
    @classmethod
    def options_from_spec(cls, where: str, bus: dict[str, Any]) -> dict[str, Any]:
        port, _, baud = where.partition("@")
        if not port or (baud and not baud.isdigit()):
            raise ValueError(f"expected rtu:PORT[@BAUD], got 'rtu:{where}'")
        return {"serial_port": port, **({"baudrate": int(baud)} if baud else {})}

    @classmethod
    def adapt_profile(cls, profile: Profile, options: RtuOptions) -> Profile:
        node = profile.modbus.node
        if options.unit_id is None and options.baudrate is None:
            return profile
        node = replace(node, unit_id=options.unit_id or node.unit_id, baudrate=options.baudrate or node.baudrate)
        return replace(profile, modbus=replace(profile.modbus, node=node))

    @classmethod
    def describe(cls, node: NodeLike[RtuOptions]) -> str:
        return f"rtu {node.options.serial_port} unit {node.profile.modbus.node.unit_id}"

    @classmethod
    def check(cls, node: NodeLike[RtuOptions], base_dir: str) -> None:
        check_serial(node.options.serial_port, "serial_port")

    @classmethod
    def check_together(cls, nodes: Sequence[NodeLike[RtuOptions]]) -> None:
        ports = [n.options.serial_port for n in nodes]
        for port in ports:
            if ports.count(port) > 1:
                raise ValueError(f"[node] serial_port: {port!r} is used by two nodes (one node per line)")

    @classmethod
    def open_node(cls, node: NodeLike[RtuOptions], context: OpenContext) -> RtuSource:
        return cls(node.profile, node.options.serial_port, baudrate=node.options.baudrate).open()
