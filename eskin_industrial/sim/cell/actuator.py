"""The gripper's drive: a force request takes effect after a dead time, and the force
follows it at a limited rate.

A request is what the gripper's register holds; the drive takes it up ``dead_s``
after it arrived (the gripper's own cycle and its current loop: 5-10 ms register
updates, a setpoint handshake of 2-3 cycles on IO-Link grippers) and moves the force
towards it at ``rate_n_per_s`` at most (no maker publishes a slew rate: 200-1,000 N/s
is swept).  Pure: the caller gives the times.
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


class Actuator:
    """Requests in, force out; ``step(t, dt)`` advances to ``t``."""

    def __init__(self, spec: ActuatorSpec) -> None:
        self.spec = spec
        self.force_n = 0.0
        self.target_n = 0.0  #: the request the drive works to now
        self.request_n = 0.0  #: the newest request received (the register)
        self._pending: collections.deque[tuple[float, float]] = collections.deque()

    def command(self, t_arrival: float, request_n: float) -> None:
        """A request that reached the gripper at ``t_arrival`` (in order of arrival)."""
        self.request_n = request_n
        self._pending.append((t_arrival + self.spec.dead_s, request_n))

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
