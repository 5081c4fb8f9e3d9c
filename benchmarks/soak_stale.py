"""The stale limit under load: a healthy sensor is not flagged, a silent one is.

    .venv/bin/python benchmarks/soak_stale.py                      # 120 s, 2 spinning processes + a GIL hog
    .venv/bin/python benchmarks/soak_stale.py --duration 600 --load 4

Two loops of the product (:class:`~eskin_industrial.bridge.loop.NodeLoop`) run side by
side in one process on the same load, each on a 100 Hz sensor (the paper-5x5 profile,
a still hold played in real time by a source thread of its own, as a CAN reader
delivers scans): the learnt limit (``[output] stale_max_s`` default, 4 x stale_s) and,
as the reference in the same run, the fixed one (``stale_max_s = stale_s``, as before).
The load: ``--load`` processes spinning on the CPU (a loaded 2-core host) and a thread
in the bridge's own process that takes the interpreter for bursts of 20-120 ms (as a
flood of Sparkplug commands decoded by paho's thread does).  Every 5 s the sensor falls
silent for 1 s.  Reported, for each limit:

- healthy: SENSOR_STALE episodes that began while the sensor was sending, per minute;
- silent: the time from the last scan to the first stale publication, p50 / max;
- the ratio of the two limits' healthy episodes (learnt / fixed).
"""

from __future__ import annotations

import argparse
import multiprocessing
import queue
import sys
import threading
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from machine import describe  # noqa: E402

from eskin_industrial.bridge.loop import NodeLoop  # noqa: E402
from eskin_industrial.bus.source import Source  # noqa: E402
from eskin_industrial.calibration import Calibrator  # noqa: E402
from eskin_industrial.frames import RawScan  # noqa: E402
from eskin_industrial.node import NodeSnapshot  # noqa: E402
from eskin_industrial.outputs.base import Sink  # noqa: E402
from eskin_industrial.profile import Profile, load_profile  # noqa: E402
from eskin_industrial.scenes import render  # noqa: E402

RATE_HZ = 100.0
PERIOD_S = 5.0  # a silence every PERIOD_S ...
SILENT_S = 1.0  # ... this long


class Sender(Source[None]):
    """A sensor thread sending at 100 Hz into a queue (a CAN reader's), silent for
    SILENT_S every PERIOD_S; the loop polls the queue."""

    kind = "sender"

    def __init__(self, raw: np.ndarray, stop: threading.Event) -> None:
        super().__init__()
        self.raw, self.stop = raw, stop
        self.q: queue.SimpleQueue[RawScan] = queue.SimpleQueue()
        self.silences: list[tuple[float, float]] = []  #: (last scan, first scan after)
        self.thread = threading.Thread(target=self._send, daemon=True)

    def start(self) -> Sender:
        self.thread.start()
        return self

    def _send(self) -> None:
        t0 = time.monotonic()
        k, last = 0, 0.0
        silent_from = None
        while not self.stop.is_set():
            due = t0 + k / RATE_HZ
            wait = due - time.monotonic()
            if wait > 0:
                time.sleep(wait)
            now = time.monotonic()
            phase = (due - t0) % PERIOD_S
            if phase >= PERIOD_S - SILENT_S:
                silent_from = silent_from or last
            else:
                if silent_from is not None:
                    self.silences.append((silent_from, now))
                    silent_from = None
                self.q.put(RawScan(k, k / RATE_HZ, self.raw[k % len(self.raw)], 0, now))
                last = now
            k += 1

    @property
    def pending(self) -> bool:
        return not self.q.empty()

    def _poll(self, timeout_s: float | None) -> RawScan | None:
        try:
            return self.q.get(timeout=timeout_s if timeout_s is not None else 0.05)
        except queue.Empty:
            return None


class Keep(Sink):
    kind = "keep"

    def __init__(self) -> None:
        super().__init__()
        self.seen: list[tuple[float, bool]] = []

    def _publish(self, snapshot: NodeSnapshot) -> None:
        self.seen.append((time.monotonic(), snapshot.stale))


def spin(until: float) -> None:
    while time.monotonic() < until:
        pass


def hog(stop: threading.Event, rng: np.random.Generator) -> None:
    """Take the interpreter for 20-120 ms bursts, a few times a second."""
    while not stop.is_set():
        end = time.monotonic() + float(rng.uniform(0.02, 0.12))
        x = 0
        while time.monotonic() < end:
            x += 1
        time.sleep(float(rng.uniform(0.1, 0.4)))


def run_loop(loop: NodeLoop, stop: threading.Event) -> None:
    while not stop.is_set():
        loop.step()


def judge(keep: Keep, silences: list[tuple[float, float]], start: float, end: float) -> tuple[float, list[float]]:
    """(healthy stale episodes per minute, silence -> stale times)."""
    onsets = [t for (t, s), (_, before) in zip(keep.seen[1:], keep.seen) if s and not before and start <= t <= end]
    in_silence = [any(a < t <= b for a, b in silences) for t in onsets]
    healthy = sum(not x for x in in_silence)
    detect = []
    for a, b in silences:
        if a < start or b > end:
            continue
        first = next((t for t, s in keep.seen if a < t <= b and s), None)
        if first is not None:
            detect.append(first - a)
    return healthy / ((end - start) / 60.0), detect


def loops(profile: Profile, raw: np.ndarray, stop: threading.Event) -> list[tuple[str, NodeLoop, Keep, Sender]]:
    fixed = replace(profile, output=replace(profile.output, stale_max_s=profile.stale_s))
    out = []
    for name, prof in (("learnt", profile), ("fixed", fixed)):
        keep, src = Keep(), Sender(raw, stop)
        out.append((name, NodeLoop(prof, src, [keep]), keep, src))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration", type=float, default=120.0)
    ap.add_argument("--load", type=int, default=2, help="processes spinning on the CPU")
    ap.add_argument("--no-hog", action="store_true", help="no GIL hog in the bridge's process")
    args = ap.parse_args()
    print(f"# {' '.join(['benchmarks/soak_stale.py', *sys.argv[1:]])}")
    print(f"# {describe()}")
    profile = load_profile(ROOT / "profiles" / "paper-5x5.toml")
    rec = render("hold", RATE_HZ, 0)
    raw = np.rint(Calibrator.from_section(profile.calibration, profile.taxels).to_raw(rec.forces))
    stop = threading.Event()
    ctx = multiprocessing.get_context("spawn")
    t_end = time.monotonic() + args.duration + 2.0
    spinners = [ctx.Process(target=spin, args=(t_end,), daemon=True) for _ in range(args.load)]
    for p in spinners:
        p.start()
    runs = loops(profile, raw, stop)
    threads = []
    for _, loop, _, src in runs:
        src.start()
        threads.append(threading.Thread(target=run_loop, args=(loop, stop), daemon=True))
    if not args.no_hog:
        threads.append(threading.Thread(target=hog, args=(stop, np.random.default_rng(0)), daemon=True))
    for t in threads:
        t.start()
    start = time.monotonic() + 5.0  # the warm-up (the detector's, the limit's first gaps)
    time.sleep(args.duration)
    end = time.monotonic()
    stop.set()
    for t in threads:
        t.join(timeout=2.0)
    for p in spinners:
        p.join(timeout=5.0)
    print(f"# stale_s {profile.stale_s * 1000:.0f} ms, stale_max_s {profile.stale_max_s * 1000:.0f} ms; "
          f"load: {args.load} spinning processes{'' if args.no_hog else ' + a GIL hog (20-120 ms bursts)'}")
    print("| limit | healthy: stale episodes per minute | silent: flagged after p50 / max (ms) | silences |")
    print("|---|---|---|---|")
    per_min = {}
    for name, loop, keep, src in runs:
        rate, detect = judge(keep, src.silences, start, end)
        per_min[name] = rate
        d = np.asarray(detect) * 1000.0
        shown = f"{np.median(d):.0f} / {d.max():.0f}" if d.size else "- / -"
        print(f"| {name} (final limit {loop.status.stale_s * 1000:.0f} ms) | {rate:.2f} | {shown} | {d.size} |")
    ratio = per_min["learnt"] / per_min["fixed"] if per_min["fixed"] else float("nan")
    print(f"# healthy stale episodes, learnt / fixed: {ratio:.2f}")


if __name__ == "__main__":
    main()
