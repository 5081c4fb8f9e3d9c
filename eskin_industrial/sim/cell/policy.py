"""The PLC program in the loop: a grip policy on the bridge's registers, run once a
scan cycle, as ``FB_SlipGuard`` (docs/plc.md) reads them.

Grip lightly; on a rising SLIP_LATCHED raise the force request by a step (or to the
maximum, or, ``hybrid``, a step first and the maximum if the slide goes on); while
SLIP stays set, raise by another step each ``repeat_s`` if the centre
of force (XC, YC) has moved by ``repeat_mm`` over the last ``repeat_s`` and since
``settle_s`` after the last raise (a detector's slip state outlasts the slide by some
tenths of a second: SLIP alone does not say the object still moves; and a soft pad's
contact grows with the force, so the raise itself moves the centre of force), or by
``creep_mm`` in all from where it stood ``settle_s`` after the last raise (a creep too
slow for ``repeat_mm`` per ``repeat_s`` still loses the part, a millimetre at a time);
acknowledge the latch once the slip is over; after ``quiet_s`` of trusted data with no
slip, relax by ``relax_share`` of the request, no lower than the light grip (nor, with
``relax_floor``, than that multiple of the force it last slipped at).

"No slip" and "I don't know" are not the same: while the data is not trusted (the
heartbeat still, DATA_VALID clear, SENSOR_STALE, BUS_FAULT or BRIDGE_OFFLINE) nothing
is relaxed and the request goes up to ``fallback_n``, the force a cautious integrator
would hold with no skin at all (the motion cannot be stopped from here, so the grip is
made safe instead).  Right after the grip command the skin has no verdict yet (its
warm-up): until its first trusted verdict in contact, or ``grace_s`` after the grip
command, that is not yet a fault.

Pure: the caller reads the registers (decoded) and writes what comes out.
"""

from __future__ import annotations

import collections
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Literal

from ...outputs.plc.image import Status
from ...schema import non_negative, positive

_TRUST_BREAKERS = int(Status.SENSOR_STALE | Status.BUS_FAULT | Status.BRIDGE_OFFLINE)
_VALID, _SLIP, _LATCHED = int(Status.DATA_VALID), int(Status.SLIP), int(Status.SLIP_LATCHED)
_CONTACT = int(Status.CONTACT)


@dataclass(frozen=True)
class PolicySettings:
    """The grip policy's parameters (forces in N; per object: ``recipes.py``)."""

    light_n: float = field(metadata=positive())
    step_n: float = field(metadata=positive())
    max_n: float = field(metadata=positive())
    fallback_n: float = field(metadata=positive())
    #: ``step``: a slip raises by ``step_n``; ``max``: straight to ``max_n``; ``hybrid``: a slip
    #: raises by ``step_n``, and a slide that goes on past it goes to ``max_n``.  Under weak
    #: velocity strengthening a load past static friction accelerates off the pads instead of
    #: settling at a few cm/s: a second step 0.2 s later comes when the object has gone, and
    #: ``max`` on every slip crushes what one step would have held (a weak cup under the cap)
    mode: Literal["step", "max", "hybrid"] = "step"
    #: ``hybrid``: the distance the centre of force may move from where it stood at the slip
    #: alarm before the request goes to ``max_n`` at once, whatever ``repeat_s`` and
    #: ``settle_s`` say (more than the soft pads' growth under a step, 1-1.5 mm, and the
    #: light grip's jitter, +-0.5 mm; 0: only the repeat test escalates)
    escalate_mm: float = field(default=3.0, metadata=non_negative())
    repeat_s: float = field(default=0.2, metadata=positive())
    repeat_mm: float = field(default=1.0, metadata=non_negative())
    #: while SLIP stays set, the distance from where the centre stood ``settle_s`` after the
    #: last raise that raises again however slowly it was covered (0: off)
    creep_mm: float = field(default=2.0, metadata=non_negative())
    settle_s: float = field(default=0.1, metadata=non_negative())
    quiet_s: float = field(default=3.0, metadata=positive())
    relax_share: float = field(default=0.1, metadata=positive())
    #: relax no lower than this multiple of the force the object last slipped at (0: the light grip)
    relax_floor: float = field(default=0.0, metadata=non_negative())
    #: a relax spread over this long, a little each cycle (0: at once).  A soft pad's contact
    #: shrinks as the force falls, so the centre of force moves with a relax; at once, on the
    #: hand's light grip of a glass, that moved it by half a millimetre in a few ms, which a
    #: detector at 1 kHz read as a slide
    relax_s: float = field(default=0.0, metadata=non_negative())
    heartbeat_timeout_s: float = field(default=0.5, metadata=positive())
    grace_s: float = field(default=1.2, metadata=non_negative())


@dataclass(frozen=True)
class Raise:
    t: float
    request_n: float
    why: Literal["slip", "still slipping", "no verdict"]


@dataclass(frozen=True)
class PlcOutput:
    request_n: float  #: the force request for the gripper
    ack: bool  #: acknowledge the slip latch (COMMAND bit 0)
    no_verdict: bool  #: the skin cannot tell now (FB_SlipGuard's bNoVerdict)
    events: tuple[str, ...] = ()  #: what changed, for a log


class GripPolicy:
    """One gripper's program; ``grip(now)`` closes it, ``cycle(now, values)`` is one scan."""

    def __init__(self, settings: PolicySettings) -> None:
        self.settings = settings
        self.request_n = 0.0
        self.gripping = False
        self.raises: list[Raise] = []
        self.relaxes = 0
        self.no_verdict = False
        self._grip_t = 0.0
        self._trusted_once = False
        self._last_hb = -1
        self._hb_t = 0.0
        self._latched_before = False
        self._last_raise = float("-inf")
        self._last_calm = 0.0  #: the last moment the grip had a reason not to relax
        self._relax_from: tuple[float, float] | None = None  #: (start, request) of a relax under way
        self._slip_force = 0.0
        #: (time, XC, YC) of the cycles of the last ``repeat_s``: the centre of force's recent path
        self._path: collections.deque[tuple[float, int, int]] = collections.deque()
        #: where the centre of force stood once the last raise had settled (None: not slipping)
        self._anchor: tuple[float, int, int] | None = None
        #: where the centre of force stood at the slip alarm (None: not slipping)
        self._alarm: tuple[float, int, int] | None = None

    def grip(self, now: float) -> float:
        """Close on the object with the light grip; returns the request."""
        self.gripping = True
        self._grip_t = self._last_calm = now
        self.request_n = self.settings.light_n
        return self.request_n

    def _raise(self, now: float, to: float, why: Literal["slip", "still slipping", "no verdict"]) -> bool:
        to = min(to, max(self.settings.max_n, self.settings.fallback_n) if why == "no verdict" else self.settings.max_n)
        if to <= self.request_n:
            return False
        self.request_n = to
        self._last_raise = now
        self._anchor = None  # the creep is counted again from once this raise has settled
        self.raises.append(Raise(now, to, why))
        return True

    def cycle(self, now: float, v: Mapping[str, int]) -> PlcOutput:
        cfg = self.settings
        events: list[str] = []
        if v["HEARTBEAT"] != self._last_hb:
            self._last_hb, self._hb_t = v["HEARTBEAT"], now
        alive = now - self._hb_t <= cfg.heartbeat_timeout_s
        status = v["STATUS"]
        trusted = alive and bool(status & _VALID) and not status & _TRUST_BREAKERS
        slip = alive and bool(status & _SLIP)
        latched = alive and bool(status & _LATCHED)
        ack = False
        path = self._path
        path.append((now, v.get("XC", 0), v.get("YC", 0)))
        since = max(now - cfg.repeat_s, self._last_raise + cfg.settle_s)
        while path[0][0] < since and len(path) > 1:
            path.popleft()
        if not slip:
            self._anchor = None
            if not latched:
                self._alarm = None
        elif self._anchor is None and now >= self._last_raise + cfg.settle_s:
            self._anchor = path[-1]
        if not self.gripping:
            self._latched_before = latched
            return PlcOutput(self.request_n, False, not trusted)
        if trusted and status & _CONTACT:
            self._trusted_once = True  # the skin's first verdict on this grasp: its warm-up is over
        if latched and not self._latched_before:
            self._slip_force = self.request_n
            self._alarm = path[-1]
            to = cfg.max_n if cfg.mode == "max" else self.request_n + cfg.step_n
            if self._raise(now, to, "slip"):
                events.append(f"SLIP: grip force request raised to {self.request_n:.2f} N")
        elif (cfg.mode == "hybrid" and slip and cfg.escalate_mm > 0 and self._alarm is not None
              and self.request_n < cfg.max_n and _moved_mm(self._alarm, path[-1]) >= cfg.escalate_mm):
            # the step did not stop it: the slide is running away, the maximum now
            self._slip_force = self.request_n
            if self._raise(now, cfg.max_n, "still slipping"):
                events.append(f"still slipping: grip force request raised to the maximum, {self.request_n:.2f} N")
        elif slip and now - self._last_raise >= cfg.repeat_s and (
                _moved_mm(path[0], path[-1]) >= cfg.repeat_mm
                or (cfg.creep_mm > 0 and self._anchor is not None and _moved_mm(self._anchor, path[-1]) >= cfg.creep_mm)):
            self._slip_force = self.request_n
            to = cfg.max_n if cfg.mode == "hybrid" else self.request_n + cfg.step_n  # hybrid: one step was not enough
            if self._raise(now, to, "still slipping"):
                events.append(f"still slipping: grip force request raised to {self.request_n:.2f} N")
        if latched and not slip:
            ack = True  # the latch outlasts the slip: acknowledge once it is over
        self._latched_before = latched
        no_verdict = not trusted and (self._trusted_once or now - self._grip_t >= cfg.grace_s)
        if no_verdict != self.no_verdict:
            self.no_verdict = no_verdict
            events.append(f"NO VERDICT ({_why(alive, status)}): no relaxing, grip raised to the fallback" if no_verdict
                          else "data trusted")
        if no_verdict:
            if self._raise(now, cfg.fallback_n, "no verdict"):
                events.append(f"no verdict: grip force request raised to {self.request_n:.2f} N")
        if not trusted or slip or latched:
            self._last_calm = now
            self._relax_from = None  # a relax under way stops where it is
        elif now - max(self._last_calm, self._last_raise) >= cfg.quiet_s:
            floor = max(cfg.light_n, cfg.relax_floor * self._slip_force)
            if self.request_n > floor:
                if self._relax_from is None or self._relax_from[0] < self._last_raise:
                    self._relax_from = (now, self.request_n)
                start, start_n = self._relax_from
                done = 1.0 if cfg.relax_s <= 0 else min(1.0, (now - start) / cfg.relax_s)
                self.request_n = max(floor, start_n * (1.0 - cfg.relax_share * done))
                if done >= 1.0 or self.request_n <= floor:
                    self._relax_from = None
                    self.relaxes += 1
                    self._last_calm = now
                    events.append(f"quiet: grip force request relaxed to {self.request_n:.2f} N")
        return PlcOutput(self.request_n, ack, no_verdict, tuple(events))


def _moved_mm(a: tuple[float, int, int], b: tuple[float, int, int]) -> float:
    """Distance between two centres of force as registers (0.01 mm), with their times."""
    return ((a[1] - b[1]) ** 2 + (a[2] - b[2]) ** 2) ** 0.5 / 100.0


def _why(alive: bool, status: int) -> str:
    """What makes the data untrustworthy, for the log."""
    if not alive:
        return "heartbeat still"
    names = [b.name for b in (Status.SENSOR_STALE, Status.BUS_FAULT, Status.BRIDGE_OFFLINE) if status & b]
    return ", ".join(str(n) for n in names) or "DATA_VALID clear"
