"""The cell in real time, through the real chain:

    world (physics, gripper drive) -> CAN node (python-can) -> bridge (CAN source,
    pipeline, register image, PLC client) -> Modbus TCP -> PLC stand-in (the grip
    policy on a fixed scan cycle) -> Modbus TCP -> gripper device -> the world

The node thread owns the world: at each scan it takes the force requests the gripper
device received (with their arrival times), advances the physics to the scan's time,
renders the frame and sends it.  The bridge is the product's own (a one-node
configuration, as ``eskin-bus demo`` runs it), on the calling thread.  The PLC
stand-in keeps its memory as the commissioning stand-in does (``sim/plc.py``) and runs
:class:`~.policy.GripPolicy` every ``plc_cycle_s`` from its own thread; it writes the
gripper's registers with the package's Modbus TCP client, and the gripper is served
by pymodbus.  Times are seconds since the node's first scan (the scene's clock).
"""

from __future__ import annotations

import collections
import os
import threading
import time
from collections.abc import Callable
from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass, field, replace

import can
import numpy as np

from ...bridge.config import BridgeConfig, NodeConfig, ResolvedNode
from ...bridge.loop import NodeLoop
from ...bridge.runtime import SingleNode
from ...bus.can.layout import CanLayout
from ...bus.can.reader import open_bus
from ...calibration import Calibrator
from ...detect.updates import Update
from ...errors import ModbusFault
from ...modbus.pymodbus_io import RegisterServer
from ...modbus.tcp_master import PipelinedTcpMaster
from ...outputs.plc.image import CMD_ACK, REG, STATUS_COUNT, TAIL_AT, TAIL_COUNT, decode_registers, decode_tail
from ...outputs.plc.options import PlcOptions
from ...profile import ModbusPlcSection, Profile
from ..can_node import CanNode, Faults
from ..demo import free_port
from ..plc import PlcMemory
from .gripper import GREG, Action, GripperRegisters, GripperState, from_register, to_register
from .outcome import EpisodeResult, result_of
from .policy import GripPolicy, PolicySettings
from .recipes import fixed_grip_n, policy_settings
from .virtual import ChainSpec, raw_of
from .world import CellWorld, Episode

#: The cell's bridge reads the sensor stale after this long without a scan (the
#: profile's default is 2.5 scan periods, 25 ms at 100 Hz): the simulated node is a
#: thread, and on a shared machine it falls tens of milliseconds behind its deadlines
#: now and then, which a node with its own clock does not; its silence for longer than
#: this is still "no verdict" to the PLC within a tenth of a second.
STALE_S = 0.1


class CellNode(CanNode):
    """A sensor node whose scans are rendered from the world as it goes, not played
    from a recording; faults act on its frames as on any simulated node's."""

    def __init__(self, layout: CanLayout, bus: can.BusABC, world: CellWorld, calibrator: Calibrator,
                 gripper: GripperState, requests: collections.deque[tuple[float, float]], heartbeat_s: float,
                 faults: Faults = Faults()) -> None:
        super().__init__(layout, bus, np.zeros((1, calibrator.taxels)), world.rate_hz, heartbeat_s, faults)
        self.world = world
        self.calibrator = calibrator
        self.gripper = gripper
        self.requests = requests
        self.t0 = 0.0  #: monotonic time of scan 0
        #: monotonic time each scan went out (the latency measurement's start)
        self.sent: list[float] = []
        self._stop = threading.Event()

    def stop(self) -> None:
        self._stop.set()

    def run_cell(self, t0: float) -> None:
        world, lay, st, f = self.world, self.layout, self.stats, self.faults
        self.t0 = t0
        period = 1.0 / self.rate_hz
        silent_lo = silent_hi = -1
        if f.silent_at_s is not None:
            silent_lo = int(round(f.silent_at_s * self.rate_hz))
            silent_hi = silent_lo + int(round(f.silent_for_s * self.rate_hz))
        requests, gripper = self.requests, self.gripper
        j = 0
        while not self._stop.is_set():
            deadline = t0 + j * period
            delay = deadline - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            else:
                st.late_s = max(st.late_s, -delay)
            while requests:
                t_mono, force = requests.popleft()
                world.command(t_mono - t0, force)
            t = j * period
            world.advance_to(t)
            c = world.contact
            gripper.target_n = world.actuator.target_n
            gripper.force_n = world.grip_n
            gripper.lost = c.over
            gripper.holding = world.grip_n > 0 and not c.over
            if world.done:
                break
            st.scans += 1
            if silent_lo <= j < silent_hi or world.renderer.lost(j):
                st.silent_scans += 1
            else:
                raw = raw_of(self.calibrator, world.frame(j, t), lay.max_raw)
                for can_id, data in lay.encode(np.array([j]), raw[None, :])[0]:
                    self._emit(self._message(can_id, data))
            self.sent.append(time.monotonic())
            if j % self.heartbeat_every == self.heartbeat_every - 1:
                self._heartbeat(j)
            j += 1
        if self._held is not None:
            held, self._held = self._held, None
            self._send(held)
        st.elapsed_s = time.monotonic() - t0


class PlcProgram:
    """The PLC stand-in with the grip policy: its memory served over Modbus TCP (the
    bridge writes it, client mode), a scan every ``cycle_s``, the gripper written over
    Modbus TCP."""

    def __init__(self, settings: ModbusPlcSection, port: int, policy: GripPolicy, gripper_port: int,
                 cycle_s: float, grip_s: float, echo: Callable[[str], None] | None = None) -> None:
        self.settings = settings
        self.policy = policy
        self.cycle_s = cycle_s
        self.grip_s = grip_s
        self.echo = echo
        self.memory = PlcMemory(settings.base_address, on_write=self._on_write)
        self.memory.regs[REG["ENABLE"].offset] = 1  # the program enables detection
        self.server = RegisterServer(self.memory, tcp=("127.0.0.1", port))
        self.master = PipelinedTcpMaster("127.0.0.1", gripper_port, unit_id=1, timeout_s=0.5)
        self.t0 = 0.0
        #: (monotonic, STATE) of every write the bridge made (the latency measurement)
        self.writes: list[tuple[float, int]] = []
        #: monotonic time just before each write to the gripper
        self.gripper_writes: list[float] = []
        self.gripper_failures = 0
        self.request_n = 0.0
        self.no_verdict = False
        self._phase_s = 0.0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def _on_write(self, _t: float) -> None:
        self.writes.append((time.monotonic(), self.memory.regs[REG["STATE"].offset]))

    def _say(self, text: str) -> None:
        if self.echo is not None:
            self.echo(f"{time.monotonic() - self.t0:7.3f} s  {text}")

    def start(self) -> PlcProgram:
        self.server.start()
        self.master.connect()
        return self

    def run(self, t0: float, phase_s: float) -> None:
        """Scan from ``t0 + phase_s`` on; times are seconds since ``t0``."""
        self.t0 = t0
        self._phase_s = phase_s
        self._thread = threading.Thread(target=self._scan, name="cell-plc", daemon=True)
        self._thread.start()

    def _write_gripper(self, values: list[int], address: int) -> None:
        self.gripper_writes.append(time.monotonic())
        try:
            self.master.write_registers(address, values)
        except ModbusFault as exc:
            self.gripper_failures += 1
            self._say(f"gripper write failed: {exc}")

    def _scan(self) -> None:
        # a fixed cycle from an arbitrary phase, as a PLC's task runs beside the bridge
        j = 0
        wo = self.settings.word_order
        sent = -1
        while not self._stop.is_set():
            deadline = self.t0 + self._phase_s + j * self.cycle_s
            delay = deadline - time.monotonic()
            if delay > 0 and self._stop.wait(delay):
                return
            j += 1
            now = time.monotonic() - self.t0
            regs = self.memory.regs
            values = decode_registers(list(regs[:STATUS_COUNT]), wo)
            values.update(decode_tail(regs[TAIL_AT:TAIL_AT + TAIL_COUNT]))
            policy = self.policy
            if not policy.gripping and now >= self.grip_s:
                request = to_register(policy.grip(now))
                self._say(f"grip: close at {from_register(request):.2f} N")
                self._write_gripper([int(Action.GO), request], GREG["ACTION"].offset)
                sent = request
            out = policy.cycle(now, values)
            for e in out.events:
                self._say(e)
            self.no_verdict = out.no_verdict
            request = to_register(out.request_n)
            if policy.gripping and request != sent:
                self._write_gripper([request], GREG["FORCE_REQUEST"].offset)
                sent = request
            self.request_n = from_register(sent) if sent >= 0 else 0.0
            if out.ack:
                regs[REG["COMMAND"].offset] |= CMD_ACK

    def halt(self) -> None:
        """Stop scanning (the episode is over); the memory is still served."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2)

    def stop(self) -> None:
        self.halt()
        self.master.close()
        self.server.stop()


@dataclass(frozen=True)
class CellParts:
    """The running cell, for a live view that watches it (``run_cell(live=...)``)."""

    profile: Profile
    loop: NodeLoop
    program: PlcProgram
    gripper: GripperState
    node: CellNode
    episode: Episode
    fixed_n: float
    started: float  #: ``time.monotonic()`` at the start


@dataclass
class CellRun:
    result: EpisodeResult
    updates: list[Update] = field(default_factory=list)
    counters: dict[str, int] = field(default_factory=dict)
    #: a scan's send -> the PLC's memory holds the state decided on it (s), per state change
    scan_to_plc_s: list[float] = field(default_factory=list)
    #: the PLC's write of a request -> the gripper's receipt of it (s)
    plc_to_gripper_s: list[float] = field(default_factory=list)
    late_s: float = 0.0  #: the node's worst lateness behind its scan deadlines


def run_cell(profile: Profile, episode: Episode, method: str, *, chain: ChainSpec = ChainSpec(),
             settings: PolicySettings | None = None, fixed_n: float | None = None,
             say: Callable[[str], None] | None = None, plc_echo: Callable[[str], None] | None = None,
             faults: Faults = Faults(), drain_s: float = 0.3,
             live: Callable[[CellParts], AbstractContextManager[object]] | None = None) -> CellRun:
    """Run ``episode`` through the real chain with ``method`` deciding; ``say`` gets the
    bridge's state changes, ``plc_echo`` the PLC program's events."""
    kind = episode.kind
    fixed = fixed_grip_n(kind) if fixed_n is None else fixed_n
    policy = GripPolicy(settings or replace(policy_settings(kind), fallback_n=fixed))
    world = CellWorld(episode, chain.actuator, chain.rate_hz, chain.viscous_s_per_m)
    # the bridge's profile: this method, this rate, the node's staleness as above
    prof = replace(profile, detector=replace(profile.detector, method=method),
                   sensor=replace(profile.sensor, rate_hz=chain.rate_hz),
                   output=replace(profile.output, stale_s=STALE_S))
    layout = CanLayout.from_profile(prof, fd=False)
    cal = Calibrator.from_section(prof.calibration, prof.taxels)
    requests: collections.deque[tuple[float, float]] = collections.deque()
    arrivals: list[float] = []
    state = GripperState()

    def on_request(t_mono: float, force_n: float) -> None:  # the gripper's server thread
        arrivals.append(t_mono)
        requests.append((t_mono, force_n))

    gripper = GripperRegisters(state, chain.actuator.max_n, on_request)
    gripper_port, plc_port = free_port(), free_port()
    channel = f"eskin-cell-{os.getpid()}-{plc_port}"
    updates: list[Update] = []

    def observed(u: Update) -> None:
        if say is not None and (not updates or u.state != updates[-1].state):
            from ...view.live import change_line

            say(change_line(u))
        updates.append(u)

    node_cfg = NodeConfig.of("cell", prof.source, "can", rate_hz=chain.rate_hz, interface="virtual", channel=channel,
                             fd=False)
    cfg = BridgeConfig(node=(node_cfg,), outputs={"plc": PlcOptions(mode="client", host="127.0.0.1", port=plc_port)})
    gripper_server = RegisterServer(gripper, tcp=("127.0.0.1", gripper_port)).start()
    program = PlcProgram(prof.modbus.plc, plc_port, policy, gripper_port, chain.plc_cycle_s, episode.task.grip_s,
                         echo=plc_echo)
    closers: list[Callable[[], None]] = [gripper_server.stop]
    try:
        program.start()
        closers.append(program.stop)
        single = SingleNode(cfg, ResolvedNode(node_cfg, prof), on_update=observed)
    except BaseException:
        for close in reversed(closers):
            close()
        raise
    loop = single.loop
    tx = open_bus("virtual", channel)
    node = CellNode(layout, tx, world, cal, state, requests, prof.can.heartbeat_s, faults)
    parts = CellParts(prof, loop, program, state, node, episode, fixed, time.monotonic())
    node_thread: threading.Thread | None = None
    try:
        with single, live(parts) if live is not None else nullcontext():
            t0 = time.monotonic() + 0.05  # the first scan and the PLC's first cycle, a moment from now
            node_thread = threading.Thread(target=node.run_cell, args=(t0,), name="cell-node", daemon=True)
            node_thread.start()
            program.run(t0, float(np.random.default_rng((episode.seed, 28)).uniform(0.0, chain.plc_cycle_s)))
            while node_thread.is_alive():
                loop.step()
            program.halt()  # the episode is over: the program's verdict on a silent sensor is not the cell's
            end = time.monotonic() + drain_s
            while time.monotonic() < end:
                loop.step()
    finally:
        node.stop()
        if node_thread is not None:
            node_thread.join(timeout=5)
        tx.shutdown()
        single.close()
        for close in reversed(closers):
            close()
    run = CellRun(result_of(method, world, policy.raises, fixed), updates, loop.counters(), late_s=node.stats.late_s)
    run.scan_to_plc_s = _scan_to_plc(updates, node.sent, program.writes, chain.rate_hz)
    run.plc_to_gripper_s = [b - a for a, b in zip(program.gripper_writes, arrivals)]
    return run


def _scan_to_plc(updates: list[Update], sent: list[float], writes: list[tuple[float, int]],
                 rate_hz: float) -> list[float]:
    """For each state change, from the send of the scan that decided it to the first
    write into the PLC's memory that carries it."""
    out: list[float] = []
    prev: int | None = None
    for u in updates:
        if prev is not None and u.state != prev:
            j = int(round(u.t * rate_hz))
            if 0 <= j < len(sent):
                t_sent = sent[j]
                landed = next((t for t, s in writes if t >= t_sent and s == u.state), None)
                if landed is not None:
                    out.append(landed - t_sent)
        prev = u.state
    return out
