"""The CAN frame layout of a sensor node: scans to frames and back, no bus involved.

Everything here is pure: :class:`CanLayout` packs raw scans into frame payloads
(vectorized over a whole recording) and unpacks them; :class:`ScanAssembler` takes
frames one at a time, as a bus or a log delivers them, and hands out complete raw
scans, counting everything it drops.  The tables are in ``docs/can.md``.

Summary (node range ``base_id .. base_id + 15``):

- classic CAN: segment ``s`` of a scan at ``base_id + s``; 2 header bytes (a 12-bit
  scan counter and the 4-bit segment index) then whole taxels: 4 at 12 bits or 3 at 16
  bits per frame.  A taxel never straddles two frames, so a DBC can describe it.
- CAN FD: the whole scan in one frame at ``base_id`` (segment 0), same header,
  padded to the next valid FD length.
- heartbeat at ``base_id + 15``: node, state, error counters, scan rate, last counter.
"""

from __future__ import annotations

import collections
import enum
import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from functools import cached_property
from typing import Literal

import can
import numpy as np

from ...errors import DecodeError, ProfileError
from ...frames import RawScan, new_raw_scan
from ...profile import Profile
from .stream import StreamWatch

SEQ_BITS = 12
SEQ_MODULO = 1 << SEQ_BITS
SEQ_MASK = SEQ_MODULO - 1
HEADER_BYTES = 2
#: Offset of the heartbeat frame from ``base_id``; a node owns 16 IDs.
STATUS_OFFSET = 15
ID_RANGE = 16
STATUS_LENGTH = 8
FD_LENGTHS = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)


class NodeState(enum.IntEnum):
    """Byte 1 of the heartbeat."""

    BOOT = 0
    RUNNING = 1
    ERROR = 2  #: the node detected a fault (its scan data may be invalid)
    STOPPED = 3


@dataclass(frozen=True, slots=True)
class NodeStatus:
    """A decoded heartbeat."""

    node_id: int
    state: int
    tx_errors: int  #: the node controller's transmit error counter (TEC)
    rx_errors: int  #: its receive error counter (REC)
    rate_hz: int  #: the node's scan rate
    seq: int  #: 12-bit counter of the last scan sent
    t: float = math.nan  #: receipt time


def fd_length(n: int) -> int:
    """The smallest valid CAN FD data length holding ``n`` bytes."""
    for length in FD_LENGTHS:
        if length >= n:
            return length
    raise ValueError(f"{n} bytes do not fit one CAN FD frame (64 bytes at most)")


@dataclass(frozen=True)
class CanLayout:
    taxels: int
    bits: int  #: 12 or 16 bits per taxel
    byte_order: Literal["little", "big"]  #: for the header and the taxels
    base_id: int
    extended_id: bool = False
    fd: bool = False
    node_id: int = 1
    per_segment: int = field(init=False)  #: taxels per data frame
    segments: int = field(init=False)  #: data frames per scan

    def __post_init__(self) -> None:
        if self.bits not in (12, 16):
            raise ValueError(f"taxel_bits: expected 12 or 16, got {self.bits}")
        if self.fd:
            per = self.taxels
            if HEADER_BYTES + self.packed_bytes(per) > 64:
                raise ValueError(f"taxel_bits: {per} taxels at {self.bits} bits do not fit one 64-byte CAN FD frame")
        else:
            per = 48 // self.bits  # 6 payload bytes after the header
        segments = -(-self.taxels // per)
        if segments > STATUS_OFFSET:
            raise ValueError(f"{self.taxels} taxels need {segments} frames per scan; a node has {STATUS_OFFSET}")
        object.__setattr__(self, "per_segment", per)
        object.__setattr__(self, "segments", segments)

    @classmethod
    def from_profile(cls, profile: Profile, fd: bool | None = None) -> CanLayout:
        """The profile's layout; ``fd`` overrides ``[can] fd``.  Refuses a profile whose
        raw values do not fit ``taxel_bits`` (they would be clipped silently)."""
        can, cal = profile.can, profile.calibration
        top = (1 << can.taxel_bits) - 1
        raw_max = cal.valid_max / cal.raw_scale
        if raw_max > top:
            raise ProfileError(
                f"{profile.source}: [can] taxel_bits: {can.taxel_bits} bits carry raw values up to {top}, but "
                f"[calibration] valid_max is {raw_max:.6g} raw units; use taxel_bits = 16 or lower valid_max"
            )
        use_fd = can.fd if fd is None else fd
        try:
            return cls(profile.taxels, can.taxel_bits, can.byte_order, can.base_id, can.extended_id, use_fd, can.node_id)
        except ValueError as exc:
            raise ProfileError(f"{profile.source}: [can] {exc}") from None

    # -- sizes and IDs -------------------------------------------------------------

    @property
    def max_raw(self) -> int:
        return (1 << self.bits) - 1

    @property
    def status_id(self) -> int:
        return self.base_id + STATUS_OFFSET

    def data_id(self, segment: int) -> int:
        return self.base_id + segment

    def packed_bytes(self, count: int) -> int:
        """Bytes that ``count`` taxels take (12-bit taxels go in pairs of 3 bytes; an
        odd last one takes 2)."""
        return -(-count * self.bits // 8)

    def segment_taxels(self, segment: int) -> int:
        return min(self.per_segment, self.taxels - segment * self.per_segment)

    def frame_length(self, segment: int) -> int:
        """The data length of segment ``segment``'s frame, header included."""
        n = HEADER_BYTES + self.packed_bytes(self.segment_taxels(segment))
        return fd_length(n) if self.fd else n

    @property
    def frames_per_scan(self) -> int:
        return self.segments

    @property
    def bytes_per_scan(self) -> int:
        return sum(self.frame_length(s) for s in range(self.segments))

    # -- packing (vectorized over scans) -------------------------------------------

    def pack(self, raw: np.ndarray) -> np.ndarray:
        """Taxel values ``(K, taxels)`` (integers in [0, max_raw]) -> packed bytes
        ``(K, packed_bytes(taxels))`` uint8, in the profile's byte order."""
        raw = np.asarray(raw)
        values = raw.astype(np.uint32)
        k = values.shape[0]
        big = self.byte_order == "big"
        if self.bits == 16:
            return values.astype(">u2" if big else "<u2").view(np.uint8).reshape(k, -1)
        if self.taxels % 2:
            values = np.concatenate([values, np.zeros((k, 1), np.uint32)], axis=1)
        a, b = values[:, 0::2], values[:, 1::2]
        v = (a << 12 | b) if big else (a | b << 12)  # 24 bits per pair
        shifts = (16, 8, 0) if big else (0, 8, 16)
        out = np.stack([(v >> s) & 0xFF for s in shifts], axis=2).astype(np.uint8).reshape(k, -1)
        return out[:, : self.packed_bytes(self.taxels)]

    def unpack(self, packed: np.ndarray) -> np.ndarray:
        """The inverse of :meth:`pack`: ``(K, packed_bytes)`` uint8 -> ``(K, taxels)`` int64."""
        packed = np.asarray(packed, dtype=np.uint8)
        k = packed.shape[0]
        big = self.byte_order == "big"
        if self.bits == 16:
            return np.ascontiguousarray(packed).view(">u2" if big else "<u2").astype(np.int64).reshape(k, -1)
        pad = (-packed.shape[1]) % 3
        if pad:
            packed = np.concatenate([packed, np.zeros((k, pad), np.uint8)], axis=1)
        t = packed.reshape(k, -1, 3).astype(np.int64)
        b0, b1, b2 = t[..., 0], t[..., 1], t[..., 2]
        if big:
            a, b = b0 << 4 | b1 >> 4, (b1 & 0xF) << 8 | b2
        else:
            a, b = b0 | (b1 & 0xF) << 8, b1 >> 4 | b2 << 4
        return np.stack([a, b], axis=2).reshape(k, -1)[:, : self.taxels]

    @cached_property
    def _shifts(self) -> list[int]:
        total = 8 * self.packed_bytes(self.taxels)
        if self.byte_order == "little":
            return [self.bits * j for j in range(self.taxels)]
        return [total - self.bits * (j + 1) for j in range(self.taxels)]

    def unpack_one(self, payload: bytes) -> np.ndarray:
        """One scan's packed bytes -> its taxel values as float64 (the hot path of
        :class:`ScanAssembler`: a few microseconds, no array of arrays)."""
        if self.bits == 16:
            return np.frombuffer(payload, ">u2" if self.byte_order == "big" else "<u2").astype(np.float64)
        v = int.from_bytes(payload, self.byte_order)
        return np.array([(v >> s) & 0xFFF for s in self._shifts], dtype=np.float64)

    def header(self, seq: int, segment: int) -> bytes:
        return ((seq & SEQ_MASK) | segment << SEQ_BITS).to_bytes(2, self.byte_order)

    def encode(self, seqs: np.ndarray, raw: np.ndarray) -> list[list[tuple[int, bytes]]]:
        """Scans -> frames: for each scan, its ``(arbitration_id, data)`` in segment order.

        ``raw`` is clipped to [0, max_raw] and rounded (a node sends integers).
        """
        raw = np.clip(np.rint(np.asarray(raw, dtype=np.float64)), 0, self.max_raw)
        packed = self.pack(raw)
        bounds = []
        for s in range(self.segments):
            start = self.packed_bytes(s * self.per_segment)
            bounds.append((self.data_id(s), s, start, start + self.packed_bytes(self.segment_taxels(s)),
                           self.frame_length(s)))
        out = []
        for k, seq in enumerate(np.asarray(seqs, dtype=np.int64).tolist()):
            row = packed[k].tobytes()
            frames = []
            for can_id, s, lo, hi, length in bounds:
                data = self.header(seq, s) + row[lo:hi]
                frames.append((can_id, data.ljust(length, b"\0")))
            out.append(frames)
        return out

    def encode_status(self, status: NodeStatus) -> bytes:
        o = self.byte_order
        return bytes([status.node_id & 0xFF, status.state & 0xFF, min(status.tx_errors, 255),
                      min(status.rx_errors, 255)]) + int(status.rate_hz & 0xFFFF).to_bytes(2, o) + \
            int(status.seq & SEQ_MASK).to_bytes(2, o)

    def decode_status(self, data: bytes, t: float = math.nan) -> NodeStatus:
        # A short payload would raise IndexError from the byte indexing below; say what
        # is wrong instead (the assembler checks the length first and counts it).
        if len(data) != STATUS_LENGTH:
            raise DecodeError(f"heartbeat: expected {STATUS_LENGTH} bytes, got {len(data)}")
        o = self.byte_order
        return NodeStatus(data[0], data[1], data[2], data[3], int.from_bytes(data[4:6], o),
                          int.from_bytes(data[6:8], o) & SEQ_MASK, t)


#: Counters a :class:`ScanAssembler` keeps (all start at 0; names are stable, they
#: appear in ``Counters.extra`` and on the command line).
ASSEMBLER_COUNTERS = (
    "frames",  #: frames seen in the node's ID range
    "foreign_frames",  #: frames of other IDs (other nodes), ignored
    "malformed_frames",  #: wrong length, unknown ID in our range, segment/ID mismatch, remote frames
    "duplicate_frames",  #: a segment already received for its scan, or a repeat of the last scan
    "late_frames",  #: a frame of a scan older than the one being assembled or delivered (reordered)
    "torn_scans",  #: scans abandoned incomplete (a segment never came)
    "error_frames",  #: error frames reported by the controller
    "bus_off",  #: error frames reporting bus-off
    "heartbeats",
    "node_id_mismatch",  #: heartbeats naming another node number
    "interleaved_frames",  #: late frames of a counter the stream never started: a second sender
    "stream_faults",  #: entries into FLAGS STREAM (:mod:`.stream`): the frames are not one node's
)

_CAN_ERR_BUSOFF = 0x040  # linux/can/error.h: error class bit in the error frame's ID
#: Error frames in a row, with no frame of the node between, that make a bus fault
#: (one bus-off report does at once): one error frame between scans is noise; a run
#: of them with nothing else is a controller that cannot talk (error passive, no ACK).
ERROR_RUN_FAULT = 5
#: Receipt-time gaps from this long on are no clock (a garbled log, a clock jump of
#: decades): the unwrap then trusts the counter alone.  It also bounds the wraps the
#: clock can add, so ``RawScan.t`` stays a finite float.
_CLOCK_LIMIT_S = 1e9
#: Counters of the scans last begun, kept to tell a reordered frame (its scan was
#: begun) from a second sender's (a counter the stream skipped).
_STARTED_KEPT = 64


class ScanAssembler:
    """Frames in, complete raw scans out, one frame at a time.

    At most one scan is assembled at a time, so segments of two scans are never
    mixed: a frame of a newer scan abandons the incomplete one (``torn_scans``); a
    frame of an older scan is dropped (``late_frames``).  The 12-bit counter is
    unwrapped into ``RawScan.seq``; ``RawScan.t = seq / rate_hz`` is the node's time,
    so receipt jitter never looks like a gap, and lost scans show as jumps of ``seq``
    (which the pipeline counts).  After a silence longer than half the counter's
    period the unwrap uses the receipt times to count the wraps.

    ``feed`` takes anything with python-can ``Message``'s attributes and never raises
    for bad input: malformed frames are counted and dropped.
    """

    def __init__(self, layout: CanLayout, rate_hz: float) -> None:
        self.layout = layout
        self.rate_hz = float(rate_hz)
        self.counters: dict[str, int] = dict.fromkeys(ASSEMBLER_COUNTERS, 0)
        self.status: NodeStatus | None = None
        self._expect = {layout.data_id(s): (s, layout.frame_length(s)) for s in range(layout.segments)}
        self._lo, self._hi = layout.base_id, layout.base_id + ID_RANGE
        self._full = (1 << layout.segments) - 1
        self._big = layout.byte_order == "big"
        self._extended = layout.extended_id
        self._cur: int | None = None  # 12-bit counter of the scan being assembled
        self._cur_rx = math.nan  # receipt time of the scan's first frame
        self._have = 0
        self._parts: list[bytes] = [b""] * layout.segments
        self._last12: int | None = None  # counter of the last delivered scan
        self._last_rx = math.nan
        self._abs = 0
        #: whether the frames are one node's (FLAGS STREAM on the scans while they are not)
        self.stream = StreamWatch(self.rate_hz, layout.segments, self.counters)
        self._started: collections.deque[int] = collections.deque(maxlen=_STARTED_KEPT)  # counters begun
        self._last_start_rx = math.nan  # receipt time of the last delivered scan's first frame
        # the newest run of error frames: ``frames`` when it began (a frame of the node
        # since ends it), its length, and whether it reported bus-off
        self._err_mark = -1
        self._err_run = 0
        self._err_bus_off = False
        # half the counter's period, in seconds: beyond it, receipt times count wraps
        self._horizon = (SEQ_MODULO / 2) / self.rate_hz

    def feed(self, msg: can.Message) -> RawScan | None:
        # The hot path, nine times a classic scan: a data frame of this node is known
        # by one lookup of its ID, and its header read from two bytes (no slice); every
        # other frame takes the checks of _other_frame.  The counters and the outcomes
        # are those of the checks in their order: _other_frame's, then the header's.
        if msg.is_error_frame:
            self._error_frame(msg)
            return None
        can_id = msg.arbitration_id
        expect = self._expect.get(can_id)
        data = msg.data
        if (expect is None or msg.is_extended_id != self._extended or msg.is_remote_frame or data is None
                or len(data) != expect[1]):
            self._other_frame(msg, can_id)
            return None
        c = self.counters
        c["frames"] += 1
        header = (data[0] << 8 | data[1]) if self._big else (data[1] << 8 | data[0])
        segment, seq = header >> SEQ_BITS, header & SEQ_MASK
        if segment != expect[0]:
            c["malformed_frames"] += 1
            return None
        rx = msg.timestamp
        cur = self._cur
        if cur is not None and seq != cur:
            if (seq - cur) % SEQ_MODULO > SEQ_MODULO // 2:
                self._late(seq, cur)  # older than the scan under way
                return None
            c["torn_scans"] += 1
            self.stream.event(c["frames"], f"scan {cur} torn by scan {seq}")
            cur = self._cur = None
        if cur is None and not self._begin(seq, rx):
            return None
        bit = 1 << segment
        have = self._have
        if have & bit:
            c["duplicate_frames"] += 1
            self.stream.event(c["frames"], f"segment {segment} of scan {seq} repeated")
            return None
        self._have = have = have | bit
        self._parts[segment] = bytes(data)
        if have != self._full:
            return None
        return self._emit(seq, rx)

    def _error_frame(self, msg: can.Message) -> None:
        c = self.counters
        c["error_frames"] += 1
        bus_off = bool(msg.arbitration_id & _CAN_ERR_BUSOFF)
        if bus_off:
            c["bus_off"] += 1
        if c["frames"] != self._err_mark:  # a frame of the node came since: a new run
            self._err_mark, self._err_run, self._err_bus_off = c["frames"], 0, False
        self._err_run += 1
        self._err_bus_off |= bus_off

    def _other_frame(self, msg: can.Message, can_id: int) -> None:
        """A frame that is not a well-formed data frame of this node: another node's, a
        heartbeat, or a malformed one (counted)."""
        c = self.counters
        if not (self._lo <= can_id < self._hi) or msg.is_extended_id != self._extended:
            c["foreign_frames"] += 1
            return
        c["frames"] += 1
        data = msg.data
        if msg.is_remote_frame or data is None:
            c["malformed_frames"] += 1
            return
        if can_id == self.layout.status_id:
            if len(data) != STATUS_LENGTH:
                c["malformed_frames"] += 1
                return
            c["heartbeats"] += 1
            self.status = self.layout.decode_status(bytes(data), msg.timestamp)
            if self.status.node_id != self.layout.node_id:
                c["node_id_mismatch"] += 1
            self.stream.heartbeat(self.status.node_id, self.layout.node_id)
            return
        c["malformed_frames"] += 1  # an ID of our range that carries no segment, or a wrong length

    def _begin(self, seq: int, rx: float) -> bool:
        """The first frame of scan ``seq``: a new scan begins, unless it repeats the
        last one delivered or is older than it (False: the frame is dropped)."""
        c = self.counters
        if self._last12 is not None and not self._clock_wraps(rx - self._last_rx):
            d = (seq - self._last12) % SEQ_MODULO
            if d == 0:
                c["duplicate_frames"] += 1
                self.stream.event(c["frames"], f"scan {seq} repeated")
                return False
            if d > SEQ_MODULO // 2:
                self._late(seq, self._last12)
                return False
            self.stream.counter_ahead(d, rx - self._last_start_rx)
        self._cur, self._cur_rx, self._have = seq, rx, 0
        self._started.append(seq)
        return True

    def _late(self, seq: int, newer: int) -> None:
        """A frame of scan ``seq``, older than scan ``newer`` (under way or delivered):
        reordered when its scan was begun, a second sequence when it never was."""
        c = self.counters
        c["late_frames"] += 1
        # (a scan just before the newest, swapped with it on the way, is a reorder too)
        if seq in self._started or (newer - seq) % SEQ_MODULO == 1:
            self.stream.event(c["frames"], f"a frame of scan {seq} after scan {newer}")
        else:
            c["interleaved_frames"] += 1
            self.stream.trip(f"two scan counters interleaved (a frame of scan {seq}, never begun, after scan {newer})")

    @property
    def error_fault(self) -> bool:
        """The controller reported bus-off, or ERROR_RUN_FAULT error frames in a row,
        and no frame of the node has come since (no cost per data frame: a frame of
        the node moves ``frames`` past the run's mark)."""
        return self.counters["frames"] == self._err_mark and (self._err_bus_off or self._err_run >= ERROR_RUN_FAULT)

    @property
    def error_reason(self) -> str:
        """What :attr:`error_fault` is about, for the log ("" when there is none)."""
        if not self.error_fault:
            return ""
        what = "bus-off reported" if self._err_bus_off else "no bus-off reported"
        return f"{self._err_run} error frames in a row and no frame of the node since ({what})"

    def _clock_wraps(self, elapsed: float) -> bool:
        """Whether a silence of ``elapsed`` seconds is long enough for the receipt times
        to count the counter's wraps (and short enough to be a clock at all: NaN and
        infinite times are not)."""
        return self._horizon < elapsed < _CLOCK_LIMIT_S

    def _emit(self, seq: int, rx: float) -> RawScan:
        lay = self.layout
        if self._last12 is None:
            self._abs = seq
        else:
            d = (seq - self._last12) % SEQ_MODULO
            # The silence is measured to the scan's first frame, as ``feed`` did when it
            # let the scan start: with the last frame's time instead, a scan whose frames'
            # times go backwards could pass as new there and add 0 here (a repeated seq).
            elapsed = self._cur_rx - self._last_rx
            if self._clock_wraps(elapsed):  # long silence: count the wraps from the clock
                wraps = max(0, round((elapsed * self.rate_hz - d) / SEQ_MODULO))
                # the same counter value after a silence is at least one wrap later
                d += SEQ_MODULO * (max(wraps, 1) if d == 0 else wraps)
            self._abs += d
        self._last12, self._last_rx, self._last_start_rx, self._cur = seq, rx, self._cur_rx, None
        if lay.segments == 1:
            payload = self._parts[0][HEADER_BYTES:HEADER_BYTES + lay.packed_bytes(lay.taxels)]
        else:
            payload = b"".join(p[HEADER_BYTES:] for p in self._parts)
        raw = lay.unpack_one(payload)
        return new_raw_scan(self._abs, self._abs / self.rate_hz, raw, self.stream.scan(), rx)

    def flush(self) -> None:
        """End of traffic: a scan still incomplete is torn."""
        if self._cur is not None:
            self.counters["torn_scans"] += 1
            self._cur = None


def decode_messages(layout: CanLayout, messages: Iterable[can.Message], rate_hz: float
                    ) -> tuple[list[RawScan], ScanAssembler]:
    """All complete scans in a sequence of messages (a log), and the assembler with its
    counters."""
    asm = ScanAssembler(layout, rate_hz)
    scans = []
    for msg in messages:
        scan = asm.feed(msg)
        if scan is not None:
            scans.append(scan)
    asm.flush()
    return scans, asm
