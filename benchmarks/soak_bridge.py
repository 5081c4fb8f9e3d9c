"""The soak: the bridge at 1 kHz for an hour; memory flat, no drops, no missed slip.

    .venv/bin/python benchmarks/soak_bridge.py                        # 1 h at 1 kHz
    .venv/bin/python benchmarks/soak_bridge.py --duration 300         # a 5-minute check

The product's :class:`~eskin_industrial.bridge.runtime.Bridge` receives a CAN FD
node on python-can's virtual bus playing the benchmark "slip train" (a slide every
1.2 s) over and over, detects, and writes Modbus TCP on loopback into a PLC stand-in
in its own process (the one of ``bench_bridge.py``).  Every 10 s: resident memory
(VmRSS) and the counters.  At the end:

- memory: first, last and peak RSS after the warm-up minute, and the slope of a
  least-squares line through the samples (MB per hour);
- drops: queue drops, lost and torn scans, superseded PLC images (not a loss: the
  newer image replaced it), log lines dropped;
- slips: every slide of every lap must be flagged between its onset and 0.5 s after
  its end (missed), and no slip flag elsewhere (false);
- latency: arrival of the deciding scan -> the PLC's receipt, p50/p99/max over the
  whole run, and the bridge's CPU share.
Reference, in the same run: the memory of the process before the bridge started.
"""

from __future__ import annotations

import argparse
import collections
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_bridge import PROFILE, PlcCapture, latencies, slip_train_toml, start_can_node, thread_cpu_s  # noqa: E402
from machine import describe  # noqa: E402


def rss_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def slip_windows(labels: np.ndarray, t: np.ndarray, tail_s: float = 0.5) -> list[tuple[float, float]]:
    """(onset, end + tail) of every slip span in one lap."""
    slip = labels == "slip"
    edges = np.flatnonzero(np.diff(np.concatenate([[0], slip.astype(int), [0]])))
    return [(float(t[a]), float(t[b - 1]) + tail_s) for a, b in zip(edges[::2], edges[1::2])]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration", type=float, default=3600.0, help="seconds (default 3600)")
    ap.add_argument("--rate", type=float, default=1000.0, help="scan rate, Hz (default 1000)")
    ap.add_argument("--lap", type=float, default=60.0, help="seconds of scene per lap (default 60)")
    args = ap.parse_args()

    from eskin_industrial.bridge.config import BridgeConfig, LogSettings, NodeConfig, resolve
    from eskin_industrial.bridge.logs import EventLog
    from eskin_industrial.bridge.runtime import Bridge
    from eskin_industrial.modbus.pymodbus_io import quiet_pymodbus
    from eskin_industrial.outputs.plc.options import PlcOptions
    from eskin_industrial.scenes import render

    quiet_pymodbus()
    rate, fd = args.rate, args.rate > 500
    laps = int(np.ceil(args.duration / args.lap))
    print(f"# .venv/bin/python benchmarks/soak_bridge.py --duration {args.duration:g} --rate {rate:g}")
    print(f"# {time.strftime('%Y-%m-%d %H:%M', time.gmtime())} UTC on {describe()}", flush=True)
    tmp = tempfile.mkdtemp()
    scene = Path(tmp) / "slip-train.toml"
    scene.write_text(slip_train_toml(args.lap))
    rec = render(str(scene), rate, 0)
    lap_s = len(rec.t) / rate
    windows = slip_windows(rec.labels, rec.t)

    plc = PlcCapture()
    channel = f"soak-{os.getpid()}"
    node_cfg = NodeConfig.of("n1", str(PROFILE), "can", interface="virtual", channel=channel, fd=fd, rate_hz=rate)
    cfg = BridgeConfig(node=(node_cfg,), outputs={"plc": PlcOptions(mode="client", host="127.0.0.1", port=plc.port)},
                       log=LogSettings(status_every_s=0))
    nodes = resolve(cfg)
    slips: list[float] = []  # node time of every entry into slip
    decisions: list[tuple[int, int]] = []
    last = [-1]

    def on_update(_name, u) -> None:
        if u.state != last[0]:
            if last[0] != -1:
                decisions.append((int(round(u.t * rate)), int(u.state)))
            if u.state == 3:
                slips.append(u.t)
            last[0] = u.state

    log = EventLog(open(os.devnull, "w"), "plain", "warning")
    rss_before = rss_mb()
    br = Bridge(cfg, nodes, log, on_update=on_update).open()
    # Arrival times of the newest scans only (a dict of an hour of scans would be the
    # leak this soak looks for); decisions are matched against them as they happen.
    arrival: dict[int, float] = {}
    recent: collections.deque[int] = collections.deque()
    kept: dict[int, float] = {}
    source = br.runs[0].loop.source
    poll = source.poll

    def timed_poll(timeout_s=None):
        scan = poll(timeout_s)
        if scan is not None:
            k = int(round(scan.t * rate))
            arrival[k] = scan.rx_time
            recent.append(k)
            if len(recent) > 5000:
                arrival.pop(recent.popleft(), None)
            if decisions and decisions[-1][0] in arrival and decisions[-1][0] not in kept:
                kept[decisions[-1][0]] = arrival[decisions[-1][0]]
        return scan

    source.poll = timed_poll  # type: ignore[method-assign]
    node = start_can_node(nodes[0].profile, scene, rate, fd, "virtual", channel, repeat=laps)
    samples: list[tuple[float, float]] = []
    cpu0, t0 = thread_cpu_s(), time.monotonic()
    br.start()
    next_print = t0 + 300
    try:
        while node.is_alive() and time.monotonic() - t0 < args.duration:
            time.sleep(10.0)
            now = time.monotonic()
            samples.append((now - t0, rss_mb()))
            if now >= next_print:
                next_print += 300
                c = br.counters()["n1"]
                print(f"  {now - t0:6.0f} s  rss {samples[-1][1]:.1f} MB  scans {c['scans']}  slips {len(slips)}  "
                      f"drops {c.get('rx_queue_drops', 0)}  lost {c.get('lost_scans', 0)}", flush=True)
    finally:
        wall = time.monotonic() - t0
        cpu1 = thread_cpu_s()
        br.stop()
        log.close()
        writes = plc.finish()
    c = br.counters()["n1"]
    # Missed and false slips, lap by lap, on the node's clock.
    ran_s = c["scans"] / rate
    missed = expected = false = 0
    t_slips = np.asarray(slips)
    used = np.zeros(len(t_slips), bool)
    for lap in range(int(ran_s // lap_s) + 1):
        for lo, hi in windows:
            lo, hi = lo + lap * lap_s, hi + lap * lap_s
            hit = (t_slips >= lo) & (t_slips <= hi)
            used |= hit  # a flag in a slide's window is never false, counted or not
            if hi > ran_s - 0.5:
                continue  # the run ended inside this window: not counted either way
            expected += 1
            missed += not hit.any()
    false = int((~used & (t_slips < ran_s - 1.0)).sum())
    lat_all, lat_slip, skipped = latencies(decisions, kept, writes)
    warm = [m for s, m in samples if s >= 60.0] or [m for _, m in samples]
    ts = np.array([s for s, _ in samples if s >= 60.0] or [s for s, _ in samples])
    slope = float(np.polyfit(ts / 3600.0, np.asarray(warm), 1)[0]) if len(warm) > 2 else float("nan")
    bridge_cpu = sum(cpu1.get(k, 0.0) - cpu0.get(k, 0.0) for k in cpu1 if k not in ("bench-node", "MainThread"))
    print(f"ran {wall:.0f} s, {c['scans']} scans at {rate:g} Hz (CAN FD on the virtual bus), {laps} laps of {lap_s:.0f} s")
    print(f"memory: before the bridge {rss_before:.1f} MB; after warm-up {warm[0]:.1f} MB, end {warm[-1]:.1f} MB, "
          f"peak {max(warm):.1f} MB, slope {slope:+.2f} MB/h")
    print(f"drops: rx queue {c.get('rx_queue_drops', 0)}, lost scans {c.get('lost_scans', 0)}, torn "
          f"{c.get('torn_scans', 0)}, malformed {c.get('malformed_frames', 0)}, log lines {log.drops}; "
          f"PLC writes {c.get('plc_writes', 0)}, failed {c.get('plc_write_failures', 0)}, superseded "
          f"{c.get('plc_superseded', 0)}")
    print(f"slips: {expected} expected, {expected - missed} found, {missed} missed, {false} false")
    if lat_all:
        a = np.asarray(lat_all) * 1000
        print(f"latency (arrival -> PLC receipt): p50 {np.percentile(a, 50):.2f} ms, p99 {np.percentile(a, 99):.2f} ms, "
              f"max {a.max():.1f} ms over {a.size} state changes ({len(lat_slip)} slips, {skipped} not matched)")
    print(f"bridge CPU {bridge_cpu / wall * 100:.1f} % of one core")


if __name__ == "__main__":
    main()
