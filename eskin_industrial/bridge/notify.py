"""systemd's notification protocol (``sd_notify``), the few lines of it the bridge
needs, with no dependency: one datagram of ``KEY=VALUE`` lines to the AF_UNIX socket
named by ``$NOTIFY_SOCKET`` (a leading ``@``: Linux's abstract namespace).

``Type=notify`` units learn from ``READY=1`` that the bridge runs (every output and
source opened), from ``STOPPING=1`` that it stops, and read ``STATUS=`` in
``systemctl status``.  With ``WatchdogSec=``, systemd sets ``$WATCHDOG_USEC`` and
expects ``WATCHDOG=1`` at least that often; the bridge sends it at half the period,
and only while every loop makes progress, so that a hung loop is restarted.

Outside systemd (no ``$NOTIFY_SOCKET``) every call does nothing.  A failed send is
counted, never raised: the bridge's work does not depend on its supervisor's mail.
"""

from __future__ import annotations

import os
import socket
from collections.abc import Mapping


class Notifier:
    def __init__(self, address: str | None, watchdog_usec: int | None = None) -> None:
        self.address: str | None = None
        if address:
            # "@name": the abstract namespace, a leading NUL byte on the wire.
            self.address = "\0" + address[1:] if address.startswith("@") else address
        self.watchdog_usec = watchdog_usec if watchdog_usec and watchdog_usec > 0 else None
        self.sent = 0
        self.failures = 0
        self._sock: socket.socket | None = None

    @classmethod
    def from_env(cls, env: Mapping[str, str] | None = None, pid: int | None = None) -> Notifier:
        """From ``$NOTIFY_SOCKET`` and ``$WATCHDOG_USEC`` (the latter only when
        ``$WATCHDOG_PID`` is unset or this process's, as sd_watchdog_enabled does)."""
        env = os.environ if env is None else env
        usec: int | None = None
        watchdog_pid = env.get("WATCHDOG_PID")
        if watchdog_pid is None or watchdog_pid == str(os.getpid() if pid is None else pid):
            try:
                usec = int(env.get("WATCHDOG_USEC", ""))
            except ValueError:
                usec = None
        return cls(env.get("NOTIFY_SOCKET"), usec)

    @property
    def enabled(self) -> bool:
        return self.address is not None

    @property
    def watchdog_interval_s(self) -> float | None:
        """How often to send WATCHDOG=1 (half systemd's period), or None: no watchdog."""
        if self.address is None or self.watchdog_usec is None:
            return None
        return self.watchdog_usec / 2e6

    def send(self, *fields: str) -> bool:
        """One datagram of ``KEY=VALUE`` fields; whether it went."""
        if self.address is None:
            return False
        try:
            if self._sock is None:
                self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC)
            self._sock.sendto("\n".join(fields).encode(), self.address)
        except OSError:
            self.failures += 1
            return False
        self.sent += 1
        return True

    def ready(self, status: str = "") -> bool:
        return self.send("READY=1", *([f"STATUS={status}"] if status else []))

    def stopping(self, status: str = "") -> bool:
        return self.send("STOPPING=1", *([f"STATUS={status}"] if status else []))

    def status(self, text: str) -> bool:
        return self.send(f"STATUS={text}")

    def watchdog(self) -> bool:
        return self.send("WATCHDOG=1")

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None
