"""The cell stepped in virtual time: the same world, detector, register image and PLC
program as the real chain, with the transport latencies drawn from the distributions
measured on it (``latency.py``), deterministically from the episode's seed.

What happens, in time order:

- a scan every ``1 / rate_hz``: the world renders a frame (``CellWorld.frame``), the
  node's integers as the CAN node sends them, the bridge's pipeline, the node's status
  (``NodeStatus``: latch, counts) and the PLC's register image rendered from its
  snapshot (``PlcImage``), as its loop runs them; an image goes out when the loop
  would publish one (a state change at once, a change of what the outputs show, else
  every ``refresh_s``) and lands in the PLC's memory ``SCAN_TO_PLC`` later (in order,
  as on one connection);
- a PLC cycle every ``plc_cycle_s`` from a random phase: the program (``policy.py``)
  reads its memory, and a new force request reaches the gripper ``PLC_TO_GRIPPER``
  later, whose drive takes it up after its dead time (``actuator.py``); an acknowledge
  sets COMMAND in the PLC's memory, which the bridge reads after its next refresh
  write (as its client-mode writer does) and applies at its next step;
- the physics between them, tick by tick (``world.py``).

Two controls skip parts of this: ``fixed`` (the cautious fixed grip: no skin, no
program) and ``oracle`` (the program fed the truth: slip the tick a slide starts,
no warm-up, through the same latencies): the physical limit for the chain's
latencies.
"""

from __future__ import annotations

import collections
from dataclasses import dataclass, field, replace

import numpy as np

from ...calibration import Calibrator
from ...detect.state import GraspState
from ...detect.updates import Update
from ...frames import RawScan
from ...node import Command, Health, NodeStatus
from ...outputs.plc.image import PlcImage, decode_registers
from ...pipeline import Pipeline
from ...profile import Profile
from .actuator import ActuatorSpec
from .gripper import from_register, to_register
from .latency import PLC_TO_GRIPPER, SCAN_TO_PLC, Quantiles
from .outcome import EpisodeResult, result_of
from .policy import GripPolicy, PolicySettings
from .recipes import fixed_grip_n, policy_settings
from .world import TICK_S, CellWorld, Episode

#: The baselines that are no detection method.
FIXED, ORACLE = "fixed", "oracle"


@dataclass(frozen=True)
class ChainSpec:
    """How the cell's chain is set up (the sweeps change these)."""

    rate_hz: float = 100.0
    plc_cycle_s: float = 0.010
    actuator: ActuatorSpec = field(default_factory=ActuatorSpec)
    scan_to_plc: Quantiles = SCAN_TO_PLC
    plc_to_gripper: Quantiles = PLC_TO_GRIPPER
    #: added to every scan -> PLC transport (the latency-budget chart)
    extra_latency_s: float = 0.0
    #: the pads' velocity strengthening (s/m); None: the physics' default
    viscous_s_per_m: float | None = None


def raw_of(calibrator: Calibrator, forces: np.ndarray, max_raw: int) -> np.ndarray:
    """The integers a node sends for these forces (as ``CanLayout.encode`` clips them)."""
    return np.clip(np.rint(calibrator.to_raw(forces)), 0, max_raw)


class _Bridge:
    """The bridge's loop for one node, in virtual time: pipeline, node status, the
    PLC's image, publications (a fresh frame always: the virtual node never falls
    silent)."""

    HEALTH = Health(frame_age_s=0.0)

    def __init__(self, profile: Profile, rate_hz: float, method: str) -> None:
        self.pipeline = Pipeline(profile, rate_hz=rate_hz, method=method)
        chosen = self.pipeline.method
        self.status = NodeStatus(profile.stale_s, chosen.name, chosen.code,
                                 (chosen.scores[0].name, chosen.scores[1].name))
        self.image = PlcImage(profile.modbus.plc)
        self.refresh_s = profile.output.refresh_s
        self.word_order = profile.modbus.plc.word_order
        self.last_pub = float("-inf")
        self.last_conditions = -1

    def observe(self, updates: list[Update]) -> bool:
        urgent = False
        for u in updates:
            urgent |= self.status.observe(u)
        return urgent

    def publish_if_due(self, now: float, urgent: bool) -> tuple[dict[str, int], bool] | None:
        """The published values (and whether they were a refresh) when due, as
        ``NodeLoop.publish_if_due`` decides."""
        conditions = self.status.conditions(0.0, False)
        changed = conditions != self.last_conditions
        if not urgent and not changed and now - self.last_pub < self.refresh_s:
            return None
        snap = self.status.snapshot(self.HEALTH, scans=0, t_event=now, wall_time_s=now, urgent=urgent or changed)
        values = decode_registers(self.image.render(snap), self.word_order)
        self.last_conditions, self.last_pub = conditions, now
        return values, not urgent and not changed


def run_episode(episode: Episode, control: str, profile: Profile, chain: ChainSpec = ChainSpec(),
                settings: PolicySettings | None = None, fixed_n: float | None = None) -> EpisodeResult:
    """One episode under ``control``: a detection method's name, ``fixed`` or ``oracle``."""
    kind = episode.kind
    fixed = fixed_grip_n(kind) if fixed_n is None else fixed_n
    world = CellWorld(episode, chain.actuator, chain.rate_hz, chain.viscous_s_per_m)
    lat = np.random.default_rng((episode.seed, 28))  # the chain's draws, apart from the world's
    to_plc = chain.scan_to_plc.shifted(chain.extra_latency_s) if chain.extra_latency_s else chain.scan_to_plc
    grip_at = episode.task.grip_s
    if control == FIXED:
        world.command(grip_at + chain.plc_to_gripper.draw(lat), from_register(to_register(fixed)))
        world.advance_to(episode.task.end_s)
        return result_of(control, world, [], fixed)
    policy = GripPolicy(settings or replace(policy_settings(kind), fallback_n=fixed))
    oracle = control == ORACLE
    bridge = _Bridge(profile, chain.rate_hz, "none" if oracle else control)
    cal = bridge.pipeline.calibrator
    max_raw = _max_raw(profile)
    period = 1.0 / chain.rate_hz
    cycle = chain.plc_cycle_s
    next_plc = float(lat.uniform(0.0, cycle))
    memory: dict[str, int] = {"STATUS": 0, "HEARTBEAT": 0}
    inbox: collections.deque[tuple[float, dict[str, int], bool]] = collections.deque()
    last_arrival = 0.0
    sent_n = -1.0
    ack_since: float | None = None  # COMMAND's ack bit set in the PLC's memory since
    ack_taken = False  # the bridge has read it: applied at its next step
    was_sliding = False
    j = 0
    while not world.done:
        t_scan = j * period
        while next_plc <= t_scan:  # PLC cycles before this scan
            now = next_plc
            while inbox and inbox[0][0] <= now:
                arrival, values, refresh = inbox.popleft()
                memory = values
                if refresh:
                    # the writer reads COMMAND right after a refresh write
                    if ack_since is not None and ack_since <= arrival:
                        ack_taken, ack_since = True, None
            if not policy.gripping and now >= grip_at:
                policy.grip(now)
            out = policy.cycle(now, memory)
            request = from_register(to_register(out.request_n))  # as the gripper's register holds it
            if request != sent_n:
                sent_n = request
                world.command(now + chain.plc_to_gripper.draw(lat), sent_n)
            if out.ack and ack_since is None and not ack_taken:
                ack_since = now
            next_plc += cycle
        if oracle:  # tick by tick: the truth the instant it changes
            while world.k < int(round(t_scan / TICK_S)) and not world.done:
                world.advance_to((world.k + 1) * TICK_S)
                sliding = world.contact.sliding
                if sliding != was_sliding:
                    was_sliding = sliding
                    urgent = bridge.observe([_truth(world, world.t)])
                    last_arrival = _publish(bridge, world.t, urgent, to_plc, lat, inbox, last_arrival)
        else:
            world.advance_to(t_scan)
        if world.done:
            break
        urgent = False
        if ack_taken:
            ack_taken = False
            before = bridge.status.latched
            bridge.status.apply(Command("ack"))
            urgent = bridge.status.latched != before
        if oracle:
            urgent |= bridge.observe([_truth(world, t_scan)])
        elif not world.renderer.lost(j):
            raw = raw_of(cal, world.frame(j, t_scan), max_raw)
            urgent |= bridge.observe(bridge.pipeline.push(RawScan(j, t_scan, raw, 0, t_scan)))
        last_arrival = _publish(bridge, t_scan, urgent, to_plc, lat, inbox, last_arrival)
        j += 1
    return result_of(control, world, policy.raises, fixed)


def _publish(bridge: _Bridge, now: float, urgent: bool, to_plc: Quantiles, lat: np.random.Generator,
             inbox: collections.deque[tuple[float, dict[str, int], bool]], last_arrival: float) -> float:
    pub = bridge.publish_if_due(now, urgent)
    if pub is None:
        return last_arrival
    arrival = max(last_arrival, now + to_plc.draw(lat))  # one connection: in order
    inbox.append((arrival, pub[0], pub[1]))
    return arrival


def _truth(world: CellWorld, t: float) -> Update:
    """The oracle's update: what the physics says, valid at once."""
    c = world.contact
    grip = 0.0 if c.over else world.grip_n
    state = GraspState.SLIP if c.sliding else GraspState.STABLE if grip > 0.2 else GraspState.NO_CONTACT
    dx, dy = c.displacement_mm  # the centre of force moves with the object
    return Update(t, 0.0, 0.0, int(state), True, grip, dx, dy, 0)


def _max_raw(profile: Profile) -> int:
    from ...bus.can.layout import CanLayout

    return CanLayout.from_profile(profile, fd=False).max_raw
