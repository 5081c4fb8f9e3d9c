"""Shared pieces of the bridge tests (tests/bridge/): configurations built in
code on python-can virtual buses, a bridge run in-process with its supervisor, a log
captured as parsed JSON events, a PLC stand-in that timestamps every write, and
senders that timestamp every frame."""

from __future__ import annotations

import contextlib
import json
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace

import can
import numpy as np
from pymodbus.client import ModbusTcpClient

from eskin_industrial.bridge.config import BridgeConfig, LogSettings, NodeConfig, resolve
from eskin_industrial.bridge.logs import EventLog
from eskin_industrial.bridge.runtime import Bridge
from eskin_industrial.bus.can.layout import CanLayout
from eskin_industrial.bus.can.reader import open_bus
from eskin_industrial.calibration import Calibrator
from eskin_industrial.modbus.pymodbus_io import RegisterServer
from eskin_industrial.outputs.plc.image import REG, STATUS_COUNT, Status
from eskin_industrial.outputs.plc.image import decode_registers as decode
from eskin_industrial.outputs.plc.options import PlcOptions
from eskin_industrial.profile import Profile
from eskin_industrial.sim.can_node import CanNode, Faults
from eskin_industrial.sim.plc import PlcMemory
from tests.helpers.modbus import free_port, slip_recording
from tests.helpers.paths import PROFILES
from tests.helpers.scenes import grasp

PAPER = str(PROFILES / "paper-5x5.toml")
#: Bits that claim a verdict: none may be set without fresh, valid data.
CLAIMS = Status.STABLE | Status.SLIP | Status.VARIABLE_FORCE | Status.CONTACT | Status.DATA_VALID


def channel() -> str:
    """A virtual bus of this test alone (virtual channels are process-wide)."""
    return f"bridge-{uuid.uuid4().hex[:10]}"


def wait_for(cond: Callable[[], object], timeout_s: float = 5.0, what: str = "condition") -> None:
    deadline = time.monotonic() + timeout_s
    while not cond():
        assert time.monotonic() < deadline, f"{what}: not met within {timeout_s} s"
        time.sleep(0.005)


def can_node(name: str, ch: str, *, base_id: int | None = None, base_address: int = 0, **kw) -> NodeConfig:
    return NodeConfig.of(name, PAPER, "can", interface="virtual", channel=ch, base_id=base_id,
                         outputs={"plc": {"base_address": base_address}}, **kw)


def server_config(*nodes: NodeConfig, port: int | None = None, linger_s: float = 0.0,
                  queue_frames: int = 200_000) -> BridgeConfig:
    return BridgeConfig(node=nodes, outputs={"plc": PlcOptions(mode="server", host="127.0.0.1", port=port or free_port(),
                                                               offline_linger_s=linger_s)},
                        log=LogSettings(format="json", status_every_s=0), queue_frames=queue_frames)


def client_config(*nodes: NodeConfig, port: int, queue_frames: int = 200_000) -> BridgeConfig:
    return BridgeConfig(node=nodes, outputs={"plc": PlcOptions(mode="client", host="127.0.0.1", port=port)},
                        log=LogSettings(format="json", status_every_s=0), queue_frames=queue_frames)


class LogCapture:
    """A text stream for :class:`EventLog` (JSON format): every line kept, parsed on demand."""

    def __init__(self) -> None:
        self._chunks: list[str] = []
        self._lock = threading.Lock()

    def write(self, text: str) -> int:
        with self._lock:
            self._chunks.append(text)
        return len(text)

    def flush(self) -> None:
        pass

    def events(self, name: str | None = None) -> list[dict]:
        with self._lock:
            text = "".join(self._chunks)
        out = [json.loads(line) for line in text.splitlines() if line.strip()]
        return [e for e in out if name is None or e["event"] == name]


@dataclass
class Running:
    bridge: Bridge
    log: LogCapture
    supervisor: threading.Thread

    def counters(self, node: str) -> dict[str, int]:
        return self.bridge.counters()[node]

    def block(self, index: int) -> dict[str, int]:
        """Server mode: the registers the node's block serves now, decoded."""
        regs = list(self.bridge.server.handlers[index].registers) + [0, 0]  # type: ignore[union-attr]
        return decode(regs, "big")


@contextlib.contextmanager
def running_bridge(config: BridgeConfig, before_start: Callable[[Bridge], None] | None = None
                   ) -> Iterator[Running]:
    """The bridge opened and started in this process, supervised as the command does
    (``Bridge.wait`` logs stale, bus fault and PLC changes); stopped on the way out.
    ``before_start`` runs between open (buses open) and start (threads run)."""
    nodes = resolve(config)
    capture = LogCapture()
    log = EventLog(capture, "json", "debug")
    bridge = Bridge(config, nodes, log)
    try:
        bridge.open()
    except BaseException:
        log.close()
        raise
    sup = threading.Thread(target=bridge.wait, kwargs={"tick_s": 0.02}, name="supervisor", daemon=True)
    try:
        if before_start is not None:
            before_start(bridge)
        bridge.start()
        sup.start()
        yield Running(bridge, capture, sup)
        assert not bridge.failure, bridge.failure
    finally:
        bridge.stop()
        sup.join(timeout=5)
        log.close()


def to_raw(profile: Profile, forces: np.ndarray) -> np.ndarray:
    return np.rint(Calibrator.from_section(profile.calibration, profile.taxels).to_raw(forces))


def hold_raw(profile: Profile, k: int, seed: int = 0) -> np.ndarray:
    """A still grasp from the first scan on."""
    return to_raw(profile, grasp(k, n=profile.taxels, seed=seed))


def slip_raw(profile: Profile, rate_hz: float = 100.0) -> tuple[np.ndarray, float]:
    """Still, a stick-slip across the grid, still again; and the slip's onset (s)."""
    _, f, onset = slip_recording(rate_hz, still_s=1.5, slip_s=0.3, after_s=1.0)
    return to_raw(profile, f), onset


class TimedTx:
    """A node's transmit side that notes when each frame left (perf_counter)."""

    def __init__(self, bus: can.BusABC) -> None:
        self.bus = bus
        self.sent: list[float] = []

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self.bus.send(msg, timeout)
        self.sent.append(time.perf_counter())


@dataclass
class NodeThread:
    """A :class:`CanNode` simulator paced in its own thread, on its own bus handle."""

    node: CanNode
    tx: TimedTx
    bus: can.BusABC
    thread: threading.Thread = field(init=False)

    def __post_init__(self) -> None:
        self.thread = threading.Thread(target=self.node.run, name="can-node", daemon=True)

    def start(self) -> NodeThread:
        self.thread.start()
        return self

    def join(self, timeout_s: float) -> None:
        self.thread.join(timeout_s)
        assert not self.thread.is_alive(), "the node simulator did not finish"

    def close(self) -> None:
        self.bus.shutdown()


@contextlib.contextmanager
def node_thread(profile: Profile, ch: str, raw: np.ndarray, rate_hz: float = 100.0, *,
                base_id: int | None = None, node_id: int | None = None, faults: Faults = Faults(),
                **kw) -> Iterator[NodeThread]:
    layout = CanLayout.from_profile(profile)
    layout = replace(layout, base_id=layout.base_id if base_id is None else base_id,
                     node_id=layout.node_id if node_id is None else node_id)
    bus = open_bus("virtual", ch)
    tx = TimedTx(bus)
    nt = NodeThread(CanNode(layout, tx, raw, rate_hz, profile.can.heartbeat_s, faults, **kw), tx, bus)  # type: ignore[arg-type]
    try:
        yield nt
    finally:
        if nt.thread.is_alive():
            nt.thread.join(timeout=30)
        nt.close()


class TimedPlc:
    """A PLC stand-in for client mode: a Modbus TCP server whose memory notes every
    write with its time and the STATUS..FLAGS registers it left."""

    def __init__(self, port: int, base: int = 0) -> None:
        self.port = port
        self.writes: list[tuple[float, dict[str, int]]] = []
        self._lock = threading.Lock()
        self.memory = PlcMemory(base, on_write=self._on_write)
        self.memory.regs[REG["ENABLE"].offset] = 1  # the PLC program enables detection
        self.server = RegisterServer(self.memory, tcp=("127.0.0.1", port))

    def _on_write(self, t: float) -> None:
        regs = list(self.memory.regs[:STATUS_COUNT]) + [0, 0]
        with self._lock:
            self.writes.append((t, decode(regs, "big")))

    def start(self) -> TimedPlc:
        self.server.start()
        return self

    def stop(self) -> None:
        self.server.stop()

    def images(self) -> list[tuple[float, dict[str, int]]]:
        with self._lock:
            return list(self.writes)

    def last(self) -> dict[str, int] | None:
        with self._lock:
            return self.writes[-1][1] if self.writes else None


class BlockPoller:
    """A PLC polling the served block with pymodbus: (time, STATUS, F_SUM in N, FLAGS) per read."""

    def __init__(self, port: int, every_s: float = 0.004) -> None:
        self.client = ModbusTcpClient("127.0.0.1", port=port, timeout=2)
        self.every_s = every_s
        self.reads: list[tuple[float, int, float, int]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="plc-poller", daemon=True)

    def _run(self) -> None:
        n = REG["FLAGS"].offset + 1
        while not self._stop.wait(self.every_s):
            reply = self.client.read_holding_registers(0, count=n)
            assert not reply.isError(), reply
            v = decode(list(reply.registers) + [0, 0], "big")
            self.reads.append((time.perf_counter(), v["STATUS"], v["F_SUM"] / 1000.0, v["FLAGS"]))

    def __enter__(self) -> BlockPoller:
        assert self.client.connect()
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(5)
        self.client.close()
