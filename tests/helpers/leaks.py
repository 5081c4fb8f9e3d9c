"""Fail a test that leaves threads, sockets or python-can virtual buses behind.

:func:`no_leaks` is an autouse fixture (``tests/conftest.py`` imports it; it also works
as a plugin: ``pytest -p tests.helpers.leaks``). Before the test it notes what this
process has open:

- threads: :func:`threading.enumerate`;
- sockets: this process's socket file descriptors (``/proc/self/fd`` links
  ``socket:[inode]``), described by the kernel's tables (``/proc/self/net/tcp``,
  ``tcp6``, ``udp``, ``udp6``, ``unix``);
- virtual CAN buses: the receive queues python-can keeps per virtual channel
  (``can.interfaces.virtual.channels``); a bus adds one when it opens and removes it on
  ``shutdown()``.

After the test (after every other fixture of the test has been torn down) it waits up
to :data:`GRACE_S` (2 s) for what the test started to wind down, then fails the test's
teardown naming what is still there: thread names, socket addresses, channel names.
Only what appeared during the test counts; what was open before (a module's server,
an earlier test's leak) does not. pytest and hypothesis start no threads of their own
here; asyncio's executor threads end when ``asyncio.run`` closes its loop, so one left
running means a loop left running. Child processes and other descriptors (files,
pipes, ptys) are not checked.

A test that leaves something on purpose says so: ``@pytest.mark.allow_leaks("why")``.
"""

from __future__ import annotations

import gc
import os
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import pytest

#: How long what a test started may take to stop after it (s); ``ESKIN_TEST_LEAK_GRACE_S``
#: overrides it.
GRACE_S = 2.0
_POLL_S = 0.02

_TCP_STATES = {
    "01": "ESTABLISHED", "02": "SYN_SENT", "03": "SYN_RECV", "04": "FIN_WAIT1", "05": "FIN_WAIT2",
    "06": "TIME_WAIT", "07": "CLOSE", "08": "CLOSE_WAIT", "09": "LAST_ACK", "0A": "LISTEN", "0B": "CLOSING",
}


def _threads() -> dict[threading.Thread, str]:
    return {t: t.name for t in threading.enumerate() if t.is_alive()}


def _socket_inodes() -> dict[int, int]:
    """inode -> fd of every socket this process has open."""
    out: dict[int, int] = {}
    fd_dir = Path("/proc/self/fd")
    try:
        fds = os.listdir(fd_dir)
    except OSError:
        return out
    for fd in fds:
        try:
            link = os.readlink(fd_dir / fd)
        except OSError:  # closed meanwhile (or the listing's own descriptor)
            continue
        if link.startswith("socket:["):
            out[int(link[8:-1])] = int(fd)
    return out


def _ip_port(text: str, v6: bool) -> str:
    """``0100007F:1F90`` (the kernel's byte order) as ``127.0.0.1:8080``."""
    addr, port = text.split(":")
    raw = bytes.fromhex(addr)
    # The address is in host order 32-bit words (little-endian on x86).
    words = [raw[i:i + 4][::-1] for i in range(0, len(raw), 4)]
    packed = b"".join(words)
    if v6:
        import ipaddress

        host = f"[{ipaddress.IPv6Address(packed)}]"
    else:
        host = ".".join(str(b) for b in packed)
    return f"{host}:{int(port, 16)}"


def _describe_sockets(inodes: set[int]) -> dict[int, str]:
    """inode -> what the kernel's tables say about it (addresses and state)."""
    found: dict[int, str] = {}
    net = Path("/proc/self/net")
    for name in ("tcp", "tcp6", "udp", "udp6"):
        try:
            lines = (net / name).read_text().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            cols = line.split()
            if len(cols) < 10 or int(cols[9]) not in inodes:
                continue
            local, remote = _ip_port(cols[1], name.endswith("6")), _ip_port(cols[2], name.endswith("6"))
            if name.startswith("tcp"):
                state = _TCP_STATES.get(cols[3], cols[3])
                found[int(cols[9])] = (f"{name} {local} (listening)" if state == "LISTEN"
                                       else f"{name} {local} -> {remote} {state}")
            else:
                found[int(cols[9])] = f"{name} {local}"
    try:
        lines = (net / "unix").read_text().splitlines()[1:]
    except OSError:
        lines = []
    for line in lines:
        cols = line.split()
        if len(cols) >= 7 and int(cols[6]) in inodes and int(cols[6]) not in found:
            found[int(cols[6])] = "unix " + (cols[7] if len(cols) > 7 else "(unnamed)")
    return found


def _virtual_queues() -> dict[int, tuple[str, object]]:
    """id -> (channel, queue) of every open python-can virtual bus."""
    try:
        from can.interfaces import virtual
    except ImportError:
        return {}
    with virtual.channels_lock:
        return {id(q): (str(ch), q) for ch, queues in virtual.channels.items() for q in queues}


@dataclass
class Snapshot:
    """What this process had open at one moment."""

    threads: dict[threading.Thread, str] = field(default_factory=_threads)
    sockets: dict[int, int] = field(default_factory=_socket_inodes)
    buses: dict[int, tuple[str, object]] = field(default_factory=_virtual_queues)

    def leaks_since(self, before: Snapshot) -> list[str]:
        """What is open now and was not in ``before``, one line each; empty when nothing."""
        out: list[str] = []
        threads = [t for t in self.threads if t not in before.threads and t is not threading.current_thread()]
        for t in sorted(threads, key=lambda t: t.name):
            out.append(f"thread {t.name!r}" + (" (daemon)" if t.daemon else "") + f" running {_target(t)}")
        inodes = {i for i in self.sockets if i not in before.sockets}
        if inodes:
            described = _describe_sockets(inodes)
            for inode in sorted(inodes):
                what = described.get(inode, f"inode {inode} (not TCP, UDP or unix: CAN, netlink, ...)")
                out.append(f"socket fd {self.sockets[inode]}: {what}")
        channels: dict[str, int] = {}
        for key, (channel, _q) in self.buses.items():
            if key not in before.buses:
                channels[channel] = channels.get(channel, 0) + 1
        for channel, n in sorted(channels.items()):
            out.append(f"python-can virtual bus on channel {channel!r}" + (f" ({n} open)" if n > 1 else "")
                       + " not shut down")
        return out


def _target(t: threading.Thread) -> str:
    target = getattr(t, "_target", None)
    if target is None:
        return f"{type(t).__module__}.{type(t).__qualname__}.run"
    owner = getattr(target, "__self__", None)
    name = getattr(target, "__qualname__", repr(target))
    module = getattr(target, "__module__", None) or (type(owner).__module__ if owner is not None else "")
    return f"{module}.{name}" if module else name


def grace_s() -> float:
    return float(os.environ.get("ESKIN_TEST_LEAK_GRACE_S", GRACE_S))


def leaks_after(before: Snapshot, grace: float) -> list[str]:
    """Wait up to ``grace`` seconds for what appeared since ``before`` to go away; what is left.

    When something is still open the garbage collector runs (once at once, once at the
    end), so what only it would close does not count as a leak by the luck of its
    timing (its ResourceWarning, if any, still reaches the test run as an error)."""
    deadline = time.monotonic() + grace
    collected = False
    while True:
        leaks = Snapshot().leaks_since(before)
        if not leaks:
            return []
        if not collected:
            gc.collect()
            collected = True
            continue
        if time.monotonic() >= deadline:
            gc.collect()
            return Snapshot().leaks_since(before)
        time.sleep(_POLL_S)


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers", "allow_leaks(reason): the test may leave threads, sockets or virtual CAN buses open")


@pytest.fixture(autouse=True)
def no_leaks(request: pytest.FixtureRequest):
    """Fail the test if it leaves a thread, a socket or a virtual CAN bus open."""
    marker = request.node.get_closest_marker("allow_leaks")
    if marker is not None:
        if not (marker.args and isinstance(marker.args[0], str) and marker.args[0].strip()):
            pytest.fail("allow_leaks needs a reason: @pytest.mark.allow_leaks(\"why\")", pytrace=False)
        yield
        return
    before = Snapshot()
    yield
    grace = grace_s()
    leaks = leaks_after(before, grace)
    if leaks:
        pytest.fail(f"left open after the test (still there {grace:g} s later):\n  " + "\n  ".join(leaks)
                    + "\nclose them in the test (with / try-finally), or mark a deliberate leak with"
                    " @pytest.mark.allow_leaks(\"why\")", pytrace=False)
