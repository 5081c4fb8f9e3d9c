"""What the commands that write a PLC do with each signal.

A signal whose default action ends the process would end it without the last
image: a client-mode PLC keeps what was written last, so it would read the last
"stable" with DATA_VALID for ever.  Every such signal an operator or a terminal can
send is therefore either a clean stop (the loops stop, every block is left reading
BRIDGE_OFFLINE, the Sparkplug deaths are sent) or has a use and leaves the process
running:

========  =============================================================
TERM      stop cleanly (``systemctl stop``), exit 0
INT       stop cleanly (Ctrl-C), exit 0
HUP       stop cleanly (the terminal or the SSH session went away), exit 0
QUIT      stop cleanly (Ctrl-\\), exit 0
USR2      stop cleanly, exit 0 (the logs go to stderr, nothing to reopen)
ABRT      stop cleanly, exit 1 (systemd's watchdog: the loop hung)
USR1      log every counter now; keeps running
PIPE      ignored (a closed stdout or stderr is an error on that write only)
========  =============================================================

KILL cannot be caught: the HEARTBEAT register stops, which is what the PLC's
watchdog is for.  The handlers only set plain attributes (:class:`SignalFlags`);
the caller's supervising thread acts on them at its next tick.
"""

from __future__ import annotations

import signal
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType
from typing import Any

#: Signals that stop the bridge cleanly; exit status 0 unless listed in FAILING.
STOPPING: tuple[signal.Signals, ...] = (signal.SIGTERM, signal.SIGINT, signal.SIGHUP, signal.SIGQUIT,
                                        signal.SIGUSR2, signal.SIGABRT)
#: Stopping signals that report a failure (exit 1): systemd's WatchdogSignal.
FAILING: frozenset[signal.Signals] = frozenset({signal.SIGABRT})
#: Log (or print) the counters and go on.
COUNTERS = signal.SIGUSR1

#: The exit status after a failure: a loop failed, or SIGABRT (systemd's watchdog).
#: 0 is a stop as asked; 2 and 3 come from the errors raised before anything runs
#: (errors.py); the table is in docs/operations.md, "Exit codes".
EXIT_FAILED = 1


class SignalFlags:
    """What the signals asked for: plain attributes, written by the handlers and read
    by the code they interrupted, both on the main thread.  No lock and no Event:
    a handler runs between two bytecodes of the main thread, which may hold the very
    lock an ``Event.set()`` would wait for (a deadlock); the supervisor looks at
    these at every tick instead."""

    def __init__(self) -> None:
        self.reason = ""  #: the first stopping signal's name ("" while none came)
        self.counters = 0  #: USR1s received

    @property
    def stopping(self) -> bool:
        return bool(self.reason)

    @property
    def failing(self) -> bool:
        return self.reason in {s.name for s in FAILING}


@contextmanager
def handled_signals() -> Iterator[SignalFlags]:
    """The handlers of the table above for the length of the block (the main thread
    only, as Python requires), the previous ones restored on the way out."""
    flags = SignalFlags()

    def stop(signum: int, _frame: FrameType | None) -> None:
        if not flags.reason:
            flags.reason = signal.Signals(signum).name

    def counters(_signum: int, _frame: FrameType | None) -> None:
        flags.counters += 1

    before: dict[signal.Signals, Any] = {}
    try:
        for sig in STOPPING:
            before[sig] = signal.signal(sig, stop)
        before[COUNTERS] = signal.signal(COUNTERS, counters)
        # Python ignores SIGPIPE at start; an embedding program may not have.
        before[signal.SIGPIPE] = signal.signal(signal.SIGPIPE, signal.SIG_IGN)
        yield flags
    finally:
        for sig, handler in before.items():
            signal.signal(sig, handler)
