"""Read a python-can bus into a bounded queue, on a thread of its own.

The bus is opened by python-can itself (:func:`open_bus`), so its interface names,
its configuration file and ``CAN_INTERFACE`` / ``CAN_CHANNEL`` all apply.  A reader
thread (:class:`BusReader`) does nothing but ``recv`` into a bounded queue: it never
waits on the detector.  When the queue is full the frame is dropped and counted.  A
bus that fails (interface down, adapter unplugged) is counted, closed and reopened
until it answers again.  The node's source (:mod:`.source`) assembles scans from the
queue; a log replayed (:mod:`.log`) fills the same kind of queue, so it gives the same
output.
"""

from __future__ import annotations

import collections
import errno
import select
import socket
import threading
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, Self

import can

from ...errors import CanBusError, EskinError, SocketCanMissing
from ...seam import DEFAULT_QUEUE_FRAMES
from .busargs import NO_BITRATE, configured, make_timing, parse_filters

if TYPE_CHECKING:
    from ...profile import Profile

#: Socket receive buffer asked for on SocketCAN (the kernel default holds a few
#: hundred frames: a 1 Mbit/s bus fills it in tens of milliseconds).
DEFAULT_RCVBUF_BYTES = 8 * 1024 * 1024


def open_bus(interface: str | None = None, channel: str | None = None, bitrate: int | None = None,
             fd: bool = False, data_bitrate: int | None = None,
             rcvbuf_bytes: int = DEFAULT_RCVBUF_BYTES, **extra: Any) -> can.BusABC:
    """``can.Bus`` with python-can's own option names; ``None`` leaves the value to
    python-can's configuration (file, ``CAN_INTERFACE``, ``CAN_CHANNEL``,
    ``CAN_BITRATE``).  ``extra``: ``timing``, ``can_filters`` and the bus class's own
    keyword arguments (``--bus-kwargs``), passed on as they are."""
    kwargs: dict = dict(extra)
    if bitrate is not None:
        kwargs["bitrate"] = bitrate
    if fd:
        kwargs["fd"] = True
        if data_bitrate is not None:
            kwargs["data_bitrate"] = data_bitrate
    try:
        bus = can.Bus(interface=interface, channel=channel, **kwargs)
    except (can.CanError, OSError, ValueError, TypeError, ImportError, NotImplementedError) as exc:
        where = f"interface {interface!r}" if interface else "the configured interface"
        if channel:
            where += f", channel {channel!r}"
        if _no_af_can(exc):
            # the name was right: the kernel lacks the protocol family, and listing the
            # valid interface names (socketcan among them) would say the opposite
            raise SocketCanMissing(
                f"cannot open CAN bus ({where}): this kernel has no SocketCAN (address family AF_CAN not "
                "supported): load it as root with `modprobe can` (and `modprobe vcan` for a virtual bus), or run "
                "where it exists; without a bus, `eskin-bus node --can-log FILE` writes a log to try") from exc
        detail = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        hint = "" if interface else " (give -i/--interface and -c/--channel, or set CAN_INTERFACE and CAN_CHANNEL)"
        raise CanBusError(f"cannot open CAN bus ({where}): {detail}{hint}; valid interfaces: "
                          f"{', '.join(sorted(can.interfaces.VALID_INTERFACES))}") from exc
    enlarge_rcvbuf(bus, rcvbuf_bytes)
    return bus


def _no_af_can(exc: BaseException) -> bool:
    """The error of a kernel without SocketCAN: the CAN socket's protocol family is
    refused (EAFNOSUPPORT), whichever python-can error wraps the OSError."""
    seen: BaseException | None = exc
    while seen is not None:
        if isinstance(seen, OSError) and seen.errno == errno.EAFNOSUPPORT:
            return True
        if getattr(seen, "error_code", None) == errno.EAFNOSUPPORT:
            return True
        seen = seen.__cause__ or seen.__context__
    return False


def bus_kwargs(profile: Profile, interface: str | None, channel: str | None, bitrate: int | None, fd: bool | None,
               data_bitrate: int | None, timing: dict[str, int] | None = None,
               filters: Sequence[str] = (), extra: dict[str, Any] | None = None) -> dict[str, Any]:
    """Arguments for :func:`open_bus` from python-can's options (the command line's
    ``-i/-c/-b/--fd/--timing/--filter/--bus-kwargs``, or a bridge node's keys).

    Bit rates resolve as python-can's own tools resolve them: the command line, then
    python-can's configuration (``CAN_BITRATE``, its config files), and only then the
    profile's ``[can]`` rates, for an interface that takes one (not virtual or
    socketcan) and is not given a ``timing``, whichever way the interface was named."""
    use_fd = profile.can.fd if fd is None else fd
    conf = configured(interface, channel)
    wants_rate = conf.get("interface") not in (None, *NO_BITRATE) and not timing and "timing" not in conf
    rate, data = bitrate, data_bitrate
    if rate is None and wants_rate and "bitrate" not in conf:
        rate = profile.can.bitrate_bps
    if data is None and wants_rate and use_fd and "data_bitrate" not in conf:
        data = profile.can.data_bitrate_bps
    kw: dict[str, Any] = dict(interface=interface, channel=channel, bitrate=rate, fd=use_fd, data_bitrate=data)
    if timing:
        kw["timing"] = make_timing(timing)
    if filters:
        kw["can_filters"] = parse_filters(filters)
    return {**(extra or {}), **kw}


def enlarge_rcvbuf(bus: can.BusABC, size: int) -> int | None:
    """Raise a SocketCAN socket's receive buffer to ``size`` bytes (past the system
    limit when privileged); returns what the kernel granted, None for other buses."""
    sock = getattr(bus, "socket", None)
    if not isinstance(sock, socket.socket):
        return None
    force = getattr(socket, "SO_RCVBUFFORCE", 33)
    try:
        sock.setsockopt(socket.SOL_SOCKET, force, size)
    except OSError:
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, size)
        except OSError:
            pass
    return sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)


class FrameThread:
    """A thread that fills a bounded frame queue, what a scan poller reads: ``queue``,
    ``arrived`` (set after frames were queued: a consumer waits on it instead of
    polling), ``counters`` (``rx_queue_drops``: frames dropped because the consumer
    fell behind; ``bus_errors``; ``bus_reopens``), ``last_error`` and ``done`` (the
    source has ended: never, for a live bus).  Subclasses write ``_run``.

    ``on_queued``, when set, is called on this thread when frames arrive in an empty
    queue; returning True means it has consumed them itself (an idle consumer served
    on the spot, with no thread hand-off), False that the consumer must be woken.
    """

    done = False
    thread_name = "can-frames"

    def __init__(self, queue_frames: int, **counters: int) -> None:
        self.queue: collections.deque[can.Message] = collections.deque()
        self.max_frames = queue_frames
        self.counters = {"rx_queue_drops": 0, "bus_errors": 0, "bus_reopens": 0, **counters}
        self.arrived = threading.Event()
        self.on_queued: Callable[[], bool] | None = None
        self.last_error = ""
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=self.thread_name, daemon=True)

    def start(self) -> Self:
        """Start the thread (once: a second call does nothing)."""
        if self._thread.ident is None:
            self._thread.start()
        return self

    def _run(self) -> None:
        raise NotImplementedError

    def stop(self) -> None:
        """Stop the thread; safe to call twice."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)


class BusReader(FrameThread):
    """Reads a bus into the bounded queue and survives bus failures: ``open`` is
    called to (re)open the bus."""

    thread_name = "can-reader"

    def __init__(self, open: Callable[[], can.BusABC], queue_frames: int = DEFAULT_QUEUE_FRAMES,
                 retry_s: float = 0.2) -> None:
        super().__init__(queue_frames)
        self._open = open
        self.bus: can.BusABC | None = open()
        self.retry_s = retry_s
        self.bus_up = True

    def _run(self) -> None:
        q, limit, counters = self.queue, self.max_frames, self.counters
        while not self._stop.is_set():
            bus = self.bus
            if bus is None:
                if not self._reopen():
                    self._stop.wait(self.retry_s)
                continue
            try:
                batch = _drain_socketcan(bus) if _is_socketcan(bus) else _drain(bus)
            except (can.CanError, OSError, ValueError) as exc:
                self._fail(exc)
                continue
            was_empty = not q
            for msg in batch:
                if msg is None:
                    continue
                if len(q) >= limit:
                    counters["rx_queue_drops"] += 1
                else:
                    q.append(msg)
            if q:
                hook = self.on_queued
                if not (was_empty and hook is not None and hook()):
                    self.arrived.set()

    def _fail(self, exc: Exception) -> None:
        self.counters["bus_errors"] += 1
        self.bus_up = False
        self.last_error = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        bus, self.bus = self.bus, None
        if bus is not None:
            try:
                bus.shutdown()
            except Exception:  # a broken driver must not stop the reader  # noqa: BLE001
                pass
        self._stop.wait(self.retry_s)

    def _reopen(self) -> bool:
        try:
            self.bus = self._open()
        except (EskinError, can.CanError, OSError, ValueError):
            self.counters["bus_errors"] += 1
            return False
        self.counters["bus_reopens"] += 1
        self.bus_up = True
        return True

    def stop(self) -> None:
        """Stop reading and close the bus; safe to call twice."""
        super().stop()
        bus, self.bus = self.bus, None
        if bus is not None:
            bus.shutdown()


def _drain(bus: can.BusABC, wait_s: float = 0.1, most: int = 256) -> list[can.Message | None]:
    """A frame (waiting up to ``wait_s``), then every frame already waiting behind it:
    a burst (the segments of one scan) is handed on in one go, not frame by frame."""
    first = bus.recv(wait_s)
    if first is None:
        return []
    out: list[can.Message | None] = [first]
    while len(out) < most:
        msg = bus.recv(0.0)
        if msg is None:
            break
        out.append(msg)
    return out


def _is_socketcan(bus: can.BusABC) -> bool:
    return type(bus).__name__ == "SocketcanBus" and isinstance(getattr(bus, "socket", None), socket.socket)


def _drain_socketcan(bus: can.BusABC, wait_s: float = 0.1, most: int = 4096) -> list[can.Message]:
    """Everything the socket holds, after waiting up to ``wait_s`` for the first frame.

    The same reads python-can's ``recv`` does (its ``capture_message``), without a
    ``select`` per frame: under load the reader drains the socket in one go.
    """
    from can.interfaces.socketcan.socketcan import capture_message

    # Called only when _is_socketcan(bus): a SocketcanBus, whose socket BusABC does not declare.
    sock = bus.socket  # type: ignore[attr-defined]
    try:
        ready, _, _ = select.select([sock], [], [], wait_s)
    except OSError as exc:
        raise can.CanOperationError(f"Failed to receive: {exc.strerror}", exc.errno) from exc
    out: list[can.Message] = []
    if not ready:
        return out
    sock.setblocking(False)
    channel = getattr(bus, "channel", None)
    while len(out) < most:
        try:
            msg = capture_message(sock, False)
        except can.CanOperationError as exc:
            if exc.error_code in (errno.EAGAIN, errno.EWOULDBLOCK):
                break
            if out:  # hand over what came before the failure; it repeats on the next read
                break
            raise
        if msg is None:
            break
        if channel and not msg.channel:
            msg.channel = channel
        out.append(msg)
    return out
