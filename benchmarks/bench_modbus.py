"""Modbus: slip decision -> acknowledged PLC write, sustained write rate, RTU poll rate.

    .venv/bin/python benchmarks/bench_modbus.py              # everything (about 1 minute)
    .venv/bin/python benchmarks/bench_modbus.py --writes 2000 --skip-rtu

1. Latency (TCP on loopback): from the arrival of the frame that completes a
   detector hop (the frame that decides a slip, or any other state) to the PLC's
   acknowledged register write: the frame goes through the pipeline, the register
   image, the writer thread and a Modbus write of the 20 status registers to the PLC
   stand-in (``eskin-bus plc-sim`` in its own process).  Every decision is written
   as urgent and awaited; p50/p99 over ``--writes`` writes, and separately over the
   decisions that were slips.  Reference: a plain pymodbus write loop of the same 20
   registers to the same server (no pipeline, no thread).
2. Sustained write rate: a new urgent image as soon as the previous write is
   acknowledged, through the writer thread; reference: the plain pymodbus loop.
3. RTU poll rate at 115200 and 19200 baud on a pseudo-terminal pair with a relay that
   paces bytes as the wire would (11 bits per character; the 3.5-character silences
   are not added: the software's own turnaround stands in for them); reference: the
   theoretical transaction time (request + response + silences).  Also the bare pty
   (no wire time): the bound the software alone sets.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from machine import describe  # noqa: E402  (benchmarks/machine.py)

from eskin_industrial import load_profile  # noqa: E402
from eskin_industrial.bus.modbus.rtu import RtuSource  # noqa: E402
from eskin_industrial.calibration import Calibrator  # noqa: E402
from eskin_industrial.detect.state import GraspState  # noqa: E402
from eskin_industrial.frames import RawScan  # noqa: E402
from eskin_industrial.modbus.pymodbus_io import TcpMaster, quiet_pymodbus  # noqa: E402
from eskin_industrial.modbus.serial_line import rtu_transaction_s  # noqa: E402
from eskin_industrial.node import Health, NodeStatus  # noqa: E402
from eskin_industrial.outputs.plc.client import PlcWriter  # noqa: E402
from eskin_industrial.outputs.plc.image import STATUS_COUNT, PlcImage  # noqa: E402
from eskin_industrial.pipeline import Pipeline  # noqa: E402
from eskin_industrial.sim.modbus_node import NodeSimulator  # noqa: E402
from tests.helpers.modbus import free_port, slip_recording  # noqa: E402

PROFILE = ROOT / "profiles" / "paper-5x5.toml"


def machine() -> str:
    return f"{time.strftime('%Y-%m-%d', time.gmtime())} on {describe()}"


def pct(values, q) -> float:
    return float(np.percentile(np.asarray(values), q))


def start_plc_sim(port: int) -> subprocess.Popen:
    proc = subprocess.Popen([sys.executable, "-m", "eskin_industrial", "plc-sim", "-p", str(PROFILE), "--port",
                             str(port)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT)
    master = TcpMaster("127.0.0.1", port)
    deadline = time.monotonic() + 15
    while True:
        try:
            master.connect()
            master.close()
            return proc
        except Exception:  # noqa: BLE001 - not up yet
            if time.monotonic() > deadline:
                proc.kill()
                raise SystemExit("plc-sim did not start") from None
            time.sleep(0.1)


def bench_latency(prof, port: int, writes: int, scores: bool = True) -> dict:
    """``scores``: each urgent image comes with its SCORE_A..SCORE_B, which the writer
    sends right after the image is acknowledged (the bridge's way): the next decision's
    write can wait behind it, as decisions here come back to back."""
    t, f, _ = slip_recording(still_s=1.5, slip_s=0.3, after_s=1.5)
    raw = np.rint(Calibrator.from_section(prof.calibration, 25).to_raw(f))
    settings = prof.modbus.plc
    acked = threading.Event()
    ack_time = [0.0]

    def on_written(t_event, t_ack):
        ack_time[0] = t_ack
        acked.set()

    writer = PlcWriter(settings, "127.0.0.1", port, poll_commands=False, on_written=on_written).start()
    pipe = Pipeline(prof)
    status = NodeStatus(prof.stale_s, pipe.method.name, pipe.method.code)
    image = PlcImage(settings)
    lat, slip_lat = [], []
    k = 0
    lap = 0
    period = 1.0 / prof.sensor.rate_hz
    span = len(t) * period
    health = Health(frame_age_s=0.0)
    # connect first
    def rendered() -> list[int]:  # the snapshot, and the PLC's image of it (as the loop and the writer do)
        return image.render(status.snapshot(health, scans=k, t_event=0.0, wall_time_s=0.0, urgent=True))

    writer.offer(rendered(), urgent=True)
    acked.wait(5)
    while len(lat) < writes:
        i = k % len(t)
        if i == 0 and k:
            lap += 1
        k += 1
        t_frame = time.perf_counter()  # the frame arrives
        updates = pipe.push(RawScan(k, t[i] + lap * span, raw[i]))
        if not updates:
            continue
        was = status.update.state if status.update is not None else None
        for u in updates:
            status.observe(u)
        acked.clear()
        registers = rendered()
        writer.offer(registers, urgent=True, t_event=t_frame, tail=tuple(image.tail) if scores else ())
        if not acked.wait(2.0):
            raise SystemExit("no acknowledged write within 2 s")
        lat.append(ack_time[0] - t_frame)
        if status.update.state == GraspState.SLIP and was != GraspState.SLIP:
            slip_lat.append(ack_time[0] - t_frame)
    scores_written = writer.stats.score_writes
    writer.stop()
    # reference: the bare pymodbus write loop
    master = TcpMaster("127.0.0.1", port)
    master.connect()
    regs = [0] * STATUS_COUNT
    ref = []
    for _ in range(writes):
        t0 = time.perf_counter()
        master.write_registers(settings.base_address, regs)
        ref.append(time.perf_counter() - t0)
    master.close()
    return {"lat": lat, "slip": slip_lat, "ref": ref, "scores": scores_written}


def bench_rate(prof, port: int, seconds: float) -> dict:
    settings = prof.modbus.plc
    acked = threading.Event()
    writer = PlcWriter(settings, "127.0.0.1", port, poll_commands=False,
                       on_written=lambda *_: acked.set()).start()
    regs = [0] * STATUS_COUNT
    writer.offer(regs, urgent=True)
    acked.wait(5)
    w0 = writer.stats.writes
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        regs[8] = (regs[8] + 1) & 0xFFFF  # a new image as soon as the previous one is acknowledged
        acked.clear()
        writer.offer(regs, urgent=True)
        acked.wait(1.0)
    rate = (writer.stats.writes - w0) / (time.perf_counter() - t0)
    writer.stop()
    master = TcpMaster("127.0.0.1", port)
    master.connect()
    n = 0
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        master.write_registers(settings.base_address, regs)
        n += 1
    ref = n / (time.perf_counter() - t0)
    master.close()
    return {"rate": rate, "ref": ref}


class WireRelay:
    """Forward bytes between two ptys, each direction paced at the baud rate: a byte
    leaves no earlier than 11/baud s after the previous one on that direction."""

    def __init__(self, left: str, right: str, baud: int) -> None:
        import serial

        self.a = serial.Serial(left, baud, timeout=0.01)
        self.b = serial.Serial(right, baud, timeout=0.01)
        self.char_s = 11.0 / baud
        self.stop = threading.Event()
        self.threads = [threading.Thread(target=self._pump, args=(self.a, self.b), daemon=True),
                        threading.Thread(target=self._pump, args=(self.b, self.a), daemon=True)]
        for th in self.threads:
            th.start()

    def _pump(self, src, dst) -> None:
        free_at = 0.0
        while not self.stop.is_set():
            data = src.read(1)  # blocks for the first byte only, then takes what is there
            if not data:
                continue
            data += src.read(src.in_waiting)
            now = time.perf_counter()
            free_at = max(free_at, now) + len(data) * self.char_s
            while time.perf_counter() < free_at:  # a sleep is too coarse for 95 us characters
                pass
            dst.write(data)

    def close(self) -> None:
        self.stop.set()
        for th in self.threads:
            th.join(timeout=1)
        self.a.close()
        self.b.close()


def pty_pair(d: Path, name: str):
    a, b = d / f"{name}A", d / f"{name}B"
    proc = subprocess.Popen(["socat", f"pty,raw,echo=0,link={a}", f"pty,raw,echo=0,link={b}"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 5
    while not (a.exists() and b.exists()):
        if time.monotonic() > deadline:
            raise SystemExit("socat did not create the pty pair")
        time.sleep(0.01)
    return proc, str(a), str(b)


def bench_rtu_unpaced(prof, seconds: float) -> float:
    """Polls per second on a bare pty pair (no baud rate): the software's own bound."""
    t, f, _ = slip_recording(still_s=1.0, slip_s=0.0, after_s=0.0)
    with tempfile.TemporaryDirectory() as tmp:
        p, a, b = pty_pair(Path(tmp), "bare")
        try:
            with NodeSimulator(prof, a, f, 100.0):
                poller = RtuSource(prof, b).open()
                try:
                    poller.poll_once()
                    c0, t0 = poller.stats.scans, time.perf_counter()
                    while time.perf_counter() - t0 < seconds:
                        poller.poll_once()
                    return (poller.stats.scans - c0) / (time.perf_counter() - t0)
                finally:
                    poller.close()
        finally:
            p.terminate()
            p.wait(timeout=5)


def bench_rtu(prof, baud: int, seconds: float) -> dict:
    t, f, _ = slip_recording(still_s=1.0, slip_s=0.0, after_s=0.0)
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        p1, node_end, relay_left = pty_pair(d, "node")
        p2, relay_right, poll_end = pty_pair(d, "bridge")
        try:
            with NodeSimulator(prof, node_end, f, 100.0, baudrate=baud):
                relay = WireRelay(relay_left, relay_right, baud)
                poller = RtuSource(prof, poll_end, baudrate=baud).open()
                try:
                    for _ in range(5):
                        poller.poll_once()
                    c0 = poller.stats.scans
                    t0 = time.perf_counter()
                    while time.perf_counter() - t0 < seconds:
                        poller.poll_once()
                    el = time.perf_counter() - t0
                    rate = (poller.stats.scans - c0) / el
                    errors = poller.stats.bus_errors
                finally:
                    poller.close()
                    relay.close()
        finally:
            for p in (p1, p2):
                p.terminate()
                p.wait(timeout=5)
    theory = rtu_transaction_s(prof.taxels, baud)
    return {"rate": rate, "theory_s": theory, "errors": errors}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--writes", type=int, default=10_000)
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--skip-rtu", action="store_true")
    args = ap.parse_args()
    quiet_pymodbus()  # "connection refused" while plc-sim starts is expected
    prof = load_profile(PROFILE)
    print(f"# python benchmarks/bench_modbus.py --writes {args.writes} --seconds {args.seconds:g}")
    print(f"# {machine()}")
    print("| figure | ours | reference | ratio |")
    print("|---|---|---|---|")
    port = free_port()
    sim = start_plc_sim(port)
    try:
        for scores in (True, False):
            r = bench_latency(prof, port, args.writes, scores)
            lat, ref = np.array(r["lat"]) * 1e3, np.array(r["ref"]) * 1e3
            how = (f"each followed by its scores' write ({r['scores']} written)" if scores
                   else "no scores' write (the image alone)")
            print(f"| decision frame -> acknowledged write, {len(lat)} writes, TCP loopback, {how} | "
                  f"p50 {pct(lat, 50):.2f} ms, p99 {pct(lat, 99):.2f} ms, max {lat.max():.2f} ms | "
                  f"plain pymodbus write: p50 {pct(ref, 50):.2f} ms, p99 {pct(ref, 99):.2f} ms | "
                  f"p99 {pct(lat, 99) / pct(ref, 99):.1f}x the bare write; target p99 <= 5 ms: "
                  f"{'met' if pct(lat, 99) <= 5 else 'NOT met'} |")
            if r["slip"]:
                s = np.array(r["slip"]) * 1e3
                print(f"| of which slip decisions ({len(s)}) | p50 {pct(s, 50):.2f} ms, p99 {pct(s, 99):.2f} ms | | |")
        w = bench_rate(prof, port, args.seconds)
        print(f"| sustained register writes (20 registers, function 16) | {w['rate']:,.0f} writes/s | "
              f"plain pymodbus loop {w['ref']:,.0f} writes/s | {w['rate'] / w['ref']:.2f}x |")
    finally:
        sim.terminate()
        sim.wait(timeout=10)
    if not args.skip_rtu:
        if shutil.which("socat") is None:
            raise SystemExit("socat is needed for the RTU figures (scripts/debian-packages.txt)")
        bare = bench_rtu_unpaced(prof, args.seconds)
        print(f"| RTU poll, 25 registers, bare pty (no wire time) | {bare:.0f} polls/s ({1e3 / bare:.2f} ms each) | "
              f"| software turnaround bound |")
        for baud in (115200, 19200):
            r = bench_rtu(prof, baud, args.seconds)
            limit = 1.0 / r["theory_s"]
            print(f"| RTU poll, 25 registers, {baud} baud (paced pty) | {r['rate']:.1f} polls/s "
                  f"({1e3 / r['rate']:.1f} ms each), {r['errors']} errors | theoretical {limit:.1f} polls/s "
                  f"({r['theory_s'] * 1e3:.1f} ms) | {r['rate'] / limit:.2f} of the limit |")


if __name__ == "__main__":
    main()
