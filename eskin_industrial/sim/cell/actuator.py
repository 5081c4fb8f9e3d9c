"""The gripper's drive: a force request takes effect after a dead time, and the force
follows it at a limited rate.

A request is what the gripper's register holds; the drive takes it up ``dead_s``
after it arrived (the gripper's own cycle and its current loop: 5-10 ms register
updates, a setpoint handshake of 2-3 cycles on IO-Link grippers) and moves the force
towards it at ``rate_n_per_s`` at most (no maker publishes a slew rate: 200-1,000 N/s
is swept).  Pure: the caller gives the times.

A gripper class (``grippers.py``) adds what a real drive does to a request: it grips
no lighter than its minimum force, sets the force in steps, and the force it holds is
off the setting by a few per cent (drawn once per episode: the drive's calibration).
"""

from __future__ import annotations

import collections
from dataclasses import dataclass, field

from ...schema import non_negative, positive


@dataclass(frozen=True)
class ActuatorSpec:
    rate_n_per_s: float = field(default=500.0, metadata=positive())
    dead_s: float = field(default=0.010, metadata=non_negative())
    #: The gripper's rated force: a request above it is refused (exception 03).
    max_n: float = field(default=100.0, metadata=positive())
    #: The lightest grip it holds: a closing request below it grips with it.
    min_n: float = field(default=0.0, metadata=non_negative())
    #: The force setting's step (N) from ``min_n`` (0: the register's 0.01 N only).
    step_n: float = field(default=0.0, metadata=non_negative())
    #: The force held is off the setting by up to this share, either way.
    error_share: float = field(default=0.0, metadata=non_negative())

    def setting_n(self, request_n: float) -> float:
        """The force setting a request comes to: 0 opens; else at least ``min_n``, on
        the steps, at most ``max_n``."""
        if request_n <= 0.0:
            return 0.0
        f = max(request_n, self.min_n)
        if self.step_n > 0.0:
            f = self.min_n + round((f - self.min_n) / self.step_n) * self.step_n
        return min(f, self.max_n)


class Actuator:
    """Requests in, force out; ``step(t, dt)`` advances to ``t``."""

    def __init__(self, spec: ActuatorSpec, error: float = 0.0) -> None:
        """``error``: this drive's force error, a share (within ``spec.error_share``)."""
        self.spec = spec
        self.error = error
        self.force_n = 0.0
        self.target_n = 0.0  #: the request the drive works to now
        self.request_n = 0.0  #: the newest request received (the register)
        self._pending: collections.deque[tuple[float, float]] = collections.deque()

    def command(self, t_arrival: float, request_n: float) -> None:
        """A request that reached the gripper at ``t_arrival`` (in order of arrival)."""
        self.request_n = request_n
        self._pending.append((t_arrival + self.spec.dead_s, self.spec.setting_n(request_n) * (1.0 + self.error)))

    def step(self, t: float, dt: float) -> float:
        """The force at ``t``, ``dt`` after the previous step."""
        pending = self._pending
        while pending and pending[0][0] <= t + 1e-12:
            self.target_n = pending.popleft()[1]
        gap = self.target_n - self.force_n
        if gap:
            most = self.spec.rate_n_per_s * dt
            self.force_n = self.target_n if abs(gap) <= most else self.force_n + (most if gap > 0 else -most)
        return self.force_n

    @property
    def settled(self) -> bool:
        """At the newest request, nothing pending."""
        return not self._pending and self.force_n == self.target_n
