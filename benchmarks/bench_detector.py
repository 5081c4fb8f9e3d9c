"""Detector speed: streaming cost per frame, batch throughput, and the ratio to a naive
reference that recomputes every window from scratch (np.corrcoef + pywt.dwt).

    .venv/bin/python benchmarks/bench_detector.py                 # full run (about a minute)
    .venv/bin/python benchmarks/bench_detector.py --quick         # smoke run
    .venv/bin/python benchmarks/bench_detector.py --instructions  # + instruction counts (valgrind, ~1 min)
    .venv/bin/python benchmarks/bench_detector.py --quick --profile-shift  # cof-track with its profile channel
    .venv/bin/python benchmarks/bench_detector.py --rate 100      # at 100 Hz (cof-track decides every frame)

The machine is shared and noisy: every figure is the median of several repeats, and
cof-track's cost against the paper detector's is the median of paired runs.  With
``--instructions`` the two are also counted in instructions per frame under
valgrind's callgrind, which no load on the machine changes.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import time
from dataclasses import replace

import numpy as np
from machine import describe

from eskin_industrial.detect import PaperDetector, paper_batch
from eskin_industrial.detect.cof_track import CofTrack
from eskin_industrial.detect.reference import reference_window_sums
from eskin_industrial.detect.settings import DetectorSettings

RATE = 1000.0


def grid(rows: int, cols: int) -> tuple[np.ndarray, np.ndarray]:
    r, c = np.divmod(np.arange(rows * cols), cols)
    return c * 5.0, r * 5.0


def recording(k: int, n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    base = rng.uniform(0.1, 0.5, n)
    f = np.abs(base + 0.01 * rng.standard_normal((k, n)))
    f[k // 2:k // 2 + k // 20] = np.roll(f[k // 2:k // 2 + k // 20], 1, axis=1)  # some movement
    return np.arange(k) / RATE, f


def stream_us_per_frame(cfg: DetectorSettings, rows: int, cols: int, frames: int, repeats: int,
                        factory=PaperDetector) -> float:
    x, y = grid(rows, cols)
    t, f = recording(frames, rows * cols)
    runs = []
    for _ in range(repeats):
        det = factory(cfg, x, y, RATE)
        push = det.push
        tl = t.tolist()
        start = time.perf_counter()
        for i in range(frames):
            push(tl[i], f[i])
        runs.append((time.perf_counter() - start) / frames * 1e6)
    return statistics.median(runs)


def paired_ratio(cfg: DetectorSettings, frames: int, pairs: int) -> tuple[float, float, float]:
    """cof-track's cost over the paper detector's, from runs taken in alternation: a
    shared machine's speed drifts by tens of percent within a minute, and a ratio of
    two medians taken minutes apart carries that drift; each pair sees one state."""
    paper, ours, ratios = [], [], []
    for _ in range(pairs):
        p = stream_us_per_frame(cfg, 5, 5, frames, 1)
        o = stream_us_per_frame(cfg, 5, 5, frames, 1, factory=CofTrack)
        paper.append(p)
        ours.append(o)
        ratios.append(o / p)
    return statistics.median(paper), statistics.median(ours), statistics.median(ratios)


def batch_frames_per_s(cfg: DetectorSettings, frames: int, repeats: int) -> float:
    x, y = grid(5, 5)
    t, f = recording(frames, 25)
    runs = []
    for _ in range(repeats):
        start = time.perf_counter()
        paper_batch(cfg, x, y, RATE, t, f)
        runs.append(frames / (time.perf_counter() - start))
    return statistics.median(runs)


def reference_us_per_frame(cfg: DetectorSettings, frames: int) -> float:
    x, y = grid(5, 5)
    _, f = recording(frames, 25)
    start = time.perf_counter()
    reference_window_sums(cfg, x, y, RATE, f)
    return (time.perf_counter() - start) / frames * 1e6


def run_frames(method: str, frames: int) -> None:
    """Make ``frames`` frames and push them through one detector, or through none
    (method "none": what making them costs), for callgrind to count."""
    cfg = replace(DetectorSettings(), window_s=0.4, hop_s=0.1, lag_s=0.1)
    x, y = grid(5, 5)
    t, f = recording(frames, 25)
    if method == "none":
        return
    det = (CofTrack if method == "cof-track" else PaperDetector)(cfg, x, y, RATE)
    push = det.push
    for i, ti in enumerate(t.tolist()):
        push(ti, f[i])


def instructions_per_frame(method: str) -> float:
    """Instructions per frame: the difference of two runs' totals over their frame
    difference (the interpreter's start-up and imports cancel out), less the same
    difference for making the frames alone."""
    # a fixed hash seed and no address randomisation: what is left is about 2 % run to run
    env = {**os.environ, "PYTHONHASHSEED": "0"}
    fixed = ["setarch", "-R"] if shutil.which("setarch") else []

    def growth(name: str) -> int:
        totals = []
        for frames in (2_000, 6_000):
            res = subprocess.run([*fixed, "valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null",
                                  sys.executable, __file__, "--rate", str(RATE), "--count", name, str(frames)],
                                 capture_output=True, text=True, check=True, env=env)
            totals.append(int(next(ln for ln in res.stderr.splitlines() if "Collected" in ln).split()[-1]))
        return totals[1] - totals[0]

    return (growth(method) - growth("none")) / 4_000


def machine() -> str:
    return describe()


def main() -> None:
    global RATE
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer frames and repeats")
    ap.add_argument("--instructions", action="store_true", help="also count instructions per frame (valgrind)")
    ap.add_argument("--profile-shift", action="store_true",
                    help="cof-track with its profile channel on ([detector.cof_track] profile_shift)")
    ap.add_argument("--rate", type=float, default=RATE, help="frame rate in Hz (default %(default)g)")
    ap.add_argument("--count", nargs=2, metavar=("METHOD", "FRAMES"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    RATE = args.rate
    if args.count:
        run_frames(args.count[0], int(args.count[1]))
        return
    if args.instructions and shutil.which("valgrind") is None:
        ap.error("--instructions needs valgrind (Debian: apt-get install valgrind)")
    if args.instructions and args.profile_shift:
        ap.error("--profile-shift: the instruction counts run the default settings; leave out --instructions")
    cfg = replace(DetectorSettings(), window_s=0.4, hop_s=0.1, lag_s=0.1)
    if args.profile_shift:
        cfg = replace(cfg, cof_track=replace(cfg.cof_track, profile_shift=True))
    frames, repeats = (5_000, 3) if args.quick else (30_000, 5)
    batch_frames = 60_000 if args.quick else 600_000  # 10 minutes at 1 kHz
    ref_frames = 1_000 if args.quick else 3_000

    print(f"# {' '.join([os.path.basename(sys.executable), *sys.argv])}")
    print(f"# {time.strftime('%Y-%m-%d')} on {machine()}")
    print(f"# rate {RATE:g} Hz, window {cfg.window_s} s, hop {cfg.hop_s} s, lag {cfg.lag_s} s, {cfg.wavelet}")
    print("| case | figure | ours | naive reference | ratio |")
    print("|---|---|---|---|---|")
    ref = reference_us_per_frame(cfg, ref_frames)
    for name, rows, cols in (("5x5", 5, 5), ("4x5", 4, 5), ("16x16", 16, 16)):
        us = stream_us_per_frame(cfg, rows, cols, frames, repeats)
        ref_cell, ratio = (f"{ref:.1f} us/frame", f"{ref / us:.0f}x faster") if name == "5x5" else ("", "")
        print(f"| stream {name} | median cost per frame | {us:.1f} us ({1e6 / us:,.0f} frames/s) | {ref_cell} | {ratio} |")
    fps = batch_frames_per_s(cfg, batch_frames, max(1, repeats // 2))
    print(f"| batch 5x5, {batch_frames / RATE / 60:g} min at {RATE:g} Hz | frames per second | {fps:,.0f} | "
          f"{1e6 / ref:,.0f} | {fps / (1e6 / ref):,.0f}x faster |")
    paper_us, ours_us, ratio = paired_ratio(cfg, frames, 3 * repeats)
    print(f"| stream 5x5, cof-track (ours) against paper, same run | median cost per frame | {ours_us:.1f} us | "
          f"paper {paper_us:.1f} us | {ratio:.2f}x the paper's cost (median of {3 * repeats} paired runs) |")
    for window in (0.2, 0.8):
        us = stream_us_per_frame(replace(cfg, window_s=window), 5, 5, frames, repeats)
        print(f"| stream 5x5, window {window} s | median cost per frame | {us:.1f} us | | (independent of the window) |")
    if args.instructions:
        paper_i, ours_i = instructions_per_frame("paper"), instructions_per_frame("cof-track")
        print(f"| stream 5x5, cof-track (ours) against paper, callgrind | instructions per frame | {ours_i:,.0f} | "
              f"paper {paper_i:,.0f} | {ours_i / paper_i:.2f}x the paper's cost |")


if __name__ == "__main__":
    main()
