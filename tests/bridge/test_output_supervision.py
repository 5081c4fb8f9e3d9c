"""No output's failure takes the PLC's block with it: each kind of output, faulted
three ways through its real seams while the bridge serves the PLC block and a Modbus
client polls it every 10 ms on loopback.

The faults, one after the other on one bridge (the case-2 scene, its slide brought
forward from 9.4 s to 5 s to keep the run short: pressed at 1 s, a slip at 5 s): (a) an exception from the output's ``publish``, (b) the death of a
thread of its own (paho's network thread, the PLC writer's, the recorder's handover:
made to die by a callback that raises; the web console's server thread, interrupted out of
its event loop; the OPC UA server's process, killed), (c) a
call that hangs.  Each is one ``output_failed`` line naming the output; the output is
back (``output_restarted``, a fresh instance) within its back-off; every read of the
served block is answered within 20 ms, DATA_VALID stays set and the slip is served.

Within 20 ms on a quiet host.  The suite shares two cores with other work, and a
process the scheduler holds back answers late whatever it runs: a control bridge
serving the PLC block alone (no output attached, a process of its own) is polled the
same way at the same time.  No read of the faulted bridge may take longer than
:data:`HOST_FACTOR` times the control's slowest plus :data:`MARGIN_S` (nor than 20 ms
when that comes to less), and no more of its reads may take over 20 ms than
HOST_FACTOR times the control's share of them, and :data:`LATE_MORE` reads.  (Two
processes the host holds back at random see slowest reads of their own: 93 ms was
seen beside the control's 79 ms, at a load average of 13 on the two cores.)  Before the OPC UA server had a process of its own,
its restarts stalled reads for 0.3 to 2.4 s (the garbage collector's full passes over
its address space, in the bridge's process).
The PLC itself in client mode is faulted the same way, writing into a Modbus server
the test starts: once as an essential output (on the loop's thread: (a) and (b)),
once handed over (the three)."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from eskin_industrial.bridge.config import BridgeConfig, LogSettings, NodeConfig, SupervisionSettings
from eskin_industrial.bridge.supervise import GuardedSink, HandedSink, SupervisedSink
from eskin_industrial.outputs.opcua.options import OpcuaOptions
from eskin_industrial.outputs.plc.image import STATUS_COUNT, Status
from eskin_industrial.outputs.plc.image import decode_registers as decode
from eskin_industrial.outputs.plc.options import PlcOptions
from eskin_industrial.outputs.recorder.kind import RecorderOptions
from eskin_industrial.outputs.sparkplug.options import SparkplugOptions
from eskin_industrial.outputs.web.options import WebOptions
from tests.helpers import sparkplug as spb
from tests.helpers.bridge import PAPER, Running, TimedPlc, running_bridge, wait_for
from tests.helpers.modbus import free_port, need
from tests.helpers.paths import ROOT

BACKOFF_S = 0.2
BACKOFF_MAX_S = 0.4
HANG_S = 0.5
#: A restart takes its back-off, the old instance's close and the new one's open (an
#: OPC UA server's process takes seconds to start, up to 26 s seen on two cores
#: shared with a dozen others): a bound on the wait, not the check (``down_s`` is).
BACK_WITHIN_S = 60.0
SLIP_AT_S = 5.0  #: the scene's slide (case 2's at 9.4 s)
SCENE_S = 300.0
CASE2 = ROOT / "eskin_industrial" / "scenes" / "builtin" / "case2.toml"


def _scene(tmp_path: Path) -> str:
    """Case 2 with its slide at :data:`SLIP_AT_S`, lasting :data:`SCENE_S` (a scene
    starts again at its end, and the detector's warm-up after its press again is no
    valid data: no fault's run, however slow its restarts on a loaded host, reaches it)."""
    text = CASE2.read_text().replace("t_s = 9.4", f"t_s = {SLIP_AT_S}").replace("duration_s = 14.0",
                                                                                   f"duration_s = {SCENE_S}")
    assert f"t_s = {SLIP_AT_S}" in text and f"duration_s = {SCENE_S}" in text
    path = tmp_path / "case2-early.toml"
    path.write_text(text)
    return str(path)
READ_WITHIN_S = 0.020
#: How much slower than the control bridge's slowest read (the host's own delay, see
#: the module's docstring) a read of the faulted bridge may be.
HOST_FACTOR = 2.0
MARGIN_S = 0.010
LATE_MORE = 5


class Died(BaseException):
    """What kills a handover's thread (its calls' exceptions are caught as failures)."""


class Interrupted(KeyboardInterrupt):
    """What kills a thread out of its asyncio loop (which keeps running past any other
    exception a callback raises)."""


#: The Modbus client, a process of its own (no thread of the bridge's process is
#: timed): it reads STATUS..METHOD_ID every 10 ms until its stdin closes, then prints
#: one line per read: perf_counter (CLOCK_MONOTONIC, shared with this process), the
#: time the answer took, and the registers; or the error that ended it.
_POLLER = r"""
import select, socket, struct, sys, time
port, count = int(sys.argv[1]), int(sys.argv[2])
deadline = time.monotonic() + 10
while True:
    try:
        s = socket.create_connection(("127.0.0.1", port), timeout=5.0)
        break
    except OSError:
        if time.monotonic() > deadline:
            raise
        time.sleep(0.01)
s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
out, tid, next_at = [], 0, time.perf_counter()
def exact(n):
    b = b""
    while len(b) < n:
        chunk = s.recv(n - len(b))
        if not chunk:
            raise ConnectionError("closed")
        b += chunk
    return b
try:
    while not select.select([sys.stdin], [], [], 0)[0]:
        tid = (tid + 1) & 0xFFFF
        t0 = time.perf_counter()
        s.sendall(struct.pack(">HHHBBHH", tid, 0, 6, 1, 3, 0, count))
        _, _, length, _ = struct.unpack(">HHHB", exact(7))
        pdu = exact(length - 1)
        took = time.perf_counter() - t0
        assert pdu[0] == 3, pdu.hex()
        out.append(f"{t0!r} {took!r} " + " ".join(map(str, struct.unpack(f">{count}H", pdu[2:]))))
        next_at += 0.010
        time.sleep(max(0.0, next_at - time.perf_counter()))
except Exception as exc:
    out.append(f"error {type(exc).__name__}: {exc} at {time.perf_counter()!r} asked at {t0!r}")
print("\n".join(out))
"""


class Poller:
    """The served block read every 10 ms by a Modbus client process: each read's time
    and image."""

    def __init__(self, port: int) -> None:
        self.port = port
        self.reads: list[tuple[float, float, dict[str, int]]] = []  #: (when, took, image)
        self.errors: list[str] = []
        self._proc = subprocess.Popen([sys.executable, "-c", _POLLER, str(port), str(STATUS_COUNT)],
                                      stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)

    def stop(self) -> None:
        out, _ = self._proc.communicate("stop\n", timeout=10)
        for line in out.splitlines():
            if line.startswith("error"):
                self.errors.append(line)
                continue
            t, took, *regs = line.split()
            self.reads.append((float(t), float(took), decode([int(v) for v in regs] + [0, 0], "big")))


def _hang(release: threading.Event) -> Callable[..., None]:
    def hang(*_: Any) -> None:
        release.wait(30)

    return hang


def _raise(*_: Any) -> None:
    raise RuntimeError("injected in publish")


def _die(*_: Any) -> None:
    raise Died("a thread of its own dies")


def _kill_paho(port: int) -> Callable[[SupervisedSink], None]:
    """paho's thread killed by its message callback raising, at an NCMD sent by a
    ``mosquitto_pub -l`` started now (no process is started while the block is timed)."""
    pub = subprocess.Popen([need("mosquitto_pub"), "-h", "127.0.0.1", "-p", str(port), "-t", "spBv1.0/g/NCMD/e",
                            "-l"], stdin=subprocess.PIPE)
    _PUBLISHERS.append(pub)

    def kill(sink: SupervisedSink) -> None:
        def bug(*_: object) -> None:
            raise RuntimeError("a bug in a callback")

        sink.inner.node.client.on_message = bug  # type: ignore[attr-defined]
        assert pub.stdin is not None
        pub.stdin.write(b"x\n")
        pub.stdin.flush()

    return kill


#: The ``mosquitto_pub -l`` of the test under way (ended with it).
_PUBLISHERS: list[subprocess.Popen[bytes]] = []


def _faults(kind: str, release: threading.Event, broker: int | None) -> dict[str, Callable[[SupervisedSink], None]]:
    """fault -> how it is made, on the output's live instance (its sink of the node)."""

    def publish_raises(sink: SupervisedSink) -> None:
        sink.inner.publish = _raise  # type: ignore[method-assign]

    def publish_hangs(sink: SupervisedSink) -> None:
        sink.inner.publish = _hang(release)  # type: ignore[method-assign]

    thread_dies: Callable[[SupervisedSink], None]
    if kind == "sparkplug":
        assert broker is not None
        thread_dies = _kill_paho(broker)
    elif kind == "opcua":
        def thread_dies(sink: SupervisedSink) -> None:  # the server's process
            os.kill(sink.inner.server.pid, signal.SIGKILL)  # type: ignore[attr-defined]
    elif kind == "web":
        def thread_dies(sink: SupervisedSink) -> None:  # the server's thread, out of its event loop
            def die() -> None:
                raise Interrupted("the web server's thread dies")

            sink.inner.server._loop.call_soon_threadsafe(die)  # type: ignore[attr-defined]
    elif kind == "recorder":
        def thread_dies(sink: SupervisedSink) -> None:  # its handover's thread: it has none other
            sink.inner.on_update = _die  # type: ignore[method-assign]
    else:  # the PLC writer's thread
        def thread_dies(sink: SupervisedSink) -> None:
            sink.inner._cycle = _die  # type: ignore[attr-defined]
    return {"publish raises": publish_raises, "thread dies": thread_dies, "call hangs": publish_hangs}


def _config(scene: str, outputs: dict[str, Any], essential: tuple[str, ...] = ("plc",)) -> BridgeConfig:
    node = NodeConfig.of("grip", PAPER, "scene", scene=scene)
    return BridgeConfig((node,), outputs, LogSettings(format="json", status_every_s=0),
                        supervision=SupervisionSettings(essential=essential, backoff_s=BACKOFF_S,
                                                        backoff_max_s=BACKOFF_MAX_S, hang_s=HANG_S))


def _fault_in_turn(r: Running, kind: str, faults: dict[str, Callable[[SupervisedSink], None]],
                   healthy: Callable[[SupervisedSink], bool]) -> list[tuple[float, float]]:
    """Each fault in turn, once the output is healthy: one failure line, then back (a
    fresh instance) after its back-off.  Returns when each restart was under way
    (perf_counter: from the fault to the fresh instance up)."""
    restarting = []
    sink = next(s for s in r.bridge.runs[0].sinks if isinstance(s, SupervisedSink) and s.kind == kind)
    for i, (name, inject) in enumerate(faults.items()):
        wait_for(lambda: healthy(sink), timeout_s=10, what=f"{kind} healthy before {name!r}")
        time.sleep(BACKOFF_MAX_S + 0.1)  # up long enough: the back-off starts again from backoff_s
        before = sink.inner
        injected = time.perf_counter()
        inject(sink)
        wait_for(lambda n=i + 1: len(_lines(r, "output_restarted", kind)) == n, timeout_s=BACK_WITHIN_S + HANG_S,
                 what=f"{kind} back after {name!r}")
        seen = time.perf_counter()
        (back,) = _lines(r, "output_restarted", kind)[i:]
        restarting.append((injected, seen))
        # back after its back-off (jittered, doubling from backoff_s), the close and the open: no other wait
        assert BACKOFF_S * 0.75 - 0.0005 <= back["backoff_s"] <= BACKOFF_MAX_S, back  # (logged to the ms)
        assert back["down_s"] <= max(back["backoff_s"], back["close_s"]) + back["open_s"] + 0.3, back
        failed = _lines(r, "output_failed", kind)
        assert len(failed) == i + 1, f"{name}: {failed}"
        assert failed[-1]["level"] == "error" and failed[-1]["node"] in ("grip", "-"), failed[-1]
        assert sink.inner is not before, f"{name}: the same instance"
        if name == "call hangs":
            assert "hang_s" in failed[-1]["error"]
    wait_for(lambda: healthy(sink), timeout_s=10, what=f"{kind} healthy at the end")
    counters = r.counters("grip")
    assert counters[f"{kind}_output_failures"] == len(faults) and counters[f"{kind}_output_restarts"] == len(faults)
    assert counters[f"{kind}_output_up"] == 1
    assert counters[f"{kind}_output_abandoned"] == int("call hangs" in faults)
    return restarting


def _lines(r: Running, event: str, kind: str) -> list[dict]:
    return [e for e in r.log.events(event) if e.get("output") == kind]


def _no_other_failure(r: Running) -> None:
    for event in ("thread_failed", "loop_failed", "supervise_failed", "stop_failed", "loop_stalled"):
        assert not r.log.events(event), r.log.events(event)
    assert not r.bridge.failure


def _served_block_held(poller: Poller, control: Poller, since: float) -> None:
    """Every read answered; from ``since`` (the grasp held, the faults to come) on, each
    within 20 ms (or what the host did to the control at the same time: see the
    module's docstring) and with DATA_VALID set; the slip served."""
    assert not poller.errors, poller.errors
    assert not control.errors, control.errors
    assert len(poller.reads) > 500, len(poller.reads)
    reads = [(t, took, img) for t, took, img in poller.reads if t >= since]
    until = reads[-1][0]
    control_took = [took for t, took, _ in control.reads if since <= t <= until]
    assert len(control_took) > 0.8 * len(reads), (len(control_took), len(reads))
    within = max(READ_WITHIN_S, HOST_FACTOR * max(control_took) + MARGIN_S)
    slowest = max(took for _, took, _ in reads)
    late = sorted((took for _, took, _ in reads if took > within), reverse=True)
    assert not late, (f"{len(late)} of {len(reads)} reads took over {within * 1000:.1f} ms (the control's slowest: "
                      f"{max(control_took) * 1000:.1f} ms): {[round(x * 1000, 1) for x in late[:10]]}")
    over = sum(1 for _, took, _ in reads if took > READ_WITHIN_S)
    control_over = sum(1 for took in control_took if took > READ_WITHIN_S)
    allowed = HOST_FACTOR * control_over * len(reads) / len(control_took) + LATE_MORE
    assert over <= allowed, f"{over} of {len(reads)} reads over 20 ms, the control's {control_over} of {len(control_took)}"
    invalid = [(round(t - since, 3), img["STATUS"]) for t, _, img in reads if not img["STATUS"] & Status.DATA_VALID]
    assert not invalid, f"{len(invalid)} reads without DATA_VALID (s after the grasp held, STATUS): {invalid[:3]}..{invalid[-3:]}"
    assert any(img["STATUS"] & Status.SLIP and img["STATE"] == 3 for _, _, img in poller.reads), "the slip was not served"
    print(f"slowest read {slowest * 1000:.1f} ms, the control's {max(control_took) * 1000:.1f} ms; over 20 ms: "
          f"{over} of {len(reads)}, the control's {control_over} of {len(control_took)}")


#: The control bridge: the PLC block alone served on the port given, the scene given,
#: until its stdin closes (it says "up" once serving).
_CONTROL = r"""
import sys
from eskin_industrial.outputs.plc.options import PlcOptions
from tests.helpers.bridge import running_bridge
from tests.bridge.test_output_supervision import _config
port, scene = int(sys.argv[1]), sys.argv[2]
outputs = {"plc": PlcOptions(mode="server", host="127.0.0.1", port=port, offline_linger_s=0.0)}
with running_bridge(_config(scene, outputs)):
    print("up", flush=True)
    sys.stdin.read()
"""


class Control:
    """The control bridge's process and its poller."""

    def __init__(self, scene: str) -> None:
        port = free_port()
        root = str(ROOT)
        env = {**os.environ, "PYTHONPATH": os.pathsep.join([root, os.environ.get("PYTHONPATH", "")])}
        self._proc = subprocess.Popen([sys.executable, "-c", _CONTROL, str(port), scene], stdin=subprocess.PIPE,
                                      stdout=subprocess.PIPE, text=True, cwd=root, env=env)
        assert self._proc.stdout is not None and self._proc.stdout.readline().strip() == "up"
        self.poller = Poller(port)

    def stop(self) -> Poller:
        try:
            self.poller.stop()
        finally:
            self._proc.communicate("", timeout=20)
        return self.poller


@pytest.mark.parametrize("kind", ["recorder", "sparkplug", "opcua", "web"])
def test_a_failing_output_restarts_while_the_plc_block_is_served(tmp_path: Path, kind: str) -> None:
    release = threading.Event()
    plc_port = free_port()
    outputs: dict[str, Any] = {"plc": PlcOptions(mode="server", host="127.0.0.1", port=plc_port,
                                                 offline_linger_s=0.0)}
    healthy: Callable[[SupervisedSink], bool]
    with spb.broker(tmp_path) if kind == "sparkplug" else _nothing() as broker:
        record = tmp_path / "grip.csv"
        if kind == "recorder":
            outputs["recorder"] = RecorderOptions(str(record), flush_every_s=0.05)

            def healthy(sink: SupervisedSink) -> bool:
                return sink.output.up and sink.counters().get("recorded_updates", 0) > 0
        elif kind == "sparkplug":
            outputs["sparkplug"] = SparkplugOptions(f"mqtt://127.0.0.1:{broker}", "g", "e")

            def healthy(sink: SupervisedSink) -> bool:
                return sink.output.up and bool(sink.health().connected)
        elif kind == "web":
            web_port = free_port()
            outputs["web"] = WebOptions(bind=f"127.0.0.1:{web_port}")

            def healthy(sink: SupervisedSink) -> bool:
                return sink.output.up and _listens(web_port)
        else:
            opcua_port = free_port()
            outputs["opcua"] = OpcuaOptions(endpoint=f"opc.tcp://127.0.0.1:{opcua_port}", offline_linger_s=0.0)

            def healthy(sink: SupervisedSink) -> bool:
                return sink.output.up and _listens(opcua_port)
        faults = _faults(kind, release, broker)  # (any process it needs started before the block is timed)
        try:
            control = Control(_scene(tmp_path))
            try:
                with running_bridge(_config(_scene(tmp_path), outputs)) as r:
                    started = time.monotonic()
                    assert isinstance(r.bridge.runs[0].sinks[0], GuardedSink)  # the PLC: on the loop's thread
                    poller = Poller(plc_port)
                    try:
                        wait_for(lambda: _held(r), timeout_s=10, what="the grasp served as stable and valid")
                        since = time.perf_counter()
                        restarting = _fault_in_turn(r, kind, faults, healthy)
                        print("faults (from, back):", [(round(a - since, 3), round(b - since, 3)) for a, b in restarting])
                        # the slide, served through it all
                        time.sleep(max(0.0, SLIP_AT_S + 1.5 - (time.monotonic() - started)))
                    finally:
                        poller.stop()
                    _no_other_failure(r)
            finally:
                control.stop()
            _served_block_held(poller, control.poller, since)
        finally:
            release.set()
            for pub in _PUBLISHERS:
                pub.kill()
                pub.communicate(timeout=5)  # (and its stdin closed)
            _PUBLISHERS.clear()
    if kind == "recorder":  # the file was appended to by each fresh instance, never started anew
        lines = record.read_text().splitlines()
        assert lines[0].startswith("t,") and sum(1 for ln in lines if ln.startswith("t,")) == 1
        assert len(lines) > 100


@pytest.mark.parametrize("essential", [True, False], ids=["essential", "handed-over"])
def test_the_plc_writer_in_client_mode_restarts_after_its_faults(tmp_path: Path, essential: bool) -> None:
    release = threading.Event()
    port = free_port()
    plc = TimedPlc(port).start()
    try:
        outputs = {"plc": PlcOptions(mode="client", host="127.0.0.1", port=port, backoff_s=0.05, backoff_max_s=0.2)}
        with running_bridge(_config(_scene(tmp_path), outputs, ("plc",) if essential else ())) as r:
            started = time.monotonic()
            poller = Poller(port)  # the PLC's own memory, read as the PLC program would
            faults = _faults("plc", release, None)
            if essential:  # a hang on the loop's thread is the loop's: not faulted here
                del faults["call hangs"]
            sink = r.bridge.runs[0].sinks[0]
            assert isinstance(sink, GuardedSink if essential else HandedSink)

            def healthy(s: SupervisedSink) -> bool:
                return s.output.up and s.counters().get("plc_writes", 0) > 0

            try:
                _fault_in_turn(r, "plc", faults, healthy)
                after = time.perf_counter()
                wait_for(lambda: any(t > after for t, _ in plc.images()), timeout_s=5, what="written again")
                if not essential:  # the slide written through it all
                    wait_for(lambda: any(img["STATE"] == 3 for _, img in plc.images()),
                             timeout_s=max(0.0, SLIP_AT_S + 3.0 - (time.monotonic() - started)),
                             what="slip written")
            finally:
                poller.stop()
            _no_other_failure(r)
            written = [img for t, img in plc.images() if t > after]
            assert written and all(img["STATUS"] & Status.DATA_VALID for img in written)
    finally:
        release.set()
        plc.stop()


def _held(r: Running) -> bool:
    """The block serves the pressed grasp: stable, DATA_VALID."""
    img = r.block(0)
    return img["STATE"] == 1 and bool(img["STATUS"] & Status.DATA_VALID)


def _listens(port: int) -> bool:
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=0.2):
            return True
    except OSError:
        return False


class _nothing:  # a context manager for "no broker", read like spb.broker
    def __enter__(self) -> None:
        return None

    def __exit__(self, *exc: object) -> None:
        return None
