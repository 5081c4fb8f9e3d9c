"""The node loop's cost per scan (``NodeLoop.step``: poll, calibrate, detect, image,
sinks), counted in instructions under valgrind's callgrind, which no load on the
machine changes; and what a sink that takes taxel frames adds.

    .venv/bin/python benchmarks/bench_loop.py               # every case (~2 min)
    .venv/bin/python benchmarks/bench_loop.py --cases none  # one case
    .venv/bin/python benchmarks/bench_loop.py --profile none  # where a scan's time goes (cProfile, no valgrind)
    .venv/bin/python benchmarks/bench_loop.py --cases publish --tree ../other   # another checkout's package
    .venv/bin/python benchmarks/bench_loop.py --gaps 0,1,10 --cases none  # the step's time, scans 0/1/10 ms apart
    .venv/bin/python benchmarks/bench_loop.py --gaps 10 --warm 0.5 --cases none  # a shadow step 0.5 ms before each

Cases (the paper-5x5 profile, its detector, scans from memory with no wait):
- ``none``: no sink at all: the loop as every command runs it.
- ``off``: one sink that asks for no frames (``frame_every_s`` None, what the
  Sparkplug output is with ``frame_interval_s = 0``).
- ``every``: one sink that takes every scan's frame (``frame_every_s = 0``) and does
  what the Sparkplug output does with it on the loop's thread: pack the forces as
  little-endian float32 and encode the DDATA (paho's publish left out): the cost of
  one frame, paid once per ``frame_interval_s`` in a real run.

- ``publish``: not a scan: one urgent publication (``NodeLoop.publish_if_due``: the
  snapshot, the PLC image's render, the client-mode writer's offer, which keeps it
  pending with no PLC connected): what a decision costs between its detection and
  the write's send.  ``--tree DIR`` imports the package of another checkout (this
  script's cases on it, the PLC writer where that tree has it).

Instructions per scan: the difference of two runs' totals (2,000 and 6,000 scans)
over their difference in scans, so that the interpreter's start-up and the imports
cancel out.  Run it from another checkout (``python OTHER/benchmarks/bench_loop.py``
imports OTHER's package) to compare two versions of the loop case by case.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from machine import describe  # noqa: E402

CASES = ("none", "off", "every", "publish")


def run_scans(case: str, scans: int, gap_s: float = 0.0, times: list[tuple[float, float]] | None = None,
              nodes: int = 1, spin: bool = False, warm_s: float | None = None) -> None:
    """``scans`` scans through one node's loop, for callgrind to count; with
    ``times``, each step's (wall, CPU) seconds appended, ``gap_s`` of sleep between
    rounds (``--gaps``; ``spin``: a busy wait instead), a round one scan of each of
    ``nodes`` loops in turn; ``warm_s``: a shadow loop of its own stepped that long
    before each round (its code shared, its state not), untimed."""
    import numpy as np

    import eskin_industrial
    from eskin_industrial.bridge.loop import NodeLoop
    from eskin_industrial.bus.source import Source
    from eskin_industrial.calibration import Calibrator
    from eskin_industrial.frames import Frame, RawScan
    from eskin_industrial.profile import load_profile
    from eskin_industrial.scenes import render

    try:
        from eskin_industrial.outputs.base import Sink
        from eskin_industrial.outputs.sparkplug import payload as pb
    except ImportError:  # a tree from before the outputs' move (--tree)
        from eskin_industrial.plant import payload as pb  # type: ignore[no-redef]
        from eskin_industrial.sinks.base import Sink  # type: ignore[no-redef]

    # the tree's own profile (a newer tree's may have keys an older one refuses)
    prof = load_profile(str(Path(eskin_industrial.__file__).parent / "data" / "profiles" / "paper-5x5.toml"))
    rec = render("case2", prof.sensor.rate_hz, 0)
    raw = np.rint(Calibrator.from_section(prof.calibration, prof.taxels).to_raw(rec.forces))

    class Memory(Source):
        """The scene's scans, one per poll, at once."""

        def __init__(self) -> None:
            super().__init__()
            self.k = 0

        def _poll(self, timeout_s: float | None) -> RawScan | None:
            k = self.k
            self.k += 1
            i = k % len(raw)
            return RawScan(k, k / prof.sensor.rate_hz, raw[i], 0, 0.0)

    class Frames(Sink):
        kind = "bench"

        def __init__(self, every_s: float | None) -> None:
            super().__init__()
            self.frame_every_s = every_s
            self.bytes = 0

        def on_frame(self, frame: Frame) -> None:
            data = frame.forces.astype("<f4").tobytes()
            metric = pb.Metric(None, 1050, None, pb.FLOAT_ARRAY, data)
            self.bytes += len(pb.encode(pb.Payload(1_700_000_000_000, (metric,), 7)))

    if case == "publish":
        try:
            from eskin_industrial.outputs.plc.client import PlcWriter
        except ImportError:  # a tree from before the outputs' move
            from eskin_industrial.plc.client import PlcWriter  # type: ignore[no-redef]
        loop = NodeLoop(prof, Memory(), [PlcWriter(prof.modbus.plc, "127.0.0.1", 1, poll_commands=False)])
        for _ in range(400):  # a detector's state to publish
            loop.step(0.0)
        publish = loop.publish_if_due
        for _ in range(scans):
            publish(True, 1.0)
        return
    sinks = [] if case == "none" else [Frames(None if case == "off" else 0.0)]
    loop = NodeLoop(prof, Memory(), sinks)
    step = loop.step
    if times is None:
        for _ in range(scans):
            step(0.0)
        return
    steps = [step] + [NodeLoop(prof, Memory(), []).step for _ in range(nodes - 1)]
    shadow = NodeLoop(prof, Memory(), []).step if warm_s is not None else None
    wall, cpu, sleep = time.perf_counter, time.thread_time, time.sleep
    for k in range(scans):
        if gap_s and k % nodes == 0:
            lead = 0.0 if warm_s is None else min(warm_s, gap_s)
            if spin:
                until = wall() + gap_s - lead
                while wall() < until:
                    pass
            else:
                sleep(gap_s - lead)
            if shadow is not None:
                shadow(0.0)
                if lead:
                    sleep(lead)
        w0, c0 = wall(), cpu()
        steps[k % nodes](0.0)
        times.append((wall() - w0, cpu() - c0))


def gaps(case: str, gaps_ms: list[float], scans: int, repeats: int, nodes: int = 1, spin: bool = False,
         warm_ms: float | None = None) -> None:
    """The step's wall and CPU time when the scans come ``gap`` ms apart, the thread
    asleep in between (as a bridge's between a 100 Hz node's scans), against the same
    steps back to back in the same run: what the instruction count cannot show, the
    caches and the branch predictors a sleeping thread finds cold again.  With
    ``nodes`` > 1, each round steps that many nodes' loops back to back (a reader
    serving its bus): their code is shared, their detectors' state is not.  ``spin``:
    the thread busy between the rounds instead of asleep.  ``warm_ms``: a shadow
    loop stepped that long before each round (does a warm-up just before a scan
    is due bring its step to the hot cost?)."""
    import numpy as np

    run_scans(case, 400, 0.0, [])  # imports and the detector's first calls out of the way
    runs: dict[float, list[tuple[float, float, float]]] = {g: [] for g in gaps_ms}
    for _ in range(repeats):
        for g in gaps_ms:  # alternately, so that the machine's moods fall on each alike
            times: list[tuple[float, float]] = []
            run_scans(case, scans, g / 1000.0, times, nodes, spin, None if warm_ms is None else warm_ms / 1000.0)
            arr = np.array(times[len(times) // 10:])  # the first tenth: the detector's warm-up
            runs[g].append((float(np.median(arr[:, 0])), float(np.percentile(arr[:, 0], 90)),
                            float(np.median(arr[:, 1]))))
    base = float(np.median([r[0] for r in runs[gaps_ms[0]]]))
    warmed = "" if warm_ms is None else f", a shadow step {warm_ms:g} ms before"
    print(f"| case | nodes a round | rounds apart, {'spinning' if spin else 'asleep'}{warmed} | step wall p50 (us) | p90 (us) | step CPU p50 (us) | wall p50 / at {gaps_ms[0]:g} ms |")
    print("|---|---|---|---|---|---|---|")
    for g in gaps_ms:
        p50, p90, c50 = (float(np.median([r[i] for r in runs[g]])) for i in range(3))
        print(f"| {case} | {nodes} | {g:g} ms | {p50 * 1e6:.0f} | {p90 * 1e6:.0f} | {c50 * 1e6:.0f} | {p50 / base:.2f}x |",
              flush=True)


def instructions_per_scan(case: str, tree: list[str]) -> float:
    # a fixed hash seed and no address randomisation, as bench_detector.py
    env = {**os.environ, "PYTHONHASHSEED": "0"}
    fixed = ["setarch", "-R"] if shutil.which("setarch") else []
    totals = []
    for scans in (2_000, 6_000):
        res = subprocess.run([*fixed, "valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null",
                              sys.executable, __file__, "--count", case, str(scans), *tree],
                             capture_output=True, text=True, check=True, env=env)
        totals.append(int(next(ln for ln in res.stderr.splitlines() if "Collected" in ln).split()[-1]))
    return (totals[1] - totals[0]) / 4_000


def profile(case: str, scans: int = 4_000, top: int = 20) -> None:
    """The loop's scans under cProfile: each module's own time and the functions that
    take most of it, as shares of the whole step (cProfile's overhead weighs every call
    alike: read the shares, not the microseconds)."""
    import cProfile
    import pstats

    run_scans(case, 200)  # imports and first calls out of the way
    prof = cProfile.Profile()
    prof.enable()
    run_scans(case, scans)
    prof.disable()
    stats = pstats.Stats(prof).stats  # type: ignore[attr-defined]
    rows = [(tt, nc, f"{Path(fn).name}:{ln}({name})", fn) for (fn, ln, name), (_, nc, tt, _, _) in stats.items()]
    total = sum(r[0] for r in rows)
    by_module: dict[str, float] = {}
    for tt, _, _, fn in rows:
        if "eskin_industrial/" in fn:
            key = fn.split("eskin_industrial/")[-1]
        else:
            key = "numpy" if "numpy" in fn else "C calls (numpy's ufuncs, min, max, ...)" if fn == "~" else Path(fn).name
        by_module[key] = by_module.get(key, 0.0) + tt
    print(f"# cProfile of {scans} scans, case {case}: {total / scans * 1e6:.0f} us a scan under the profiler")
    print("| module (own time) | share |")
    print("|---|---|")
    for key, tt in sorted(by_module.items(), key=lambda kv: -kv[1])[:top]:
        print(f"| {key} | {tt / total * 100:.1f} % |")
    print()
    print("| function (own time) | calls a scan | share |")
    print("|---|---|---|")
    for tt, nc, where, _ in sorted(rows, key=lambda r: -r[0])[:top]:
        print(f"| {where} | {nc / scans:.2f} | {tt / total * 100:.1f} % |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default=",".join(CASES), help=f"comma-separated, of {', '.join(CASES)}")
    ap.add_argument("--count", nargs=2, metavar=("CASE", "SCANS"), help=argparse.SUPPRESS)
    ap.add_argument("--profile", metavar="CASE", help="instead: where a scan's time goes in CASE, by cProfile")
    ap.add_argument("--gaps", metavar="MS,...", help="instead: the step's wall time with the scans MS apart "
                    "(the thread asleep between), against the first (0: back to back); medians of --repeats")
    ap.add_argument("--nodes", type=int, default=1, help="--gaps: nodes stepped back to back a round (default 1)")
    ap.add_argument("--spin", action="store_true", help="--gaps: a busy wait between the rounds instead of a sleep")
    ap.add_argument("--warm", type=float, metavar="MS", help="--gaps: a shadow loop (its own state, the code "
                    "shared) stepped MS before each round, untimed")
    ap.add_argument("--scans", type=int, default=1000, help="scans per --gaps run (default 1000)")
    ap.add_argument("--repeats", type=int, default=3, help="runs of each --gaps gap, alternately (default 3)")
    ap.add_argument("--tree", metavar="DIR", help="the package of this checkout instead of this script's")
    args = ap.parse_args()
    if args.tree:
        sys.path.insert(0, str(Path(args.tree).resolve()))
    if args.profile:
        print(f"# .venv/bin/python benchmarks/bench_loop.py --profile {args.profile}")
        print(f"# on {describe()}")
        profile(args.profile)
        return
    if args.gaps:
        print(f"# .venv/bin/python benchmarks/bench_loop.py --gaps {args.gaps} --cases {args.cases.split(',')[0]} "
              f"--nodes {args.nodes}" + (" --spin" if args.spin else "") + ("" if args.warm is None else f" --warm {args.warm:g}") + f" --scans {args.scans} --repeats {args.repeats}" + (f" --tree {args.tree}" if args.tree else ""))
        print(f"# {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())} on {describe()}, load average "
              f"{os.getloadavg()[0]:.1f}")
        gaps(args.cases.split(",")[0], [float(g) for g in args.gaps.split(",")], args.scans, args.repeats, args.nodes,
             args.spin, args.warm)
        return
    if args.count:
        run_scans(args.count[0], int(args.count[1]))
        return
    if shutil.which("valgrind") is None:
        ap.error("needs valgrind (Debian: apt-get install valgrind)")
    cases = args.cases.split(",")
    for c in cases:
        if c not in CASES:
            ap.error(f"--cases: {c!r} is not one of {', '.join(CASES)}")
    print(f"# .venv/bin/python benchmarks/bench_loop.py --cases {','.join(cases)}"
          + (f" --tree {args.tree}" if args.tree else ""))
    print(f"# on {describe()}")
    print("| case | instructions per scan |")
    print("|---|---|")
    for c in cases:
        print(f"| {c} | {instructions_per_scan(c, ['--tree', args.tree] if args.tree else []):,.0f} |", flush=True)


if __name__ == "__main__":
    main()
