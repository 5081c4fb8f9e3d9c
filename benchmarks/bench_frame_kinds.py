"""What one frame costs the detector, by what the frame does: cof-track's push and the
paper detector's, frame by frame, on a scene with slides.

    .venv/bin/python benchmarks/bench_frame_kinds.py               # 1 kHz, case6, three runs each
    .venv/bin/python benchmarks/bench_frame_kinds.py --rate 100    # 100 Hz (cof-track decides every frame)

The averages of ``bench_detector.py`` hide where a decision's time goes: most frames
only add to running sums, and the work of a hop comes at its last frame.  A frame that
changes the state is a hop's last frame, and may also be the torsion channel's hop
(40 ms) or the paper's indicators' hop (0.1 s, computed beside cof-track for R_COE and
R_DW).  This bench times each push on the clock (back to back, the caches warm: a
bridge at 100 Hz meets them cold, ``bench_loop.py --gaps``) and sorts the frames by
kind; the paper detector run the same way is the reference, as a ratio of medians.
The two hops are told by wrapping cof-track's own calls (nothing in the package is
timed for it).  The machine is shared: each figure is the median over the runs.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from machine import describe

from eskin_industrial.detect import PaperDetector
from eskin_industrial.detect.cof_track import CofTrack
from eskin_industrial.detect.settings import DetectorSettings
from eskin_industrial.evaluation.corpus import coordinates
from eskin_industrial.scenes import render


def _flagging(obj: Any, name: str, seen: list[bool]) -> None:
    """Wrap ``obj.name`` (an instance's call) so that a call sets ``seen[0]``."""
    inner = getattr(obj, name)

    def wrapped(*args: Any) -> Any:
        seen[0] = True
        return inner(*args)

    setattr(obj, name, wrapped)


def one_run(factory: Callable[..., Any], t: list[float], forces: np.ndarray, x: np.ndarray, y: np.ndarray,
            rate: float, settings: DetectorSettings) -> dict[str, list[float]]:
    """Each frame's push (us), by kind."""
    det = factory(settings, x, y, rate)
    turned, paper_hop = [False], [False]
    if isinstance(det, CofTrack):
        if det._turn is not None:
            _flagging(det._turn, "_hop", turned)
        _flagging(det.paper, "_hop", paper_hop)
    push, clock = det.push, time.perf_counter_ns
    kinds: dict[str, list[float]] = {}
    state = None
    for i in range(len(t)):
        f = forces[i]
        turned[0] = paper_hop[0] = False
        a = clock()
        out = push(t[i], f)
        b = clock()
        if not out:
            kind = "no update"
        else:
            new = out[-1].state
            kind = "state change" if state is not None and new != state else "update"
            state = new
            if paper_hop[0]:
                kind += ", the paper's hop"
            if turned[0]:
                kind += ", a torsion hop"
        kinds.setdefault(kind, []).append((b - a) / 1000)
    return kinds


def _pct(v: list[float], q: float) -> float:
    return float(np.percentile(v, q))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rate", type=float, default=1000.0, help="frame rate in Hz (default %(default)g)")
    ap.add_argument("--scene", default="case6", help="a built-in scene with slides (default %(default)s)")
    ap.add_argument("--runs", type=int, default=3, help="runs of each detector, alternately (default %(default)s)")
    args = ap.parse_args()
    rec = render(args.scene, args.rate, 0)
    x, y = coordinates(rec)
    t = rec.t.tolist()
    settings = DetectorSettings()
    runs: dict[str, list[dict[str, list[float]]]] = {"cof-track": [], "paper": []}
    for _ in range(args.runs):
        for name, factory in (("cof-track", CofTrack), ("paper", PaperDetector)):
            runs[name].append(one_run(factory, t, rec.forces, x, y, args.rate, settings))
    print(f"# {' '.join([os.path.basename(sys.executable), *sys.argv])}")
    print(f"# {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())} on {describe()}")
    print(f"# {args.scene} at {args.rate:g} Hz, seed 0: {len(t)} frames, {args.runs} runs each (the medians over "
          "them); each push timed back to back")
    print("| detector | frame | frames a run | p50 us | p90 us | p99 us | share of the detector's time |")
    print("|---|---|---|---|---|---|---|")
    p50s: dict[str, float] = {}
    for name, by_run in runs.items():
        whole = statistics.median(sum(sum(v) for v in r.values()) for r in by_run)
        for kind in sorted({k for r in by_run for k in r}, key=lambda k: (k != "no update", k)):
            got = [r[kind] for r in by_run if kind in r]
            p50, p90, p99 = (statistics.median(_pct(v, q) for v in got) for q in (50, 90, 99))
            share = statistics.median(sum(v) for v in got) / whole
            print(f"| {name} | {kind} | {statistics.median(len(v) for v in got):.0f} | {p50:.1f} | "
                  f"{p90:.1f} | {p99:.1f} | {100 * share:.1f} % |")
        every = [sum(r.values(), []) for r in by_run]
        p50s[name] = statistics.median(_pct(v, 50) for v in every)
    print(f"# every frame, p50: cof-track {p50s['cof-track']:.1f} us, the paper {p50s['paper']:.1f} us "
          f"({p50s['cof-track'] / p50s['paper']:.2f}x)")


if __name__ == "__main__":
    main()
