"""A python-can bus over UDP datagrams on loopback, for benchmarks whose node
simulators run in processes of their own (python-can's ``virtual`` bus exists in one
process only, and its ``udp_multicast`` needs ``msgpack``, which the package does not
depend on).

One datagram a frame: the sender's wall-clock time (the stamp a virtual bus puts on
at send), the arbitration ID with its flags, and the data.  A channel is a loopback
UDP port: the receiving bus binds it (one receiver a channel: the bridge's reader),
a sending bus sends to it.  :func:`register` makes it ``interface="udp-loopback"``
for ``can.Bus``, so the bridge opens it as it opens any python-can interface: the
reader thread, the routing by ID and the assembly are the product's own.
"""

from __future__ import annotations

import select
import socket
import struct
import time
from typing import Any

import can

INTERFACE = "udp-loopback"
_HEAD = struct.Struct("<dIB")  # timestamp, arbitration id, flags
_EXTENDED, _FD, _BRS, _ERROR = 1, 2, 4, 8


class UdpLoopbackBus(can.BusABC):
    """``channel``: the UDP port; ``receive``: bind it (the one reader), else send to it."""

    def __init__(self, channel: Any = None, receive: bool = True, fd: bool = False, **kwargs: Any) -> None:
        self.port = int(channel)
        self.channel_info = f"udp-loopback 127.0.0.1:{self.port}"
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._receive = receive
        if receive:
            self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 * 1024 * 1024)
            self._sock.bind(("127.0.0.1", self.port))
        self._sock.setblocking(False)
        self._to = ("127.0.0.1", self.port)
        super().__init__(channel, **kwargs)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        flags = ((_EXTENDED if msg.is_extended_id else 0) | (_FD if msg.is_fd else 0)
                 | (_BRS if msg.bitrate_switch else 0) | (_ERROR if msg.is_error_frame else 0))
        data = _HEAD.pack(time.time(), msg.arbitration_id, flags) + bytes(msg.data)
        try:
            self._sock.sendto(data, self._to)
        except BlockingIOError:
            if not select.select([], [self._sock], [], timeout)[1]:
                raise can.CanOperationError("udp-loopback: send timed out") from None
            self._sock.sendto(data, self._to)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        try:
            data = self._sock.recv(128)
        except BlockingIOError:
            if timeout == 0.0 or not select.select([self._sock], [], [], timeout)[0]:
                return None, False
            data = self._sock.recv(128)
        t, can_id, flags = _HEAD.unpack_from(data)
        payload = data[_HEAD.size:]
        return can.Message(timestamp=t, arbitration_id=can_id, is_extended_id=bool(flags & _EXTENDED),
                           is_fd=bool(flags & _FD), bitrate_switch=bool(flags & _BRS),
                           is_error_frame=bool(flags & _ERROR), data=payload, dlc=len(payload),
                           channel=self.port), False

    def shutdown(self) -> None:
        super().shutdown()
        self._sock.close()


def register() -> None:
    """``can.Bus(interface="udp-loopback", channel=PORT)`` in this process."""
    import can.util

    can.interfaces.BACKENDS[INTERFACE] = (__name__, "UdpLoopbackBus")
    # python-can checks the name against the set it made at import (each module holds its own reference)
    valid = frozenset(can.interfaces.VALID_INTERFACES | {INTERFACE})
    can.interfaces.VALID_INTERFACES = can.util.VALID_INTERFACES = valid  # type: ignore[attr-defined,misc]
