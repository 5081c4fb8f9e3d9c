"""A sensor node simulator that serves a scene as a Modbus RTU slave.

The node keeps its newest scan in ``taxels x words`` registers from the profile's
``[modbus.node] start_address`` (input registers for function 4, holding registers
for function 3), row-major, each the calibration's raw value as ``value_type``;
with ``counter_register`` the node's scan counter comes first.
:func:`encode_scan` / :func:`decode_scans` are the pure codec; the RTU source
(``bus/modbus/rtu.py``) and the simulator here share them.

It serves through the package's own RTU server (:mod:`eskin_industrial.modbus.rtu_server`):
the RTU source polls with pymodbus' master, so that a Modbus stack we did not write
stands on the other side of the server, and ours on the other side of the master.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field

import numpy as np

from ..bus.modbus.codec import encode_scan, register_count
from ..calibration import Calibrator
from ..modbus.exception_codes import ILLEGAL_ADDRESS, ILLEGAL_FUNCTION
from ..modbus.pdu import Identity, Table
from ..modbus.rtu_server import RtuServer
from ..modbus.serial_line import SerialSettings
from ..profile import ModbusNodeSection, Profile

#: What the simulated node answers to report server id and device identification.
IDENTITY = Identity(vendor_name="eskin-industrial", product_code="modbus-node", revision="simulator")


@dataclass
class NodeRegisters:
    """The node's register file as a server handler; ``scan`` is swapped whole."""

    node: ModbusNodeSection
    count: int
    scan: list[int] = field(default_factory=list)
    reads: int = 0

    def read(self, table: Table, address: int, count: int) -> list[int] | int:
        wanted = "input" if self.node.function == 4 else "holding"
        if table != wanted:
            return ILLEGAL_FUNCTION if table in ("coils", "discrete") else ILLEGAL_ADDRESS
        start = self.node.start_address
        if address < start or address + count > start + self.count:
            return ILLEGAL_ADDRESS
        scan = self.scan or [0] * self.count
        self.reads += 1
        return scan[address - start: address - start + count]

    def write(self, table: Table, address: int, values: list[int] | list[bool]) -> int | None:
        return ILLEGAL_ADDRESS  # the node's registers are read-only


class NodeSimulator:
    """Serves a force sequence as the node would: a new scan every ``1/rate_hz``.

    ``forces`` is ``(K, taxels)`` in newtons; the calibration's inverse turns them
    into the node's raw unit.  The scene loops unless ``loop=False`` (then the
    last scan stays)."""

    def __init__(self, profile: Profile, port: str, forces: np.ndarray, rate_hz: float, *,
                 baudrate: int | None = None, loop: bool = True) -> None:
        node = profile.modbus.node
        cal = Calibrator.from_section(profile.calibration, profile.taxels)
        forces = np.asarray(forces, dtype=np.float64)
        if forces.ndim != 2 or forces.shape[1] != profile.taxels:
            raise ValueError(f"forces: expected (K, {profile.taxels}), got {forces.shape}")
        self.scans = [encode_scan(node, row) for row in cal.to_raw(forces)]
        self.rate_hz = rate_hz
        self.loop = loop
        self.counter = node.counter_register
        self.registers = NodeRegisters(node, register_count(node, profile.taxels), self._content(0, 0))
        serial = SerialSettings(port, baudrate or node.baudrate, node.parity, node.stopbits)
        self.server = RtuServer(self.registers, serial, node.unit_id, IDENTITY)
        self.index = 0
        self.started: float | None = None  #: perf_counter when scan 0 went out
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> NodeSimulator:
        self.server.start()
        self._thread = threading.Thread(target=self._step, name="node-scene", daemon=True)
        self._thread.start()
        return self

    def _step(self) -> None:
        period = 1.0 / self.rate_hz
        t0 = time.monotonic()
        self.started = time.perf_counter()
        k = 0
        while not self._stop.is_set():
            k += 1
            delay = t0 + k * period - time.monotonic()
            if delay > 0 and self._stop.wait(delay):
                return
            i = k % len(self.scans) if self.loop else min(k, len(self.scans) - 1)
            if not self.loop and k >= len(self.scans):
                continue  # the scene is over: the last scan stays, its counter too
            self.index = i
            self.registers.scan = self._content(k, i)

    def _content(self, k: int, i: int) -> list[int]:
        return [k & 0xFFFF, *self.scans[i]] if self.counter else self.scans[i]

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2)
        self.server.stop()

    def __enter__(self) -> NodeSimulator:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


def serve_scene_rtu(profile: Profile, port: str, t: np.ndarray, forces: np.ndarray, rate_hz: float | None = None,
                    *, baudrate: int | None = None, loop: bool = True, duration_s: float | None = None,
                    stop: threading.Event | None = None) -> NodeSimulator:
    """Serve a scene as a Modbus RTU slave on ``port`` until ``stop`` is set or
    ``duration_s`` has passed (forever when neither is given), or Ctrl-C (SIGTERM, as
    the command line turns it into one) stops it; returns the stopped simulator (its
    ``registers.reads`` tells how often it was polled)."""
    if rate_hz is None:
        steps = np.diff(np.asarray(t, dtype=np.float64))
        steps = steps[steps > 0]
        rate_hz = float(1.0 / np.median(steps)) if steps.size else profile.sensor.rate_hz
    sim = NodeSimulator(profile, port, forces, rate_hz, baudrate=baudrate, loop=loop)
    stop = stop or threading.Event()
    with sim:
        try:
            stop.wait(duration_s)
        except KeyboardInterrupt:  # a stop as asked: what was served is still told
            stop.set()
    return sim
