"""The bridge end to end: from the arrival of the scan that decides a state to the
PLC's acknowledged write, at 100 Hz and 1 kHz, over CAN (python-can's virtual bus,
or SocketCAN vcan) and Modbus RTU; and the CPU the bridge takes.

    .venv/bin/python benchmarks/bench_bridge.py                 # every path, 60 s each (~5 min)
    .venv/bin/python benchmarks/bench_bridge.py --paths can-1k --duration 30
    .venv/bin/python benchmarks/bench_bridge.py --paths can-100 --duration 30 --breakdown   # where the time goes
    .venv/bin/python benchmarks/bench_bridge.py --paths can-100,can-1k --duration 20 --viewers 5 --repeats 3   # the web console's cost
    python tests/vcan/vm.py -- .venv/bin/python benchmarks/bench_bridge.py --paths vcan-100,vcan-1k

What runs: the product's own :class:`~eskin_industrial.bridge.runtime.Bridge` (reader
thread, CAN loop, detector, register image, client-mode writer thread) writing
Modbus TCP on loopback into a PLC stand-in in its *own process*, which notes the
wall-clock time and STATE of every write.  The scene is a "slip train": a
still grasp with a short slide every 1.2 s, so a minute holds about 50 slip decisions.

- arrival: the time the frame completing the deciding scan reached the bus (CAN:
  python-can's message timestamp: the virtual bus stamps at send, SocketCAN at
  kernel receipt); for RTU, the moment the poll's answer was complete.
- end: the PLC stand-in's receipt of the first write after the arrival that shows the
  new STATE (the acknowledgement follows on loopback within microseconds).  A decision
  overtaken by the next one before its image went out (the writer sends the newest
  image: the PLC gets the present) is not timed, and counted as superseded.
- Every state change is a sample ("all"), slip entries are also reported alone.
- CPU: the bridge's own threads (from /proc/self/task), in % of one core; the node
  simulator sharing the process (the virtual bus exists in one process only) is
  excluded.
- Reference, in the same run: python-can's ``Notifier`` + a plain pymodbus client
  writing the same register at the same decision scans (no assembly, no detection,
  no image): the floor set by the two libraries.  Ratio = ours / reference.

1 kHz uses the profile's CAN FD layout (one frame per scan): classic CAN at 1 Mbit/s
carries about 8,000 frames/s, and a 5 x 5 scan at 16 bits takes 9 classic frames.
RTU runs at 100 Hz only: one poll of 25 registers takes 9.5 ms at 115200 baud.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
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
sys.path.insert(0, str(ROOT / "benchmarks"))

PROFILE = ROOT / "profiles" / "paper-5x5.toml"
PATHS = ("can-100", "can-1k", "rtu-100")


def slip_train_toml(duration_s: float, every_s: float = 1.2) -> str:
    """A still 8 N grasp with a 4 mm slide at 20 mm/s every ``every_s``, back and forth."""
    lines = ['[scene]', 'name = "slip-train"', 'description = "benchmark: a slide every 1.2 s"',
             'profile = "paper-5x5"', f'duration_s = {duration_s:.1f}', '',
             '[footprint]', 'size_mm = [20.0, 20.0]', 'centre_mm = [10.0, 10.0]', 'gradient_per_mm = [0.01, 0.0]',
             '', '[[events]]', 'kind = "press"', 't_s = 0.5', 'duration_s = 0.5', 'force_n = 8.0']
    t, sign = 2.5, 1.0
    while t < duration_s - 1.0:
        lines += ['', '[[events]]', 'kind = "slide"', f't_s = {t:.2f}', f'distance_mm = [{4.0 * sign:.1f}, 0.0]',
                  'speed_mm_s = 20.0']
        t += every_s
        sign = -sign
    return "\n".join(lines) + "\n"


# -- the PLC stand-in (its own process) ----------------------------------------------

def capture_main(port: int, out: str) -> None:
    """Serve the PLC's registers; note (time, STATE) of every write."""
    from eskin_industrial.modbus.pymodbus_io import RegisterServer, quiet_pymodbus
    from eskin_industrial.outputs.plc.image import IMAGE_COUNT, REG

    quiet_pymodbus()
    seen: list[tuple[float, int]] = []
    state_at = REG["STATE"].offset

    class Capture:
        def read(self, table, address, count):
            regs = [0] * IMAGE_COUNT
            regs[REG["ENABLE"].offset] = 1
            return regs[address: address + count]

        def write(self, table, address, values):
            t = time.time()
            if address <= state_at < address + len(values):
                seen.append((t, int(values[state_at - address])))
            return None

    server = RegisterServer(Capture(), tcp=("127.0.0.1", port)).start()
    done = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    print("ready", flush=True)
    done.wait()
    server.stop()
    Path(out).write_text(json.dumps(seen))


class PlcCapture:
    def __init__(self) -> None:
        from tests.helpers.modbus import free_port

        self.port = free_port()
        self.out = tempfile.mktemp(suffix=".json")
        self.proc = subprocess.Popen([sys.executable, __file__, "--capture", str(self.port), self.out],
                                     stdout=subprocess.PIPE, text=True)
        assert self.proc.stdout is not None and self.proc.stdout.readline().strip() == "ready"

    def finish(self) -> list[tuple[float, int]]:
        self.proc.send_signal(signal.SIGTERM)
        self.proc.wait(timeout=10)
        data = json.loads(Path(self.out).read_text())
        os.unlink(self.out)
        return [(float(t), int(s)) for t, s in data]


# -- per-thread CPU -------------------------------------------------------------------

def thread_cpu_s() -> dict[str, float]:
    """CPU seconds of each thread of this process, by thread name."""
    names = {t.native_id: t.name for t in threading.enumerate()}
    tick = os.sysconf("SC_CLK_TCK")
    out: dict[str, float] = {}
    for tid in os.listdir("/proc/self/task"):
        try:
            stat = Path(f"/proc/self/task/{tid}/stat").read_text()
        except OSError:
            continue
        fields = stat.rsplit(")", 1)[1].split()
        cpu = (int(fields[11]) + int(fields[12])) / tick  # utime + stime
        name = names.get(int(tid), f"tid-{tid}")
        out[name] = out.get(name, 0.0) + cpu
    return out


# -- matching decisions to PLC writes -------------------------------------------------

def latencies(decisions: list[tuple[int, int]], arrival: dict[int, float], writes: list[tuple[float, int]]):
    """For each decision (scan index, new state): the first write after the scan's
    arrival that shows that state, if it comes before the next decision's arrival;
    else the image was superseded by the next decision's before it went out (by
    design: the PLC gets the present), and the decision is skipped and counted."""
    out_all, out_slip, skipped = [], [], 0
    times = np.array([t for t, _ in writes])
    for i, (k, state) in enumerate(decisions):
        t0 = arrival.get(k)
        if t0 is None:
            skipped += 1
            continue
        t_next = arrival.get(decisions[i + 1][0], np.inf) if i + 1 < len(decisions) else np.inf
        j = int(np.searchsorted(times, t0))
        while j < len(writes) and writes[j][1] != state and writes[j][0] < t_next:
            j += 1
        if j >= len(writes) or writes[j][1] != state or writes[j][0] >= t_next:
            skipped += 1
            continue
        dt = writes[j][0] - t0
        out_all.append(dt)
        if state == 3:
            out_slip.append(dt)
    return out_all, out_slip, skipped


# -- our bridge -------------------------------------------------------------------------

def run_ours(path: str, duration_s: float, scene_file: Path, interface: str, channel: str,
             breakdown: bool = False, viewers: int | None = None):
    """``viewers``: None, no web console; else the console attached with that many
    viewers (:mod:`web_viewers`) watching the node."""
    from eskin_industrial.bridge.config import BridgeConfig, LogSettings, NodeConfig, resolve
    from eskin_industrial.bridge.logs import EventLog
    from eskin_industrial.bridge.runtime import Bridge
    from eskin_industrial.outputs.plc.options import PlcOptions

    rate = 1000.0 if path.endswith("1k") else 100.0
    fd = rate > 500
    plc = PlcCapture()
    rtu_proc = pty = None
    try:
        if path.startswith("rtu"):
            from tests.helpers.modbus import pty_pair

            pty = pty_pair(Path(tempfile.mkdtemp()))
            a, b = pty.__enter__()
            rtu_proc = subprocess.Popen([str(ROOT / ".venv/bin/eskin-bus"), "modbus-node", "-p", str(PROFILE),
                                         "--port", str(a), "--scene", str(scene_file), "--rate", str(rate)],
                                        stderr=subprocess.DEVNULL)
            time.sleep(1.0)
            node_cfg = NodeConfig.of("n1", str(PROFILE), "modbus-rtu", serial_port=str(b), rate_hz=rate)
        else:
            node_cfg = NodeConfig.of("n1", str(PROFILE), "can", interface=interface, channel=channel, fd=fd, rate_hz=rate)
        outputs: dict = {"plc": PlcOptions(mode="client", host="127.0.0.1", port=plc.port)}
        web_base = None
        if viewers is not None:
            from eskin_industrial.outputs.web.options import WebOptions
            from tests.helpers.modbus import free_port

            web_port = free_port()
            web_base = f"http://127.0.0.1:{web_port}"
            outputs["web"] = WebOptions(bind=f"127.0.0.1:{web_port}")
        cfg = BridgeConfig(node=(node_cfg,), outputs=outputs, log=LogSettings(status_every_s=0))
        nodes = resolve(cfg)
        decisions: list[tuple[int, int]] = []
        last = [-1]

        def on_update(_name, u):
            if u.state != last[0]:
                if last[0] != -1:  # the first state is no change (and the PLC link may still be opening)
                    decisions.append((int(round(u.t * rate)), int(u.state)))
                last[0] = u.state

        log = EventLog(open(os.devnull, "w"), "plain", "warning")
        br = Bridge(cfg, nodes, log, on_update=on_update).open()
        arrival: dict[int, float] = {}
        source = br.runs[0].loop.source
        poll = source.poll
        mono_to_wall = time.time() - time.monotonic()

        def timed_poll(timeout_s=None):
            scan = poll(timeout_s)
            if scan is not None:
                rx = scan.rx_time + (mono_to_wall if path.startswith("rtu") else 0.0)
                arrival[int(round(scan.t * rate))] = rx
            return scan

        hops: dict[int, dict[str, float]] = {}  # decision scan -> hop name -> wall time
        acks: list[tuple[float, int]] = []  # (wall time, STATE) of each write the bridge saw acknowledged
        if breakdown:
            hops, acks = time_hops(br, rate, timed_poll, lambda scan: arrival[int(round(scan.t * rate))])
        else:
            source.poll = timed_poll  # type: ignore[method-assign]
        node_thread = None
        if not path.startswith("rtu"):
            node_thread = start_can_node(nodes[0].profile, scene_file, rate, fd, interface, channel)
        from web_viewers import Viewers

        # the viewers connected before the run: their process's start-up is not in it
        with Viewers(web_base or "", viewers or 0) as seen:
            cpu0, t0 = thread_cpu_s(), time.monotonic()
            br.start()
            br.wait(duration_s)
            wall = time.monotonic() - t0
            cpu1 = thread_cpu_s()
        br.stop()
        log.close()
        counters = br.counters()["n1"]
    finally:
        writes = plc.finish()
        if rtu_proc is not None:
            rtu_proc.terminate()
            rtu_proc.wait(timeout=5)
        if pty is not None:
            pty.__exit__(None, None, None)
    if node_thread is not None:
        node_thread.join(timeout=5)
    ours = {k: cpu1.get(k, 0.0) - cpu0.get(k, 0.0) for k in cpu1}
    bridge_cpu = sum(v for k, v in ours.items() if k not in ("bench-node", "MainThread", "bench-viewers"))
    lat_all, lat_slip, skipped = latencies(decisions, arrival, writes)
    return dict(rate=rate, decisions=decisions, lat_all=lat_all, lat_slip=lat_slip, skipped=skipped, arrival=arrival, writes=writes,
                cpu=bridge_cpu / wall, counters=counters, viewer_messages_s=[m / wall for m in seen.messages],
                breakdown=hop_table(decisions, arrival, hops, acks, writes) if breakdown else None)


#: The hops of a decision scan, in order, as ``--breakdown`` times them (wall clock).
HOPS = (("frame", "the deciding scan's last frame sent (its CAN timestamp)"),
        ("woken", "the thread that steps the node holds the frame (the reader serving it, or the loop thread)"),
        ("assembled", "the scan assembled (the source's poll returns it)"),
        ("detected", "calibration, sensor-fault watch and detector done (the pipeline's push returns)"),
        ("snapshot", "the node's snapshot made, handed to the PLC's sink"),
        ("rendered", "the register image rendered, offered to the writer"),
        ("sent", "the write request on the socket (the offering thread, or the writer thread)"),
        ("received", "the PLC stand-in's receipt (its own process)"),
        ("acked", "the bridge's writer has the answer"))


def time_hops(br, rate: float, poll, arrival_of):
    """Wrap the bridge's calls on the urgent path to stamp each hop of every scan
    (``HOPS``): the source's poll, the pipeline's push, the PLC sink's publish, its
    offer and send, and the writer's acknowledged write.  Every hop up to the send
    runs on the thread that steps the node, one scan at a time, so each stamp is the
    scan's that thread polled last."""
    import threading as _threading

    run = br.runs[0]
    loop = run.loop
    plc = next(s for s in run.sinks if s.kind == "plc")
    writer = plc.inner
    hops: dict[int, dict[str, float]] = {}
    acks: list[tuple[float, int]] = []
    now: dict[str, float] = {}  # the hops of the scan being stepped
    woken = [0.0]
    group = getattr(loop.source, "feeder", None)
    if group is not None:  # CAN (an RTU poll is its own thread's: "woken" is its answer)
        on_queued, wait = group._on_queued, group.wait

        def timed_on_queued():  # the reader has frames: it serves them itself when the loop is idle
            woken[0] = time.time()
            return on_queued()

        def timed_wait(timeout_s):  # the loop thread woken by the reader's event: a thread hop
            wait(timeout_s)
            woken[0] = time.time()

        group._on_queued = timed_on_queued  # (taken by serve_arrivals when the bridge starts)
        group.wait = timed_wait

    def timed_poll(timeout_s=None):
        scan = poll(timeout_s)
        if scan is not None:
            k = int(round(scan.t * rate))
            now.clear()
            t = time.time()
            now.update(frame=arrival_of(scan), woken=woken[0] if group is not None else t, assembled=t,
                       inline=float(_threading.current_thread().name == "can-reader"))
            hops[k] = now.copy()
            now["k"] = k
        return scan

    loop.source.poll = timed_poll
    push = loop.pipeline.push

    def timed_push(scan):
        out = push(scan)
        hops[int(round(scan.t * rate))]["detected"] = time.time()
        return out

    loop.pipeline.push = timed_push
    publish, offer = plc.publish, writer.offer
    send_write, write_registers, written = writer.master.send_write, writer.master.write_registers, writer._written

    def stamp(name):
        k = now.get("k")
        if k is not None and name not in hops[k]:
            hops[k][name] = time.time()

    def timed_publish(snap):
        if snap.urgent:
            stamp("snapshot")
        return publish(snap)

    def timed_offer(registers, urgent=False, t_event=None, tail=()):
        if urgent:
            stamp("rendered")
        return offer(registers, urgent, t_event, tail)

    def timed_send(address, values):
        if _threading.current_thread().name != "plc-writer":
            stamp("sent")
        else:  # the writer thread sends what was pending: stamped by STATE below
            acks.append((-time.time(), int(values[1])))
        return send_write(address, values)

    def timed_write(address, values):
        acks.append((-time.time(), int(values[1])))
        return write_registers(address, values)

    def timed_written(registers, t_event, took_s):
        acks.append((time.time(), int(registers[1])))
        return written(registers, t_event, took_s)

    plc.publish = timed_publish
    writer.offer = timed_offer
    writer.master.send_write = timed_send
    writer.master.write_registers = timed_write
    writer._written = timed_written
    return hops, acks


def hop_table(decisions, arrival, hops, acks, writes) -> list[tuple[str, list[float]]]:
    """Per hop, the seconds from the one before it, over the decision scans whose
    every hop was stamped; the writer thread's sends (negative stamps in ``acks``) and
    the acknowledgements are matched by STATE, the first after the scan's detection;
    the PLC's receipt by STATE, as :func:`latencies`."""
    sends = sorted((-t, st) for t, st in acks if t < 0)
    acked = sorted((t, st) for t, st in acks if t >= 0)
    w_times = [t for t, _ in writes]
    s_times, a_times = [t for t, _ in sends], [t for t, _ in acked]

    def first(times, items, t0, state):
        j = int(np.searchsorted(times, t0))
        while j < len(items) and items[j][1] != state:
            j += 1
        return items[j][0] if j < len(items) else None

    rows: dict[str, list[float]] = {name: [] for name, _ in HOPS[1:]}
    rows["total"] = []
    hopped = 0
    for k, state in decisions:
        h = hops.get(k)
        if h is None or "rendered" not in h:
            continue
        h = dict(h)
        if "sent" not in h:  # the writer thread sent it (the offering thread found it busy)
            t = first(s_times, sends, h["rendered"], state)
            if t is None:
                continue
            h["sent"] = t
        rec, ack = first(w_times, writes, h["detected"], state), first(a_times, acked, h["detected"], state)
        if rec is None or ack is None:
            continue
        h["received"], h["acked"] = rec, ack
        hopped += int(not h["inline"])
        names = [name for name, _ in HOPS]
        for a, b in zip(names, names[1:]):
            rows[b].append(h[b] - h[a])
        rows["total"].append(h["received"] - h["frame"])
    rows["loop thread woken"] = [float(hopped)]
    return list(rows.items())


def start_can_node(profile, scene_file: Path, rate: float, fd: bool, interface: str, channel: str,
                   repeat: int = 1) -> threading.Thread:
    from eskin_industrial.bus.can.layout import CanLayout
    from eskin_industrial.bus.can.reader import open_bus
    from eskin_industrial.calibration import Calibrator
    from eskin_industrial.scenes import render
    from eskin_industrial.sim.can_node import CanNode, Faults

    rec = render(str(scene_file), rate, 0)
    raw = np.rint(Calibrator.from_section(profile.calibration, profile.taxels).to_raw(rec.forces))
    layout = CanLayout.from_profile(profile, fd=fd)
    tx = open_bus(interface, channel, fd=fd)
    node = CanNode(layout, tx, raw, rate, profile.can.heartbeat_s, Faults(), False, repeat, None)

    def run():
        try:
            node.run()
        finally:
            tx.shutdown()

    t = threading.Thread(target=run, name="bench-node", daemon=True)
    t.start()
    return t


# -- the reference: python-can Notifier + plain pymodbus --------------------------------

def run_reference(path: str, decisions: list[tuple[int, int]], scene_file: Path, interface: str, channel: str):
    """The same node and the same decision scans; a listener that writes STATE with a
    plain pymodbus client as soon as the last frame of a decision scan arrives."""
    import can

    from eskin_industrial import load_profile
    from eskin_industrial.bus.can.layout import CanLayout
    from eskin_industrial.bus.can.reader import open_bus
    from eskin_industrial.modbus.pymodbus_io import TcpMaster
    from eskin_industrial.outputs.plc.image import REG

    rate = 1000.0 if path.endswith("1k") else 100.0
    fd = rate > 500
    prof = load_profile(PROFILE)
    layout = CanLayout.from_profile(prof, fd=fd)
    last_id = layout.data_id(layout.segments - 1)
    want = dict(decisions)
    plc = PlcCapture()
    master = TcpMaster("127.0.0.1", plc.port, 1, 0.5)
    master.connect()
    arrival: dict[int, float] = {}
    state_at = REG["STATE"].offset
    count = [0]

    class Forward(can.Listener):
        def on_message_received(self, msg: can.Message) -> None:
            if msg.arbitration_id != last_id:
                return
            k = count[0]
            count[0] += 1
            state = want.get(k)
            if state is not None:
                arrival[k] = msg.timestamp
                master.write_registers(prof.modbus.plc.base_address + state_at, [state])

    rx = open_bus(interface, channel, fd=fd)
    notifier = can.Notifier(rx, [Forward()], timeout=0.01)
    node_thread = start_can_node(prof, scene_file, rate, fd, interface, channel)
    node_thread.join()
    time.sleep(0.2)
    notifier.stop()
    rx.shutdown()
    master.close()
    writes = plc.finish()
    lat_all, lat_slip, skipped = latencies(decisions, arrival, writes)
    return dict(lat_all=lat_all, lat_slip=lat_slip, skipped=skipped)


def web_row(path: str, duration_s: float, scene: Path, interface: str, channel: str, n: int, repeats: int = 1) -> str:
    """The console attached with 0 and with ``n`` viewers, one after the other in the same
    run (a fresh bus channel each), ``repeats`` times in turn: the latency the viewers
    add, as the ratio of the medians over the repeats of each run's p50 and p99."""
    suffix = "" if interface != "virtual" else "-web"
    r0s, rns = [], []
    for k in range(repeats):
        r0s.append(run_ours(path, duration_s, scene, interface, f"{channel}{suffix}0-{k}", viewers=0))
        rns.append(run_ours(path, duration_s, scene, interface, f"{channel}{suffix}n-{k}", viewers=n))

    def med(runs: list[dict], q: float) -> float:
        return float(np.median([np.percentile(r["lat_all"], q) for r in runs if r["lat_all"]]))

    ratio = "-"
    if all(r["lat_all"] for r in r0s + rns):
        ratio = f"{med(rns, 50) / med(r0s, 50):.2f}x / {med(rns, 99) / med(r0s, 99):.2f}x"
    cpu0, cpun = (float(np.median([r["cpu"] for r in runs])) for runs in (r0s, rns))
    rates = [m for r in rns for m in r["viewer_messages_s"]]
    each = " / ".join(f"{np.percentile(a['lat_all'], 99) * 1000:.2f}:{np.percentile(b['lat_all'], 99) * 1000:.2f}"
                      for a, b in zip(r0s, rns))
    return (f"| {path} | {repeats} | {med(r0s, 50) * 1000:.2f} / {med(r0s, 99) * 1000:.2f} | {med(rns, 50) * 1000:.2f} / "
            f"{med(rns, 99) * 1000:.2f} | {ratio} | {cpu0 * 100:.1f} / {cpun * 100:.1f} % | "
            f"{(cpun - cpu0) * 100 / max(n, 1):.2f} % | {min(rates):.0f} to {max(rates):.0f} | {each} |"
            if rates else "-")


def ms(values, q) -> str:
    return f"{np.percentile(np.asarray(values) * 1000, q):.2f}" if len(values) else "-"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--paths", default=",".join(PATHS),
                    help=f"comma-separated: {', '.join(PATHS)}, vcan-100, vcan-1k (SocketCAN vcan0)")
    ap.add_argument("--duration", type=float, default=60.0, help="seconds per path (default 60)")
    ap.add_argument("--breakdown", action="store_true",
                    help="also where our time goes, hop by hop, per decision scan (p50 / p90 / p99): the frame "
                         "in, the stepping thread woken, assembled, detected, snapshot, image rendered, sent, "
                         "the PLC's receipt, the bridge's acknowledgement")
    ap.add_argument("--viewers", type=int, default=None, metavar="N",
                    help="also, per path, the bridge with the web console attached, with 0 and with N viewers "
                         "(WebSocket clients acknowledging as the page does, in a process of their own), and the "
                         "ratio of their latencies")
    ap.add_argument("--repeats", type=int, default=1, metavar="R",
                    help="with --viewers: the 0 and N viewer runs R times in turn, the ratio of the medians")
    ap.add_argument("--capture", nargs=2, metavar=("PORT", "OUT"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.capture:
        capture_main(int(args.capture[0]), args.capture[1])
        return
    from machine import describe

    from eskin_industrial.modbus.pymodbus_io import quiet_pymodbus

    quiet_pymodbus()
    cmd = (f".venv/bin/python benchmarks/bench_bridge.py --paths {args.paths} --duration {args.duration:g}"
           + (" --breakdown" if args.breakdown else "") + (f" --viewers {args.viewers}" if args.viewers else "")
           + (f" --repeats {args.repeats}" if args.repeats != 1 else ""))
    print(f"# {cmd}")
    print(f"# {time.strftime('%Y-%m-%d', time.gmtime())} on {describe()}")
    print("| path | rate | decisions timed (slips) | ours p50 / p99 ms | slips p50 / p99 ms | reference p50 / p99 ms "
          "| ratio p50 / p99 | bridge CPU | drops |")
    print("|---|---|---|---|---|---|---|---|---|")
    breakdowns: list[str] = []
    web_rows: list[str] = []
    with tempfile.TemporaryDirectory() as tmp:
        scene = Path(tmp) / "slip-train.toml"
        scene.write_text(slip_train_toml(args.duration))
        for path in args.paths.split(","):
            if path.startswith("vcan"):
                interface, channel = "socketcan", "vcan0"
            else:
                interface, channel = "virtual", f"bench-bridge-{os.getpid()}-{path}"
            r = run_ours(path, args.duration, scene, interface, channel, args.breakdown)
            ref = None
            if not path.startswith("rtu"):
                ref = run_reference(path, r["decisions"], scene, interface, channel + "-ref"
                                    if interface == "virtual" else channel)
            c = r["counters"]
            drops = (c.get("rx_queue_drops", 0) + c.get("lost_scans", 0) + c.get("torn_scans", 0)
                     + c.get("rtu_failed_polls", 0))
            n_slip = sum(1 for _, s in r["decisions"] if s == 3)
            ratio = "-"
            if ref and ref["lat_all"] and r["lat_all"]:
                p50 = np.percentile(r["lat_all"], 50) / np.percentile(ref["lat_all"], 50)
                p99 = np.percentile(r["lat_all"], 99) / np.percentile(ref["lat_all"], 99)
                ratio = f"{p50:.1f}x / {p99:.1f}x"
            refcol = f"{ms(ref['lat_all'], 50)} / {ms(ref['lat_all'], 99)}" if ref else "- (no RTU reference)"
            print(f"| {path} | {r['rate']:g} Hz | {len(r['lat_all'])} ({n_slip}), {r['skipped']} superseded | {ms(r['lat_all'], 50)} / "
                  f"{ms(r['lat_all'], 99)} | {ms(r['lat_slip'], 50)} / {ms(r['lat_slip'], 99)} | {refcol} | {ratio} | "
                  f"{r['cpu'] * 100:.1f} % | {drops} (of {c.get('scans', 0)} scans) |", flush=True)
            if r["breakdown"]:
                rows = dict(r["breakdown"])
                n = len(rows["total"])
                breakdowns.append(f"# {path}: the hops of {n} decision scans, each from the one before "
                                  f"(the loop thread woken for {int(rows['loop thread woken'][0])} of them; "
                                  "the others served by the reader)")
                breakdowns.append("| hop | what | p50 us | p90 us | p99 us |")
                breakdowns.append("|---|---|---|---|---|")
                for name, what in HOPS[1:] + (("total", "frame -> received: the bench's latency"),):
                    v = np.asarray(rows[name]) * 1e6
                    if len(v):
                        breakdowns.append(f"| {name} | {what} | {np.percentile(v, 50):.0f} | {np.percentile(v, 90):.0f} "
                                          f"| {np.percentile(v, 99):.0f} |")
            if args.viewers:
                web_rows.append(web_row(path, args.duration, scene, interface, channel, args.viewers, args.repeats))
    for line in breakdowns:
        print(line)
    if web_rows:
        print()
        print(f"| path | repeats | console, 0 viewers: p50 / p99 ms | {args.viewers} viewers: p50 / p99 ms "
              "| ratio p50 / p99 | bridge CPU 0 / N | CPU per viewer | messages/s per viewer | p99 0:N each repeat |")
        print("|---|---|---|---|---|---|---|---|---|")
        for row in web_rows:
            print(row)


if __name__ == "__main__":
    main()
