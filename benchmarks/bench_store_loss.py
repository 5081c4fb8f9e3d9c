"""What store-and-forward guarantees at the host, with and without a primary host: a
mosquitto of its own restarted every 2 s (killed, started again on its port, nothing
persisted), a Sparkplug host application that reconnects 1 s after each restart,
and an edge node publishing a data message every 10 ms throughout.

    .venv/bin/python benchmarks/bench_store_loss.py            # 20 s per case
    .venv/bin/python benchmarks/bench_store_loss.py --quick    # 8 s per case

Each message is one publication whose state changed (a DDATA at once), known at the
host by its ``Counters/Slip Events`` value.  "published" counts the publications the
node took (live or held), "received" the distinct ones the host got (live or
historical), "lost" the rest.  The node's own counters (held, forwarded, overflow)
show what it lost itself: its guarantee ends at the broker.  Without a primary host
the node publishes as soon as it has a session: what it sends before the host is
back, the history of the outage first, reaches no one.  With one, the node waits for
the host's STATE before its births and holds its data meanwhile.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import paho.mqtt.client as mqtt
from machine import describe

from eskin_industrial.node import NodeSnapshot
from eskin_industrial.outputs.sparkplug.kind import open_edge
from eskin_industrial.outputs.sparkplug.metrics import DEVICE_METRICS
from eskin_industrial.outputs.sparkplug.options import SparkplugOptions
from tests.helpers import sparkplug as spb
from tests.helpers.modbus import free_port
from tests.helpers.snapshots import made

RESTART_EVERY_S = 2.0
HOST_BACK_AFTER_S = 1.0
EVERY_S = 0.01
SLIP_EVENTS = 1000 + next(i for i, m in enumerate(DEVICE_METRICS) if m.name == "Counters/Slip Events")
HOST_ID = "scada"


def publication(i: int) -> NodeSnapshot:
    return made(state=i % 4, slip_events=i)


class Host:
    """A Sparkplug host application (paho): subscribes to the group, and as the primary
    host publishes its STATE (online, retained, its will offline) once subscribed;
    back 1 s after each loss of its broker (paho's reconnect delay)."""

    def __init__(self, port: int, primary: bool) -> None:
        self.live: set[int] = set()
        self.historical: set[int] = set()
        self.primary = primary
        self._lock = threading.Lock()
        self.c = mqtt.Client(callback_api_version=mqtt.CallbackAPIVersion.VERSION2, client_id="bench-host",
                             clean_session=True)
        self.c.reconnect_delay_set(HOST_BACK_AFTER_S, HOST_BACK_AFTER_S)
        if primary:
            self.c.will_set(f"spBv1.0/STATE/{HOST_ID}", self._state(False), qos=1, retain=True)
        self.c.on_connect = self._on_connect
        self.c.on_message = self._on_message
        self.subscribed = threading.Event()
        self.c.on_subscribe = lambda *a: self.subscribed.set()
        self.c.connect("127.0.0.1", port, keepalive=5)
        self.c.loop_start()

    @staticmethod
    def _state(online: bool) -> str:
        return json.dumps({"online": online, "timestamp": int(time.time() * 1000)})

    def _on_connect(self, client: Any, userdata: Any, flags: Any, reason: Any, props: Any) -> None:
        client.subscribe("spBv1.0/bench/#", qos=0)
        if self.primary:  # (after the subscription: in order on one connection)
            client.publish(f"spBv1.0/STATE/{HOST_ID}", self._state(True), qos=1, retain=True)

    def _on_message(self, client: Any, userdata: Any, msg: Any) -> None:
        if "/DDATA/" not in msg.topic:
            return
        p = spb.parse(msg.payload)
        for m in p.metrics:
            if m.alias == SLIP_EVENTS:
                with self._lock:
                    (self.historical if m.is_historical else self.live).add(int(spb.value(m)))

    def received(self) -> tuple[set[int], set[int]]:
        with self._lock:
            return set(self.live), set(self.historical)

    def close(self) -> None:
        self.c.loop_stop()
        self.c.disconnect()


def run(primary: bool, seconds: float, tmp: Path) -> dict[str, int]:
    port = free_port()
    broker = spb.Broker(tmp, port)
    host = Host(port, primary)
    host.subscribed.wait(5)
    edge = open_edge(SparkplugOptions(f"mqtt://127.0.0.1:{port}", "bench", "e", store_dir=str(tmp / "store"),
                                      reconnect_min_s=0.1, reconnect_max_s=0.1,
                                      primary_host_id=HOST_ID if primary else None), [("grip", {})])
    dev = edge.devices[0]
    try:
        edge.start()
        if not edge.wait_connected(10):
            raise SystemExit("the edge node did not come up within 10 s")
        n = 0
        t0 = time.monotonic()
        next_restart = t0 + RESTART_EVERY_S
        while time.monotonic() - t0 < seconds:
            dev.publish(publication(n))
            n += 1
            if time.monotonic() >= next_restart:
                broker.kill()
                broker = spb.Broker(tmp, port)
                next_restart += RESTART_EVERY_S
            time.sleep(EVERY_S)
        # the broker stays up: until the node has sent what it holds and the host has it all
        deadline = time.monotonic() + 15
        while time.monotonic() < deadline:
            live, hist = host.received()
            if edge.forwarder.pending == 0 and edge.connected and len(live | hist) >= n:
                break
            time.sleep(0.1)
        time.sleep(1.0)  # the last in flight
        live, hist = host.received()
        f = edge.forwarder
        held, forwarded, overflow = f.held, f.forwarded, f.overflow
    finally:
        edge.close()
        host.close()
        broker.kill()
    got = live | hist
    return {"published": n, "received": len(got & set(range(n))), "lost": n - len(got & set(range(n))),
            "held": held, "forwarded": forwarded, "overflow": overflow, "historical_received": len(hist),
            "historical_lost": forwarded - len(hist)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=20.0, help="publishing time per case (default 20)")
    ap.add_argument("--quick", action="store_true", help="8 s per case")
    args = ap.parse_args()
    seconds = 8.0 if args.quick else args.seconds
    cmd = "benchmarks/bench_store_loss.py" + (" --quick" if args.quick else f" --seconds {seconds:g}")
    print(f"# {describe()}")
    print(f"# {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}: .venv/bin/python {cmd}")
    print(f"# broker restarted every {RESTART_EVERY_S:g} s, host back {HOST_BACK_AFTER_S:g} s after each, "
          f"a message every {EVERY_S * 1000:g} ms for {seconds:g} s")
    print("case | published | received | lost | node: held / forwarded / overflow | historical received / lost")
    with tempfile.TemporaryDirectory() as d:
        for primary in (False, True):
            tmp = Path(d) / ("primary" if primary else "none")
            tmp.mkdir()
            r = run(primary, seconds, tmp)
            case = "primary host" if primary else "no primary host"
            print(f"{case} | {r['published']} | {r['received']} | {r['lost']} | {r['held']} / {r['forwarded']} / "
                  f"{r['overflow']} | {r['historical_received']} / {r['historical_lost']}")


if __name__ == "__main__":
    main()
