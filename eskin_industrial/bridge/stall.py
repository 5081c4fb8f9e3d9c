"""A node loop that stops turning does not leave its last verdict standing.

A loop turns at least every 50 ms while it runs (``NodeLoop.MAX_WAIT_S``), and every
turn is one beat.  A loop can still stop turning: a call of an essential output that
hangs (it is called on the loop's thread, :mod:`.supervise`), a source call that never
returns.  The PLC's server goes on answering from its own thread meanwhile, so the
block would go on saying DATA_VALID and "stable" about a grasp no one looks at any more.
Past ``[supervision] loop_stall_s`` without a beat, the loop's nodes get their offline
image (nothing claimed, as at a stop) through every sink, from a thread of its own (the
call that hangs may hold a sink's lock), and one line: ``loop_stalled``; the loop's next
publication replaces it, and ``loop_resumed`` says how long it was gone.  systemd's
watchdog restarts a bridge whose loop stays stuck (docs/operations.md).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from typing import Protocol

from .loop import NodeLoop


class NodeRun(Protocol):
    """What the guard reads of a node inside the bridge (``runtime.NodeRun``)."""

    @property
    def name(self) -> str: ...

    @property
    def loop(self) -> NodeLoop: ...


class StallGuard:
    def __init__(self, limit_s: float, log: Callable[..., None]) -> None:
        self.limit_s = limit_s
        self._log = log
        self._loops: list[tuple[str, Sequence[NodeRun]]] = []
        self._seen: list[tuple[int, float]] = []
        self._stalled: dict[int, float] = {}  #: loop index -> when its last beat was
        self._offlining: threading.Thread | None = None
        self._last_check = time.monotonic()

    def add(self, name: str, runs: Sequence[NodeRun]) -> None:
        """The next loop (in the order of the beats)."""
        self._loops.append((name, runs))
        self._seen.append((0, time.monotonic()))

    def check(self, beats: Sequence[int], alive: Sequence[bool], tick_s: float, now: float | None = None) -> None:
        """One look, every ``tick_s``."""
        now = time.monotonic() if now is None else now
        if now - self._last_check > max(self.limit_s / 2, 2.5 * tick_s):
            # This thread was held back (the whole process paused, a loaded host): the
            # loops were too, and must be seen not turning by a guard that was awake.
            self._seen = [(beats[i], now) for i in range(len(self._seen))]
            self._last_check = now
            return
        self._last_check = now
        for i, (name, runs) in enumerate(self._loops):
            beat, since = self._seen[i]
            if beats[i] != beat:
                self._seen[i] = (beats[i], now)
                if i in self._stalled:
                    gone = now - self._stalled.pop(i)
                    self._log("loop_resumed", "warning", loop=name, after_s=round(gone, 3))
                continue
            if i in self._stalled or not alive[i] or now - since < self.limit_s:
                continue
            self._stalled[i] = since
            if any(r.loop.offline for r in runs):
                continue  # (already offline: its source ended)
            self._log("loop_stalled", "error", loop=name, node=",".join(r.name for r in runs),
                      for_s=round(now - since, 3), then="offline")
            self._offline(runs)

    def _offline(self, runs: Sequence[NodeRun]) -> None:
        if self._offlining is not None and self._offlining.is_alive():
            return  # the last one is stuck too: no pile of threads behind one lock
        self._offlining = threading.Thread(target=_publish_offline, args=(runs,), name="stall-offline", daemon=True)
        self._offlining.start()


def _publish_offline(runs: Sequence[NodeRun]) -> None:
    for run in runs:
        loop = run.loop
        snap = loop.offline_snapshot()
        for sink in loop.sinks:
            try:
                sink.publish(snap)
            except Exception:  # noqa: BLE001 - the others still get it; a failing sink fails on its own
                pass


