"""The OPC UA output: from the scan that decides a state to a subscribed client's
data-change notification, against a bare asyncua server writing the same value to
the same client in the same run; and what the output costs per node in a fleet on
one bridge.

    .venv/bin/python benchmarks/bench_opcua.py                          # both (~8 min)
    .venv/bin/python benchmarks/bench_opcua.py --only latency --duration 90
    .venv/bin/python benchmarks/bench_opcua.py --only fleet --nodes 8,16 --fleet-duration 20 --repeats 2
    .venv/bin/python benchmarks/bench_opcua.py --only storms --storm-s 8

Latency (one node, at 100 Hz and 1 kHz): a CAN node of the project's simulator on
python-can's virtual bus plays the slip train of ``bench_bridge.py`` (a slide every
1.2 s: about 110 state changes a minute) into a bridge whose only output is OPC UA.
At every state change the loop hands its snapshot to our server, and the same moment
(alternately just before and just after) hands the new state to a bare asyncua
server of its own (its own thread and event loop, one Int32 variable, one write:
what asyncua itself costs).  One asyncua client, in a process of its own, subscribes
to both (the same publishing interval, 0: publish at once) and notes the wall-clock
time of every notification.  Latency = that time minus the deciding scan's arrival
(the snapshot's ``wall_time_s``, the source timestamp both servers send).  Ratio =
ours / bare, p50 and p99.

Fleet: N nodes at 100 Hz (4 a bus) on one bridge, run twice the same way: with the
OPC UA output (one client subscribed to every node's GraspState, Slip and TotalForce,
100 ms publishing interval), and with an output that does nothing.  The bridge's CPU
(its threads, the simulators' left out, from ``/proc/self/task``) of the one minus
the other, per node: what OPC UA adds, its server thread and the loops' handover.
Each step repeated ``--repeats`` times, in turn; medians.

Storms (``bench_opcua_storms.py``): a well-behaved client's reads while idle sockets,
connect/close storms, malformed messages and 50 clients at once hit the server, its
worst read in each phase (target: at most 50 ms), and whether every refused client
was told why.
"""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
import os
import subprocess
import sys
import tempfile
import threading
import time
from datetime import UTC
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_bridge import PROFILE, slip_train_toml  # noqa: E402
from bench_bridge import thread_cpu_s as bridge_thread_cpu_s  # noqa: E402
from bench_fleet import make_nodes, raw_scans, start  # noqa: E402
from bench_opcua_storms import print_storms, run_storms  # noqa: E402
from machine import describe  # noqa: E402

NAMESPACE_URI = "urn:eskin-industrial:opcua:grasp"


# -- the client (a process of its own) ------------------------------------------------

def client_main(specs: list[str], interval_ms: float) -> None:
    """``TAG=URL=NODEID`` ...: subscribe to each, print ``TAG TIME VALUE`` per notification."""
    from asyncua import Client

    class Handler:
        def __init__(self, tag: str) -> None:
            self.tag = tag

        def datachange_notification(self, node: Any, val: Any, data: Any) -> None:
            print(f"{self.tag} {time.time():.6f} {val}", flush=True)

    async def main() -> None:
        clients = []
        for spec in specs:
            tag, url, nodeid = spec.split("=", 2)
            c = Client(url, timeout=30)
            await c.connect()
            ns = await c.get_namespace_index(NAMESPACE_URI) if "{ns}" in nodeid else 0
            sub = await c.create_subscription(interval_ms, Handler(tag))
            for one in nodeid.split(","):
                await sub.subscribe_data_change(c.get_node(one.replace("{ns}", str(ns))), queuesize=100)
            clients.append(c)
        print("ready", flush=True)
        await asyncio.get_running_loop().run_in_executor(None, sys.stdin.read)  # until the parent closes it
        for c in clients:
            await c.disconnect()

    asyncio.run(main())


def start_client(specs: list[str], interval_ms: float, out: Path) -> tuple[subprocess.Popen[str], Any]:
    f = open(out, "w")
    proc = subprocess.Popen([sys.executable, __file__, "--client", str(interval_ms), *specs], stdin=subprocess.PIPE,
                            stdout=f, stderr=subprocess.DEVNULL, text=True)
    deadline = time.monotonic() + 120
    while "ready" not in out.read_text():
        if time.monotonic() > deadline or proc.poll() is not None:
            raise RuntimeError("the benchmark's OPC UA client did not connect")
        time.sleep(0.1)
    return proc, f


def stop_client(proc: subprocess.Popen[str], f: Any) -> None:
    assert proc.stdin is not None
    proc.stdin.close()
    try:
        proc.wait(30)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(10)
    f.close()


# -- the bare asyncua server ----------------------------------------------------------

class BareServer:
    """asyncua alone: one Int32 variable, written on its own event loop and thread,
    handed a value as our server is (``call_soon_threadsafe``)."""

    def __init__(self, port: int) -> None:
        self.url = f"opc.tcp://127.0.0.1:{port}"
        self.ready = threading.Event()
        self.loop: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None
        self.thread = threading.Thread(target=lambda: asyncio.run(self._main()), name="bare-server", daemon=True)
        self.thread.start()
        if not self.ready.wait(120):
            raise RuntimeError("the bare asyncua server did not start")

    async def _main(self) -> None:
        from asyncua import Server, ua

        server = Server()
        await server.init()
        server.set_endpoint(self.url)
        server.set_security_policy([ua.SecurityPolicyType.NoSecurity])
        idx = await server.register_namespace(NAMESPACE_URI)
        var = await server.nodes.objects.add_variable(ua.NodeId("bare.State", idx), "State", 0, ua.VariantType.Int32)
        self.nodeid = var.nodeid
        self.server = server
        self.loop = asyncio.get_running_loop()
        self._stop = asyncio.Event()
        async with server:
            self.ready.set()
            await self._stop.wait()

    def write(self, value: int, wall_time_s: float) -> None:
        """From the loop's thread: the value, with its source timestamp, written on the server's loop."""
        from datetime import datetime

        from asyncua import ua

        async def write() -> None:
            now = datetime.now(UTC)
            await self.server.write_attribute_value(self.nodeid, ua.DataValue(
                ua.Variant(value, ua.VariantType.Int32), ua.StatusCode(0),
                datetime.fromtimestamp(wall_time_s, UTC), now))

        assert self.loop is not None
        self.loop.call_soon_threadsafe(lambda: asyncio.ensure_future(write()))

    def stop(self) -> None:
        assert self.loop is not None and self._stop is not None
        self.loop.call_soon_threadsafe(self._stop.set)
        self.thread.join(30)


# -- a null output for the fleet's baseline -------------------------------------------

@dataclasses.dataclass(frozen=True)
class NullOptions:
    pass


def null_kind() -> str:
    """An output kind that takes every snapshot and does nothing (registered here, for
    the baseline: the same loops and handovers but for what OPC UA does)."""
    from eskin_industrial.outputs.base import SINKS, OutputKind, Sink

    class NullSink(Sink):
        pass

    class NullKind(OutputKind[NullOptions]):
        name = "bench-null"
        Options = NullOptions

        @classmethod
        def _open_nodes(cls, options: Any, nodes: Any, context: Any) -> list[Sink]:
            return [NullSink() for _ in nodes]

    globals()["NullKind"] = NullKind
    SINKS["bench-null"] = f"{__name__}:NullKind"
    return "bench-null"


# -- a bridge of CAN nodes ------------------------------------------------------------

def bridge_config(n: int, rate: float, tag: str, outputs: dict[str, Any]) -> tuple[Any, Any, list[tuple[str, int]]]:
    from eskin_industrial.bridge.config import BridgeConfig, LogSettings, NodeConfig, resolve

    fd = rate > 500
    nodes, buses = [], []
    for i in range(n):
        channel, k = f"opcua-{os.getpid()}-{tag}-bus{i // 4}", i % 4
        nodes.append(NodeConfig.of(f"n{i + 1:02d}", str(PROFILE), "can", interface="virtual", channel=channel, fd=fd,
                                   rate_hz=rate, node_id=k + 1, base_id=0x200 + 0x10 * k))
        buses.append((channel, k))
    cfg = BridgeConfig(node=tuple(nodes), outputs=outputs, log=LogSettings(status_every_s=0))
    return cfg, resolve(cfg), buses


def free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


# -- latency --------------------------------------------------------------------------

def run_latency(rate: float, scene: Path, tmp: Path) -> dict[str, Any]:
    from eskin_industrial.bridge.logs import EventLog
    from eskin_industrial.bridge.runtime import Bridge
    from eskin_industrial.outputs.opcua.options import OpcuaOptions

    port = free_port()
    cfg, nodes, buses = bridge_config(1, rate, f"lat{int(rate)}", {"opcua": OpcuaOptions(
        endpoint=f"opc.tcp://127.0.0.1:{port}", offline_linger_s=0.0)})
    raw = raw_scans(nodes[0].profile, scene, rate)
    log = EventLog(open(os.devnull, "w"), "plain", "warning")
    br = Bridge(cfg, nodes, log).open()
    bare = BareServer(free_port())
    ours = br.runs[0].sinks[0]
    publish = ours.publish
    decisions: list[tuple[float, int]] = []
    last, flip = [-1], [False]

    def both(s: Any) -> None:
        if s.state is None or s.state == last[0]:
            publish(s)
            return
        last[0] = s.state
        decisions.append((s.wall_time_s, s.state))
        flip[0] = not flip[0]
        if flip[0]:
            bare.write(s.state, s.wall_time_s)
            publish(s)
        else:
            publish(s)
            bare.write(s.state, s.wall_time_s)

    ours.publish = both  # type: ignore[method-assign]
    out = tmp / f"client-{int(rate)}.txt"
    client, f = start_client([f"ours={ours.server.url}=ns={{ns}};s=n01.GraspState",
                              f"bare={bare.url}=ns={{ns}};s=bare.State"], 0, out)
    br.start()
    cpu0, t0 = thread_cpu_s(), time.monotonic()
    sims = start(make_nodes(nodes[0].profile, raw, rate, rate > 500, buses))
    for t, _ in sims:
        t.join()
    wall = time.monotonic() - t0
    cpu1 = thread_cpu_s()
    time.sleep(0.5)
    br.stop()
    log.close()
    stop_client(client, f)
    bare.stop()
    seen: dict[str, list[tuple[float, int]]] = {"ours": [], "bare": []}
    for line in out.read_text().splitlines():
        parts = line.split()
        if len(parts) == 3 and parts[0] in seen and parts[2] not in ("None",):
            seen[parts[0]].append((float(parts[1]), int(parts[2])))
    server_cpu = cpu1.get("opcua-server", 0.0) - cpu0.get("opcua-server", 0.0)
    return dict(rate=rate, decisions=len(decisions), ours=match(decisions, seen["ours"]),
                bare=match(decisions, seen["bare"]), server_cpu=server_cpu / wall)


def match(decisions: list[tuple[float, int]], seen: list[tuple[float, int]]) -> list[float]:
    """For each decision, the first notification of its value at or after its time."""
    out, j = [], 0
    for i, (t, state) in enumerate(decisions):
        until = decisions[i + 1][0] if i + 1 < len(decisions) else float("inf")
        while j < len(seen) and (seen[j][0] < t - 0.001 or seen[j][1] != state) and seen[j][0] < until:
            j += 1
        if j < len(seen) and seen[j][1] == state and seen[j][0] >= t - 0.001:
            out.append(seen[j][0] - t)
            j += 1
    return out


def thread_cpu_s() -> dict[str, float]:
    """CPU seconds of each thread of this process, by name, the OPC UA server's process
    (``opcua-server``, a process of its own) counted with the thread of that name."""
    import multiprocessing

    out = bridge_thread_cpu_s()
    tick = os.sysconf("SC_CLK_TCK")
    for child in multiprocessing.active_children():
        if child.name != "opcua-server":
            continue
        try:
            fields = Path(f"/proc/{child.pid}/stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        out["opcua-server"] = out.get("opcua-server", 0.0) + (int(fields[11]) + int(fields[12])) / tick
    return out


# -- the fleet ------------------------------------------------------------------------

def run_fleet_step(n: int, kind: str, scene: Path, duration_s: float, tmp: Path) -> dict[str, Any]:
    from eskin_industrial.bridge.logs import EventLog
    from eskin_industrial.bridge.runtime import Bridge
    from eskin_industrial.outputs.opcua.options import OpcuaOptions

    rate = 100.0
    tag = f"{kind}-{n}-{time.monotonic_ns()}"
    port = free_port()
    outputs = ({"opcua": OpcuaOptions(endpoint=f"opc.tcp://127.0.0.1:{port}", offline_linger_s=0.0)}
               if kind == "opcua" else {null_kind(): NullOptions()})
    cfg, nodes, buses = bridge_config(n, rate, tag, outputs)
    raw = raw_scans(nodes[0].profile, scene, rate)
    sims = make_nodes(nodes[0].profile, raw, rate, False, buses)
    log = EventLog(open(os.devnull, "w"), "plain", "warning")
    br = Bridge(cfg, nodes, log).open()
    client = None
    if kind == "opcua":
        ids = ",".join(f"ns={{ns}};s=n{i + 1:02d}.{v}" for i in range(n) for v in ("GraspState", "Slip", "TotalForce"))
        client = start_client([f"scada=opc.tcp://127.0.0.1:{port}={ids}"], 100, tmp / f"fleet-{tag}.txt")
    br.start()
    start(sims)
    time.sleep(1.0)  # the loops and the buses warm
    cpu0, t0 = thread_cpu_s(), time.monotonic()
    time.sleep(duration_s)
    cpu1, wall = thread_cpu_s(), time.monotonic() - t0
    for t, _ in sims:
        t.join(timeout=duration_s + 60)
    br.stop()
    log.close()
    if client is not None:
        stop_client(*client)
    counters = br.counters()
    ours = {k: cpu1.get(k, 0.0) - cpu0.get(k, 0.0) for k in cpu1}
    bridge = sum(v for k, v in ours.items() if not k.startswith("bench-node") and k != "MainThread") / wall
    lost = sum(c.get("lost_scans", 0) + c.get("rx_queue_drops", 0) for c in counters.values())
    return dict(n=n, kind=kind, cpu=bridge, server=ours.get("opcua-server", 0.0) / wall, lost=lost,
                scans=sum(c.get("scans", 0) for c in counters.values()),
                writes=sum(c.get("opcua_writes", 0) for c in list(counters.values())[:1]))


# -- report ---------------------------------------------------------------------------

def q(values: list[float], p: float) -> float:
    return float(np.percentile(values, p)) if values else float("nan")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", choices=["latency", "fleet", "storms"], default=None)
    ap.add_argument("--duration", type=float, default=75.0, help="Latency: seconds of slip train at each rate.")
    ap.add_argument("--rates", default="100,1000")
    ap.add_argument("--nodes", default="8,16", help="Fleet sizes at 100 Hz.")
    ap.add_argument("--fleet-duration", type=float, default=20.0)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--storm-s", type=float, default=8.0, help="Storms: seconds of each phase.")
    ap.add_argument("--client", nargs="+", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.client:
        client_main(args.client[1:], float(args.client[0]))
        return
    import logging

    logging.getLogger("asyncua").setLevel(logging.ERROR)
    print(f"# bench_opcua  {time.strftime('%Y-%m-%d')}  {describe()}")
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        if args.only in (None, "latency"):
            scene = tmp / "slip-train.toml"
            scene.write_text(slip_train_toml(args.duration))
            print("\n## deciding scan -> subscribed client's notification (ms)")
            print("| rate | decisions | ours p50 / p99 | bare asyncua p50 / p99 | ratio p50 / p99 | server thread |")
            print("|---|---|---|---|---|---|")
            for rate in (float(r) for r in args.rates.split(",")):
                r = run_latency(rate, scene, tmp)
                o, b = r["ours"], r["bare"]
                print(f"| {rate:g} Hz | {r['decisions']} ({len(o)}, {len(b)} matched) | {q(o, 50) * 1e3:.2f} / "
                      f"{q(o, 99) * 1e3:.2f} | {q(b, 50) * 1e3:.2f} / {q(b, 99) * 1e3:.2f} | "
                      f"{q(o, 50) / q(b, 50):.2f} / {q(o, 99) / q(b, 99):.2f} | {r['server_cpu'] * 100:.1f} % |",
                      flush=True)
        if args.only in (None, "fleet"):
            scene = tmp / "slip-train-fleet.toml"
            scene.write_text(slip_train_toml(args.fleet_duration + 3))
            print("\n## fleet at 100 Hz: the bridge's CPU (% of one core), with OPC UA and with a null output")
            print("| nodes | null | OPC UA | added | added per node | server thread | lost scans |")
            print("|---|---|---|---|---|---|---|")
            for n in (int(x) for x in args.nodes.split(",")):
                runs: dict[str, list[dict[str, Any]]] = {"bench-null": [], "opcua": []}
                for _ in range(args.repeats):
                    for kind in ("bench-null", "opcua"):
                        runs[kind].append(run_fleet_step(n, kind, scene, args.fleet_duration, tmp))
                null = float(np.median([r["cpu"] for r in runs["bench-null"]]))
                ours = float(np.median([r["cpu"] for r in runs["opcua"]]))
                server = float(np.median([r["server"] for r in runs["opcua"]]))
                lost = sum(r["lost"] for rs in runs.values() for r in rs)
                print(f"| {n} | {null * 100:.1f} | {ours * 100:.1f} | {(ours - null) * 100:.1f} | "
                      f"{(ours - null) / n * 100:.2f} | {server * 100:.1f} | {lost} |", flush=True)
        if args.only in (None, "storms"):
            print(f"\n## a well-behaved client's reads under connection storms ({args.storm_s:g} s a phase)")
            print_storms(run_storms(tmp, args.storm_s, PROFILE))


if __name__ == "__main__":
    main()
