"""Sparkplug store-and-forward: what a data message costs the loop's thread when it
goes live and when it is held (broker away), and how fast an outage's held messages
go out once the broker is back, at Sparkplug's QoS 0 and at the opt-in QoS 1
(``nonconforming_qos1``), on a mosquitto of its own.

    .venv/bin/python benchmarks/bench_sparkplug_store.py                # 10000 messages
    .venv/bin/python benchmarks/bench_sparkplug_store.py --messages 2000 --store-dir /tmp/s

Each message is one publication of a register image whose state changed (a DDATA at
once, its metrics by alias), through :meth:`SparkplugDevice.publish`, the call the
bridge's loop makes.  "forward" is from the reconnect to the store's last row sent;
"confirmed" to the last one known at the broker (QoS 0: handed back to the node on its
own subscription; QoS 1: acknowledged).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from machine import describe

from eskin_industrial.node import NodeSnapshot
from eskin_industrial.outputs.sparkplug.kind import open_edge
from eskin_industrial.outputs.sparkplug.options import SparkplugOptions
from tests.helpers import sparkplug as spb
from tests.helpers.modbus import free_port
from tests.helpers.snapshots import made


def publication(i: int) -> NodeSnapshot:
    return made(state=i % 4, slip_events=i)


def timed(dev, pubs) -> list[float]:
    out = []
    for p in pubs:
        t0 = time.perf_counter()
        dev.publish(p)
        out.append(time.perf_counter() - t0)
    return out


def pct(xs: list[float], q: float) -> float:
    return sorted(xs)[min(len(xs) - 1, int(q * len(xs)))] * 1e6


def run(qos: int, n: int, tmp: Path, store_dir: str | None) -> dict[str, float]:
    port = free_port()
    edge = open_edge(SparkplugOptions(f"mqtt://127.0.0.1:{port}", "bench", f"q{qos}", nonconforming_qos1=qos == 1,
                                      store_max=n, store_dir=store_dir, reconnect_min_s=0.1, reconnect_max_s=0.1),
                     [("grip", {})])
    dev = edge.devices[0]
    pubs = [publication(i) for i in range(n)]
    edge.start()
    held = timed(dev, pubs)  # no broker yet: every message is held
    while edge.forwarder.rows < n:
        time.sleep(0.01)
    broker = spb.Broker(tmp, port)
    try:
        t0 = time.monotonic()
        while edge.forwarder.forwarded < n:
            time.sleep(0.001)
            if time.monotonic() - t0 > 120:
                raise SystemExit("forwarding did not finish within 120 s")
        forward_s = time.monotonic() - t0
        # until the broker has the last: acknowledged (QoS 1), or seen back (QoS 0)
        while (not all(info.is_published() for info, *_ in list(edge.inflight))) if qos else edge.inflight:
            time.sleep(0.001)
        acked_s = time.monotonic() - t0
        live = timed(dev, [publication(i) for i in range(n, n + min(n, 5000))])
    finally:
        edge.close()
        broker.kill()
    return {"held_p50": pct(held, 0.5), "held_p99": pct(held, 0.99), "live_p50": pct(live, 0.5),
            "live_p99": pct(live, 0.99), "forward_s": forward_s, "acked_s": acked_s,
            "rate": n / acked_s}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--messages", type=int, default=10000)
    ap.add_argument("--store-dir", default=None, help="the queue on disk here (default: a temporary folder)")
    args = ap.parse_args()
    print(f"# {describe()}")
    print(f"# {args.messages} messages held during an outage, then forwarded (reconnect included)")
    print("qos | publish held p50 / p99 (us) | publish live p50 / p99 (us) | handed to paho (s) | confirmed (s) "
          "| messages/s")
    with tempfile.TemporaryDirectory() as d:
        for qos in (0, 1):
            r = run(qos, args.messages, Path(d), args.store_dir or str(Path(d) / "store"))
            acked = f"{r['acked_s']:.2f}"
            print(f"{qos} | {r['held_p50']:.0f} / {r['held_p99']:.0f} | {r['live_p50']:.0f} / {r['live_p99']:.0f} | "
                  f"{r['forward_s']:.2f} | {acked} | {r['rate']:.0f}")


if __name__ == "__main__":
    main()
