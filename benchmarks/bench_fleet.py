"""A fleet of sensor nodes on one bridge process publishing Sparkplug B to one local
mosquitto: how many nodes one core carries with no drops, the bridge's CPU per node,
the broker's messages/s, memory; and the latency from the scan that decides a state
to a ``mosquitto_sub`` subscriber receiving its DDATA, against a bare paho-mqtt floor.

    .venv/bin/python benchmarks/bench_fleet.py                      # fleet and latency (~8 min)
    .venv/bin/python benchmarks/bench_fleet.py --nodes-100 8,16,32 --nodes-1k 1,2,4 --duration 10
    .venv/bin/python benchmarks/bench_fleet.py --only latency --latency-duration 60
    .venv/bin/python benchmarks/bench_fleet.py --only fleet --nodes-100 8 --nodes-1k 2 --frame-interval 1
    .venv/bin/python benchmarks/bench_fleet.py --only fleet --pin --nodes-100 16,32,48,64 --nodes-1k 4,8,16 --duration 20

The nodes: the project's CAN node simulator (``sim/can_node.py``), playing the slip train of ``bench_bridge.py`` (a still grasp with a
slide every 1.2 s: about 110 state changes a minute per node, each a DDATA at once,
besides the analog metrics at their minimum interval).  CAN nodes, not ``scene:``
sources: the frame decode, the routing by ID and the scan assembly are part of what
a node costs the bridge (scene sources skip them).  Nodes share buses as they would on
a real line: ``--per-bus`` nodes (distinct node ids and base IDs) on each bus, 4 by
default (100 Hz classic: 9 frames a scan, 3,600 frames/s a bus; 1 kHz CAN FD: one
frame a scan, 4,000 frames/s a bus, near what FD at 1/5 Mbit/s carries).

The simulators run in processes of their own (``--sender-procs``, 4 by default; a
bus's nodes in one of them), sending over a loopback datagram bus
(``benchmarks/udp_bus.py``: one UDP datagram a frame, the sender's time as the frame's
timestamp) that the bridge opens as a python-can interface like any other: its
reader threads, routing, assembly, detection and outputs are the product's own, and
the simulators share neither its interpreter lock nor, with ``--pin``, its CPU (the
bridge's process on CPU 0; the simulators, the broker and the subscriber on CPU 1).
``--sender-procs 0`` runs them as before, one thread a node in the bridge's process on
python-can's virtual buses (whose count of nodes is then a lower bound).  ``--web``
attaches the web console (no viewer) to the fleet's bridge.

- bridge CPU: the bridge's own threads (readers, loops, paho's network thread, the
  store's), % of one core; per node = that / N.
- drops: frames dropped from a reader's queue, lost and torn scans, Sparkplug
  messages dropped; "scans" is what the loops took against what the nodes sent;
  "stale": the times a node's ``Sensor Stale`` went true in the DDATA received (the
  loop got to a node's scan later than ``stale_s``, 2.5 scan periods by default: the
  PLC and the plant would see it).
- broker: messages/s received by a ``mosquitto_sub`` on ``spBv1.0/#`` (the broker's
  fan-out to one subscriber: every message the bridge published), and the broker's
  own CPU (``/proc/PID/stat``).
- memory: the process's resident set (VmRSS) at the end of the step, and its growth
  from before the bridge opened (the simulators' frames already made): the bridge's
  own memory, its queues and buffers.
- frames (``--frame-interval S``: ``[sparkplug] frame_interval_s`` of the fleet's
  bridge): the taxel frames received per second and the size of one frame's DDATA
  (median, bytes: the payload as the broker carries it).
- A step is "carried" when it has no drop and no stale node, the bridge took every scan sent, and the
  bridge's CPU stays under 90 % of one core (the interpreter lock makes one core the
  bound of one bridge process).  When the simulators fall behind their deadlines by
  more than 0.5 s (the process's interpreter is saturated by bridge and simulators
  together) the step is not carried either, and says so.

Latency (one node, at 100 Hz and 1 kHz; its simulator in the bridge's process on a
virtual bus, as its floor's): from the arrival of the frame completing
the deciding scan (python-can's message timestamp: the virtual bus stamps at send)
to the receipt of the DDATA carrying the new state by ``mosquitto_sub`` (its ``%U``
timestamp, payloads decoded with the ``protobuf`` package from the tests' schema,
not the package's codec).  The floor, in the same run: python-can's ``Notifier`` on
the same node's traffic and a bare paho-mqtt client that publishes the very DDATA
bytes our run sent for that decision, from the listener thread, the moment the
deciding scan's last frame arrives (no assembly, no detection, no encoding): what
python-can, paho and the broker cost.  Ratio = ours / floor.
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_bridge import PROFILE, latencies, slip_train_toml, thread_cpu_s  # noqa: E402
from machine import describe  # noqa: E402

from tests.helpers import sparkplug as spb  # noqa: E402
from tests.helpers.modbus import need  # noqa: E402

GROUP = "bench"
STATE_CODE, STALE = 1, 5  # alias offsets of "State Code", "Sensor Stale" in a device's block (DEVICE_METRICS order)
FRAME = 50  # the alias offset of "Taxels/Frame" (FRAME_ALIAS)
DROP_KEYS = ("rx_queue_drops", "lost_scans", "torn_scans", "sparkplug_dropped")


# -- measuring ------------------------------------------------------------------------

def rss_kib() -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    return 0


def proc_cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


class Subscriber:
    """``mosquitto_sub`` on ``spBv1.0/#``: every message as (receipt time, topic, payload)."""

    def __init__(self, port: int, out: Path, payloads: bool = True) -> None:
        self.out = out
        self._file = open(out, "w")
        fmt = "%U %t %x" if payloads else "%t"
        self.proc = subprocess.Popen([need("mosquitto_sub"), "-h", "127.0.0.1", "-p", str(port), "-t", "spBv1.0/#",
                                      "-F", fmt], stdout=self._file, stderr=subprocess.DEVNULL)
        time.sleep(0.3)  # subscribed before anything is published

    def count(self) -> int:
        self._file.flush()
        with open(self.out, "rb") as f:
            return sum(1 for _ in f)

    def close(self) -> None:
        time.sleep(0.3)
        self.proc.terminate()
        self.proc.wait(5)
        self._file.close()

    def messages(self) -> list[tuple[float, str, bytes]]:
        out = []
        for line in self.out.read_text().splitlines():
            t, topic, hexed = line.split(" ", 2)
            out.append((float(t), topic, bytes.fromhex(hexed)))
        return out


def state_changes(msgs: list[tuple[float, str, bytes]], edge: str, device: str = "n01") -> list[tuple[float, int, bytes]]:
    """(receipt time, State Code, payload) of every DDATA of ``edge``/``device`` that carries a state."""
    out = []
    for t, topic, data in msgs:
        parts = topic.split("/")
        if parts[2] != "DDATA" or parts[3] != edge or parts[-1] != device:
            continue
        for m in spb.parse(data).metrics:
            if m.alias % 1000 == STATE_CODE:
                out.append((t, int(spb.value(m)), data))
    return out


# -- the nodes ------------------------------------------------------------------------

def make_nodes(profile: Any, raw: np.ndarray, rate: float, fd: bool, buses: list[tuple[str, int]],
               interface: str = "virtual") -> list[tuple[threading.Thread, Any]]:
    """One simulator thread a node (not started): ``buses`` = (channel, index on that bus)."""
    from eskin_industrial.bus.can.layout import CanLayout
    from eskin_industrial.bus.can.reader import open_bus
    from eskin_industrial.sim.can_node import CanNode, Faults

    base = CanLayout.from_profile(profile, fd=fd)
    # one sending bus a channel, shared by its nodes: a virtual bus copies every frame
    # into the queue of each other bus on the channel, and the nodes read none
    if interface == "virtual":
        tx = {channel: open_bus("virtual", channel, fd=fd) for channel, _ in buses}
    else:  # a sending end of the loopback datagram bus (udp_bus.py)
        import can

        tx = {channel: can.Bus(interface=interface, channel=channel, receive=False, fd=fd) for channel, _ in buses}
    left = [len(buses)]
    lock = threading.Lock()
    out = []
    for i, (channel, k) in enumerate(buses):
        layout = dataclasses.replace(base, base_id=base.base_id + 0x10 * k, node_id=k + 1)
        node = CanNode(layout, tx[channel], raw, rate, profile.can.heartbeat_s, Faults(), False, 1, None)

        def run(node: CanNode = node) -> None:
            try:
                node.run()
            finally:
                with lock:
                    left[0] -= 1
                    if left[0] == 0:
                        for bus in tx.values():
                            bus.shutdown()

        t = threading.Thread(target=run, name=f"bench-node-{i}", daemon=True)
        out.append((t, node))
    return out


def sender_main(spec_json: str) -> None:
    """A process of simulated nodes (``--sender``): renders the scene, says ``ready``,
    starts its nodes at ``go`` on stdin, and prints each node's stats as JSON at the end."""
    import json

    import udp_bus

    from eskin_industrial import load_profile

    spec = json.loads(spec_json)
    if spec.get("cpu") is not None:
        os.sched_setaffinity(0, {int(spec["cpu"])})
    udp_bus.register()
    logging.getLogger("can").setLevel(logging.ERROR)
    profile = load_profile(PROFILE)
    rate = float(spec["rate"])
    raw = raw_scans(profile, Path(spec["scene"]), rate)
    sims = make_nodes(profile, raw, rate, rate > 500, [(str(p), int(k)) for p, k in spec["buses"]], udp_bus.INTERFACE)
    print("ready", flush=True)
    sys.stdin.readline()
    start(sims)
    for t, _ in sims:
        t.join()
    print(json.dumps([{"scans": node.stats.scans, "late_s": node.stats.late_s} for _, node in sims]), flush=True)


class Senders:
    """The simulated nodes in ``procs`` processes of their own, pinned to ``cpu``: the
    bridge's process runs none of their work (nor shares their interpreter lock)."""

    def __init__(self, rate: float, scene: Path, buses: list[tuple[str, int]], procs: int, cpu: int | None) -> None:
        import json

        by_bus: dict[str, list[tuple[str, int]]] = {}
        for channel, k in buses:
            by_bus.setdefault(channel, []).append((channel, k))
        groups: list[list[tuple[str, int]]] = [[] for _ in range(min(procs, len(by_bus)))]
        for i, members in enumerate(by_bus.values()):  # a bus's nodes stay in one process: one sending socket
            groups[i % len(groups)].extend(members)
        self.procs = []
        for g in groups:
            spec = json.dumps({"rate": rate, "scene": str(scene), "buses": g, "cpu": cpu})
            self.procs.append(subprocess.Popen([sys.executable, __file__, "--sender", spec], stdin=subprocess.PIPE,
                                               stdout=subprocess.PIPE, text=True))
        for p in self.procs:
            assert p.stdout is not None and p.stdout.readline().strip() == "ready"

    def go(self) -> None:
        for p in self.procs:
            assert p.stdin is not None
            p.stdin.write("go\n")
            p.stdin.flush()

    def cpu_s(self) -> float:
        return sum(proc_cpu_s(p.pid) for p in self.procs)

    def finish(self, timeout_s: float) -> list[dict[str, float]]:
        import json

        out: list[dict[str, float]] = []
        for p in self.procs:
            assert p.stdout is not None
            line, _ = p.communicate(timeout=timeout_s)
            out += json.loads(line.strip().splitlines()[-1])
        return out


def start(sims: list[tuple[threading.Thread, Any]]) -> list[tuple[threading.Thread, Any]]:
    for t, _ in sims:
        t.start()
    return sims


def raw_scans(profile: Any, scene: Path, rate: float) -> np.ndarray:
    from eskin_industrial.calibration import Calibrator
    from eskin_industrial.scenes import render

    rec = render(str(scene), rate, 0)
    return np.rint(Calibrator.from_section(profile.calibration, profile.taxels).to_raw(rec.forces))


def bridge_for(n: int, rate: float, per_bus: int, port: int, edge: str, tag: str, frame_interval_s: float = 0.0,
               interface: str = "virtual", web: bool = False):
    """``interface`` "virtual": the nodes' buses are python-can's virtual ones (the
    simulators in this process); else the loopback datagram bus (udp_bus.py), a UDP
    port a bus.  ``web``: the web console attached too (no viewer)."""
    from eskin_industrial.bridge.config import BridgeConfig, LogSettings, NodeConfig, resolve
    from eskin_industrial.outputs.sparkplug.options import SparkplugOptions
    from tests.helpers.modbus import free_port

    fd = rate > 500
    base = 0x200
    nodes, buses = [], []
    channels: dict[int, str] = {}
    for i in range(n):
        b, k = i // per_bus, i % per_bus
        if b not in channels:
            channels[b] = f"fleet-{os.getpid()}-{tag}-bus{b}" if interface == "virtual" else str(free_port())
        channel = channels[b]
        nodes.append(NodeConfig.of(f"n{i + 1:02d}", str(PROFILE), "can", interface=interface, channel=channel, fd=fd,
                                   rate_hz=rate, outputs={"plc": {"base_address": 32 * i}}, node_id=k + 1,
                                   base_id=base + 0x10 * k))
        buses.append((channel, k))
    outputs: dict[str, Any] = {"sparkplug": SparkplugOptions(f"mqtt://127.0.0.1:{port}", GROUP, edge,
                                                            frame_interval_s=frame_interval_s)}
    if web:
        from eskin_industrial.outputs.web.options import WebOptions

        outputs["web"] = WebOptions(bind=f"127.0.0.1:{free_port()}")
    cfg = BridgeConfig(node=tuple(nodes), outputs=outputs, log=LogSettings(status_every_s=0))
    return cfg, resolve(cfg), buses


# -- the fleet ------------------------------------------------------------------------

def run_step(n: int, rate: float, per_bus: int, port: int, broker_pid: int, scene: Path, duration_s: float,
             tmp: Path, frame_interval_s: float = 0.0, procs: int = 0, sender_cpu: int | None = None,
             web: bool = False) -> dict[str, Any]:
    """``procs`` > 0: the simulators in that many processes of their own (on
    ``sender_cpu``), over the loopback datagram bus; 0: threads of this process on
    python-can's virtual bus."""
    from eskin_industrial.bridge.logs import EventLog
    from eskin_industrial.bridge.runtime import Bridge

    tag = f"{int(rate)}-{n}-{time.monotonic_ns()}"
    interface = "virtual" if procs == 0 else "udp-loopback"
    cfg, nodes, buses = bridge_for(n, rate, per_bus, port, f"fleet{n}x{int(rate)}", tag, frame_interval_s,
                                   interface, web)
    sub = Subscriber(port, tmp / f"count-{tag}.txt")
    sims: list[tuple[threading.Thread, Any]] = []
    senders: Senders | None = None
    if procs == 0:
        raw = raw_scans(nodes[0].profile, scene, rate)
        sims = make_nodes(nodes[0].profile, raw, rate, rate > 500, buses)  # their frames made before rss0
    else:
        senders = Senders(rate, scene, buses, procs, sender_cpu)
        if sender_cpu is not None:
            os.sched_setaffinity(sub.proc.pid, {sender_cpu})
    rss0 = rss_kib()
    log = EventLog(open(os.devnull, "w"), "plain", "warning")
    br = Bridge(cfg, nodes, log).open()
    br.start()
    time.sleep(0.5)  # connected, births out
    if senders is not None:
        senders.go()
    start(sims)
    time.sleep(1.0)  # the first scans: the loops and the buses warm
    s0 = senders.cpu_s() if senders is not None else 0.0
    m0, cpu0, b0, t0, w0 = sub.count(), thread_cpu_s(), proc_cpu_s(broker_pid), time.monotonic(), time.time()
    time.sleep(duration_s)
    m1, cpu1, b1, wall, w1 = sub.count(), thread_cpu_s(), proc_cpu_s(broker_pid), time.monotonic() - t0, time.time()
    s1 = senders.cpu_s() if senders is not None else 0.0
    rss1 = rss_kib()
    for t, _ in sims:
        t.join(timeout=duration_s + 30)
    stats = senders.finish(duration_s + 30) if senders is not None else [
        {"scans": node.stats.scans, "late_s": node.stats.late_s} for _, node in sims]
    time.sleep(0.3)
    br.stop()
    log.close()
    sub.close()
    counters = br.counters()
    ours = {k: cpu1.get(k, 0.0) - cpu0.get(k, 0.0) for k in cpu1}
    bridge_cpu = sum(v for k, v in ours.items() if not k.startswith("bench-node") and k != "MainThread") / wall
    sim_cpu = (sum(v for k, v in ours.items() if k.startswith("bench-node")) + s1 - s0) / wall
    drops = sum(c.get(k, 0) for c in counters.values() for k in DROP_KEYS)
    scans = sum(c.get("scans", 0) for c in counters.values())
    sent = int(sum(st["scans"] for st in stats))
    late = max(st["late_s"] for st in stats)
    # a node the loop fell behind on by more than stale_s (2.5 scan periods) is
    # "Sensor Stale" for a moment: the PLC and the plant would see it (counted in the
    # measured span only: every node turns stale when its simulator ends)
    measured = [(topic, data) for t, topic, data in sub.messages() if "/DDATA/" in topic and w0 <= t <= w1]
    stale = sum(1 for topic, data in measured for m in spb.parse(data).metrics if m.alias % 1000 == STALE and spb.value(m))
    frames = [len(data) for topic, data in measured if any(m.alias % 1000 == FRAME for m in spb.parse(data).metrics)]
    return dict(n=n, rate=rate, cpu=bridge_cpu, sim_cpu=sim_cpu, drops=drops, scans=scans, sent=sent, stale=stale,
                msgs=(m1 - m0) / wall, broker_cpu=(b1 - b0) / wall, rss=rss1, rss_growth=rss1 - rss0, late=late,
                frames=len(frames) / (w1 - w0), frame_bytes=int(np.median(frames)) if frames else 0)


# -- latency --------------------------------------------------------------------------

def run_latency(rate: float, port: int, scene: Path, duration_s: float, tmp: Path) -> dict[str, Any]:
    from eskin_industrial.bridge.logs import EventLog
    from eskin_industrial.bridge.runtime import Bridge

    tag = f"lat{int(rate)}-{time.monotonic_ns()}"
    cfg, nodes, buses = bridge_for(1, rate, 1, port, f"lat{int(rate)}", tag)
    raw = raw_scans(nodes[0].profile, scene, rate)
    decisions: list[tuple[int, int]] = []
    last = [-1]

    def on_update(_name: str, u: Any) -> None:
        if u.state != last[0]:
            if last[0] != -1:
                decisions.append((int(round(u.t * rate)), int(u.state)))
            last[0] = u.state

    sub = Subscriber(port, tmp / f"{tag}.txt")
    log = EventLog(open(os.devnull, "w"), "plain", "warning")
    br = Bridge(cfg, nodes, log, on_update=on_update).open()
    arrival: dict[int, float] = {}
    source = br.runs[0].loop.source
    poll = source.poll

    def timed_poll(timeout_s: float | None = None) -> Any:
        scan = poll(timeout_s)
        if scan is not None:
            arrival[int(round(scan.t * rate))] = scan.rx_time
        return scan

    source.poll = timed_poll  # type: ignore[method-assign]
    bare = same_thread_floor(br.runs[0].sinks[0].node.client, port, f"spBv1.0/{GROUP}/DDATA/same{int(rate)}/n01")
    br.start()
    time.sleep(0.5)
    cpu0, t0 = thread_cpu_s(), time.monotonic()
    sims = start(make_nodes(nodes[0].profile, raw, rate, rate > 500, buses))
    for t, _ in sims:
        t.join(timeout=duration_s + 30)
    wall = time.monotonic() - t0
    cpu1 = thread_cpu_s()
    time.sleep(0.3)
    br.stop()
    log.close()
    sub.close()
    bare.loop_stop()
    bare.disconnect()
    msgs = sub.messages()
    got = state_changes(msgs, f"lat{int(rate)}")
    same_all, same_slip, same_skipped = latencies(decisions, arrival, [(t, s) for t, s, _ in state_changes(msgs, f"same{int(rate)}")])
    ours_all, ours_slip, skipped = latencies(decisions, arrival, [(t, s) for t, s, _ in got])
    cpu = sum(v - cpu0.get(k, 0.0) for k, v in cpu1.items() if not k.startswith("bench-node") and k != "MainThread")
    # the floor: the same decisions, the very bytes our run sent for each
    payload_of: dict[int, bytes] = {}
    times = [t for t, _, _ in got]
    for k, state in decisions:
        t_k = arrival.get(k)
        if t_k is None:
            continue
        j = int(np.searchsorted(times, t_k))
        while j < len(got) and got[j][1] != state:
            j += 1
        if j < len(got):
            payload_of[k] = got[j][2]
    ref_all, ref_slip, ref_skipped = run_floor(rate, port, nodes[0].profile, raw, decisions, payload_of, tmp)
    return dict(rate=rate, decisions=decisions, all=ours_all, slip=ours_slip, skipped=skipped, ref_all=ref_all,
                same_all=same_all, same_slip=same_slip,
                ref_slip=ref_slip, ref_skipped=ref_skipped, cpu=cpu / wall)


def same_thread_floor(client: Any, port: int, topic: str) -> Any:
    """A bare paho-mqtt client of its own that publishes every DDATA the edge node
    publishes, the same bytes, from the same thread at the same moment: just before
    the edge node's own publish at every other DDATA, just after at the others (so
    neither is favoured by going first)."""
    import paho.mqtt.client as mqtt

    bare = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=f"same-{os.getpid()}-{time.monotonic_ns()}")
    bare.connect("127.0.0.1", port, 30)
    bare.loop_start()
    publish = client.publish
    flip = [False]

    def both(topic_: str, payload: Any = None, qos: int = 0, retain: bool = False, properties: Any = None) -> Any:
        if "/DDATA/" not in topic_:
            return publish(topic_, payload, qos, retain, properties)
        flip[0] = not flip[0]
        if flip[0]:
            bare.publish(topic, payload, qos=0)
            return publish(topic_, payload, qos, retain, properties)
        info = publish(topic_, payload, qos, retain, properties)
        bare.publish(topic, payload, qos=0)
        return info

    client.publish = both
    return bare


def run_floor(rate: float, port: int, profile: Any, raw: np.ndarray, decisions: list[tuple[int, int]],
              payload_of: dict[int, bytes], tmp: Path) -> tuple[list[float], list[float], int]:
    import can
    import paho.mqtt.client as mqtt

    from eskin_industrial.bus.can.layout import CanLayout
    from eskin_industrial.bus.can.reader import open_bus

    fd = rate > 500
    layout = CanLayout.from_profile(profile, fd=fd)
    last_id = layout.data_id(layout.segments - 1)
    want = dict(decisions)
    topic = f"spBv1.0/{GROUP}/DDATA/floor{int(rate)}/n01"
    client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=f"floor-{os.getpid()}-{int(rate)}")
    client.connect("127.0.0.1", port, 30)
    client.loop_start()
    sub = Subscriber(port, tmp / f"floor-{int(rate)}-{time.monotonic_ns()}.txt")
    arrival: dict[int, float] = {}
    count = [0]

    class Forward(can.Listener):
        def on_message_received(self, msg: can.Message) -> None:
            if msg.arbitration_id != last_id:
                return
            k = count[0]
            count[0] += 1
            if k in want and k in payload_of:
                arrival[k] = msg.timestamp
                client.publish(topic, payload_of[k], qos=0)

    channel = f"floor-{os.getpid()}-{int(rate)}"
    rx = open_bus("virtual", channel, fd=fd)
    notifier = can.Notifier(rx, [Forward()], timeout=0.01)
    sims = start(make_nodes(profile, raw, rate, fd, [(channel, 0)]))
    for t, _ in sims:
        t.join()
    time.sleep(0.3)
    notifier.stop()
    rx.shutdown()
    client.loop_stop()
    client.disconnect()
    sub.close()
    got = state_changes(sub.messages(), f"floor{int(rate)}")
    timed = [(k, s) for k, s in decisions if k in payload_of]
    a, s, skipped = latencies(timed, arrival, [(t, st) for t, st, _ in got])
    return a, s, skipped + len(decisions) - len(timed)


# -- output ---------------------------------------------------------------------------

def ms(values: list[float], q: float) -> str:
    return f"{np.percentile(np.asarray(values) * 1000, q):.2f}" if len(values) else "-"


def ratio(ours: list[float], floor: list[float]) -> str:
    if not ours or not floor:
        return "-"
    return (f"{np.percentile(ours, 50) / np.percentile(floor, 50):.2f}x / "
            f"{np.percentile(ours, 99) / np.percentile(floor, 99):.2f}x")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", choices=("fleet", "latency"), help="one part only")
    ap.add_argument("--nodes-100", default="8,16,32,48,64,96,128", help="node counts at 100 Hz, in order (\"\": none)")
    ap.add_argument("--nodes-1k", default="1,2,4,8,12,16", help="node counts at 1 kHz, in order (\"\": none)")
    ap.add_argument("--per-bus", type=int, default=4, help="nodes sharing one CAN bus (default 4)")
    ap.add_argument("--duration", type=float, default=20.0, help="seconds measured per fleet step (default 20)")
    ap.add_argument("--latency-duration", type=float, default=60.0, help="seconds per latency rate (default 60)")
    ap.add_argument("--frame-interval", type=float, default=0.0, help="the fleet's [sparkplug] frame_interval_s "
                    "(default 0: no taxel frames)")
    ap.add_argument("--go-on", action="store_true", help="every step, even past a drop, the simulators behind "
                    "or the bridge at 90 %% of a core")
    ap.add_argument("--sender-procs", type=int, default=4, help="the fleet's simulators in this many processes of "
                    "their own, over a loopback datagram bus (udp_bus.py); 0: threads of the bridge's process on "
                    "python-can's virtual bus, as before (default 4)")
    ap.add_argument("--pin", action="store_true", help="the bridge's process on CPU 0, the simulators, broker "
                    "and subscriber on CPU 1 (os.sched_setaffinity)")
    ap.add_argument("--web", action="store_true", help="the fleet's bridge with the web console attached too")
    ap.add_argument("--sender", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.sender:
        sender_main(args.sender)
        return
    logging.getLogger("can").setLevel(logging.ERROR)  # python-can's note on a bus closed by the collector
    import udp_bus

    udp_bus.register()  # the bridge opens the senders' buses by this interface name
    cmd = (".venv/bin/python benchmarks/bench_fleet.py" + (f" --only {args.only}" if args.only else "")
           + (f" --nodes-100 {args.nodes_100} --nodes-1k {args.nodes_1k} --per-bus {args.per_bus} "
              f"--duration {args.duration:g}" if args.only != "latency" else "")
           + (f" --latency-duration {args.latency_duration:g}" if args.only != "fleet" else "")
           + (f" --frame-interval {args.frame_interval:g}" if args.frame_interval else "")
           + (" --go-on" if args.go_on else "")
           + (f" --sender-procs {args.sender_procs}" if args.only != "latency" else "")
           + (" --pin" if args.pin else "") + (" --web" if args.web else ""))
    print(f"# {cmd}")
    print(f"# {time.strftime('%Y-%m-%d', time.gmtime())} on {describe()}")
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        broker = spb.Broker(tmp)
        sender_cpu = None
        if args.pin:
            # this thread first: every thread the bridge starts inherits its CPU
            os.sched_setaffinity(0, {0})
            os.sched_setaffinity(broker.proc.pid, {1})
            sender_cpu = 1
        try:
            if args.only != "fleet":
                scene = tmp / "slip-train-latency.toml"
                scene.write_text(slip_train_toml(args.latency_duration))
                print("| latency | rate | decisions timed (slips) | ours p50 / p99 ms | slips p50 / p99 ms "
                      "| floor, same thread: p50 / p99 ms | ratio p50 / p99 | floor, no bridge: p50 / p99 ms "
                      "| ratio p50 / p99 | bridge CPU |")
                print("|---|---|---|---|---|---|---|---|---|---|")
                for rate in (100.0, 1000.0):
                    r = run_latency(rate, broker.port, scene, args.latency_duration, tmp)
                    n_slip = sum(1 for _, s in r["decisions"] if s == 3)
                    print(f"| 1 node to mosquitto_sub | {rate:g} Hz | {len(r['all'])} ({n_slip}), {r['skipped']} not timed "
                          f"| {ms(r['all'], 50)} / {ms(r['all'], 99)} | {ms(r['slip'], 50)} / {ms(r['slip'], 99)} "
                          f"| {ms(r['same_all'], 50)} / {ms(r['same_all'], 99)} | {ratio(r['all'], r['same_all'])} "
                          f"| {ms(r['ref_all'], 50)} / {ms(r['ref_all'], 99)} | {ratio(r['all'], r['ref_all'])} "
                          f"| {r['cpu'] * 100:.1f} % |", flush=True)
            if args.only != "latency":
                scene = tmp / "slip-train-fleet.toml"
                scene.write_text(slip_train_toml(args.duration + 3))
                print("| fleet | rate | nodes | bridge CPU (% of a core) | per node | drops | stale | scans taken / sent "
                      "| broker msgs/s | per node | broker CPU | RSS MiB (growth) | carried |")
                print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
                for rate, counts in ((100.0, args.nodes_100), (1000.0, args.nodes_1k)):
                    for n in (int(x) for x in counts.split(",") if x.strip()):  # ("": none at that rate)
                        r = run_step(n, rate, args.per_bus, broker.port, broker.proc.pid, scene, args.duration, tmp,
                                     args.frame_interval, args.sender_procs, sender_cpu, args.web)
                        behind = r["late"] > 0.5 or r["scans"] < r["sent"]
                        ok = r["drops"] == 0 and r["stale"] == 0 and r["cpu"] < 0.9 and not behind
                        print(f"| one bridge | {rate:g} Hz | {n} | {r['cpu'] * 100:.1f} % | {r['cpu'] * 100 / n:.2f} % "
                              f"| {r['drops']} | {r['stale']} | {r['scans']} / {r['sent']} | {r['msgs']:.0f} | {r['msgs'] / n:.1f} "
                              f"| {r['broker_cpu'] * 100:.1f} % | {r['rss'] / 1024:.0f} ({r['rss_growth'] / 1024:+.0f}) "
                              f"| {'yes' if ok else 'no (simulators behind)' if behind else 'no (stale)' if r['stale'] else 'no'} |", flush=True)
                        print(f"#   simulators: {r['sim_cpu'] * 100:.0f} % of a core, latest scan "
                              f"{r['late'] * 1000:.1f} ms behind its deadline", flush=True)
                        if args.frame_interval:
                            print(f"#   taxel frames: {r['frames']:.1f}/s received ({r['frames'] / n:.2f} per node), "
                                  f"a frame's DDATA {r['frame_bytes']} bytes", flush=True)
                        if (behind or r["drops"] or r["cpu"] >= 0.9) and not args.go_on:
                            break  # (a stale node alone does not end the steps: it may be the machine's hiccup)
        finally:
            broker.kill()


if __name__ == "__main__":
    main()
