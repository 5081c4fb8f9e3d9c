"""The detector compiled by mypyc, against the same code interpreted, in one run:
what "compiled code" buys the bridge as the code stands, before any rewrite for it.

    .venv/bin/python benchmarks/bench_compiled.py            # build, check, time (about 4 minutes)
    .venv/bin/python benchmarks/bench_compiled.py --fleet 24,40 --fleet-1k 4,6   # and the fleet's CPU

A copy of this checkout's package is made in a temporary directory, with the modules
of ``detect/`` but :data:`INTERPRETED` compiled to C extensions by mypyc (the test
extra's mypy; gcc and the interpreter's headers).  Then, each in a process of its own
importing one tree or the other:

- **the same updates**: every method's updates on seeded scenes, compared field by
  field, exactly (a compiled build that decided otherwise would be no build to time);
- **a frame**: cof-track's push per frame on case6 at 100 Hz and 1 kHz (the medians
  of the trees' runs, taken alternately), and the ratio;
- **a scan**: ``bench_loop.py --gaps 0,10 --tree``: the loop's step hot (scans back to
  back) and as a lone 100 Hz node meets it (10 ms apart, the caches gone cold);
- ``--fleet N,...``: ``bench_fleet.py``'s bridge CPU at those counts of 100 Hz nodes
  (``--fleet-1k`` at 1 kHz), run from each tree's root, alternately.

Nothing is installed; the copy is removed at the end (``--keep DIR`` builds it there
and keeps it).  The package itself ships interpreted: this measures a lever, it does
not pull it.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from machine import describe  # noqa: E402

#: Modules of ``detect/`` left interpreted: the settings (their schema is read from
#: the dataclass's field types at run time, which a compiled class does not keep as
#: types), the method registry and the detector's protocol (no per-frame work).
INTERPRETED = ("__init__.py", "settings.py", "methods.py", "protocol.py")
#: Scenes and seeds of the updates' check (each method at the profile's rate and 1 kHz).
CHECK_SCENES = (("case2", 0), ("case6", 0), ("case6", 1))
CHECK_METHODS = ("cof-track", "paper", "learned")
MYPY_INI = "[mypy]\npython_version = 3.11\nignore_missing_imports = True\n"


def build(dest: Path) -> float:
    """The package copied into ``dest`` and its detector compiled there; seconds taken."""
    shutil.copytree(ROOT / "eskin_industrial", dest / "eskin_industrial",
                    ignore=shutil.ignore_patterns("__pycache__", "*.so"))
    shutil.copytree(ROOT / "benchmarks", dest / "benchmarks", ignore=shutil.ignore_patterns("__pycache__"))
    # (the fleet's bench reads the profiles and the tests' helpers from its own root)
    shutil.copytree(ROOT / "profiles", dest / "profiles")
    shutil.copytree(ROOT / "tests", dest / "tests", ignore=shutil.ignore_patterns("__pycache__", "node_modules"))
    (dest / "mypy.ini").write_text(MYPY_INI)  # (no pyproject.toml there: mypyc's setup would read it)
    modules = sorted(str(p.relative_to(dest)) for p in (dest / "eskin_industrial" / "detect").glob("*.py")
                     if p.name not in INTERPRETED)
    t0 = time.monotonic()
    done = subprocess.run([sys.executable, "-m", "mypyc", *modules], cwd=dest, capture_output=True, text=True)
    if done.returncode != 0:
        tail = (done.stdout + done.stderr).strip().splitlines()[-15:]
        raise SystemExit("bench_compiled: mypyc failed:\n" + "\n".join(tail))
    built = list((dest / "eskin_industrial" / "detect").glob("*.so"))
    if len(built) != len(modules):
        raise SystemExit(f"bench_compiled: {len(built)} extensions built for {len(modules)} modules")
    return time.monotonic() - t0


# -- the work done in a tree's own process -------------------------------------------
def _worker(tree: str, task: str, arg: str) -> None:
    sys.path.insert(0, tree)
    from eskin_industrial import detect
    from eskin_industrial.methods import ready_method
    from eskin_industrial.profile import load_profile
    from eskin_industrial.scenes import render

    prof = load_profile(str(Path(tree) / "eskin_industrial" / "data" / "profiles" / "paper-5x5.toml"))
    x, y = prof.coordinates_mm
    compiled = any(Path(detect.__file__).parent.glob("*.so"))
    if task == "updates":
        out = []
        for rate in (prof.sensor.rate_hz, 1000.0):
            for scene, seed in CHECK_SCENES:
                rec = render(scene, rate, seed)
                for method in CHECK_METHODS:
                    det = ready_method(method, prof.detector, None).stream(prof.detector, x, y, rate)
                    ups = det.feed(rec.t, rec.forces)
                    out.append([f"{scene}/{seed} {method} {rate:g} Hz",
                                [[float(v) if isinstance(v, float) else int(v) for v in u] for u in ups]])
        print(json.dumps({"compiled": compiled, "runs": out}))
    elif task == "frame":
        rate = float(arg)
        rec = render("case6", rate, 0)
        runs = []
        for _ in range(3):
            det = ready_method("cof-track", prof.detector, None).stream(prof.detector, x, y, rate)
            push, ts, fs = det.push, rec.t.tolist(), list(rec.forces)
            t0 = time.perf_counter()
            for t, f in zip(ts, fs):
                push(t, f, 0)
            runs.append((time.perf_counter() - t0) / len(ts) * 1e6)
        print(json.dumps({"compiled": compiled, "us": statistics.median(runs)}))


def in_tree(tree: Path, task: str, arg: str = "") -> dict:
    done = subprocess.run([sys.executable, __file__, "--worker", str(tree), task, arg], capture_output=True,
                          text=True, env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})
    if done.returncode != 0:
        raise SystemExit(f"bench_compiled: {task} in {tree} failed:\n{done.stderr.strip()[-2000:]}")
    return json.loads(done.stdout)


def check_updates(trees: dict[str, Path]) -> None:
    got = {name: in_tree(tree, "updates") for name, tree in trees.items()}
    if got["interpreted"]["compiled"] or not got["compiled"]["compiled"]:
        raise SystemExit("bench_compiled: the trees did not import as built (a compiled module where none "
                         "should be, or none where they should)")
    n = 0
    for (label, a), (_, b) in zip(got["interpreted"]["runs"], got["compiled"]["runs"]):
        if a != b:
            at = next((i for i, (u, v) in enumerate(zip(a, b)) if u != v), min(len(a), len(b)))
            raise SystemExit(f"bench_compiled: {label}: the compiled detector's update {at} differs: "
                             f"{a[at] if at < len(a) else None} against {b[at] if at < len(b) else None}")
        n += len(a)
    print(f"# the same updates: {n} updates of {len(got['compiled']['runs'])} runs equal field by field "
          f"({', '.join(CHECK_METHODS)}; {', '.join(f'{s}/{k}' for s, k in CHECK_SCENES)}; the profile's "
          "rate and 1 kHz)")


def time_frames(trees: dict[str, Path], rounds: int) -> None:
    print("| detector's frame (cof-track, case6) | interpreted us | compiled us | compiled / interpreted |")
    print("|---|---|---|---|")
    for rate in ("100", "1000"):
        us: dict[str, list[float]] = {name: [] for name in trees}
        for _ in range(rounds):
            for name, tree in trees.items():
                us[name].append(in_tree(tree, "frame", rate)["us"])
        a, b = statistics.median(us["interpreted"]), statistics.median(us["compiled"])
        print(f"| {rate} Hz | {a:.1f} | {b:.1f} | {b / a:.2f}x |")


def time_steps(trees: dict[str, Path], rounds: int) -> None:
    rows: dict[tuple[str, str], list[float]] = {}
    for _ in range(rounds):
        for name, tree in trees.items():
            done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_loop.py"), "--gaps", "0,10",
                                   "--cases", "none", "--scans", "600", "--repeats", "1", "--tree", str(tree)],
                                  capture_output=True, text=True, env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})
            if done.returncode != 0:
                raise SystemExit(f"bench_compiled: bench_loop.py --tree {tree} failed:\n{done.stderr[-2000:]}")
            for line in done.stdout.splitlines():
                cells = [c.strip() for c in line.strip("|").split("|")]
                if len(cells) == 7 and cells[0] == "none":
                    rows.setdefault((name, cells[2]), []).append(float(cells[3]))
    print("| the loop's step (bench_loop.py --gaps) | interpreted us | compiled us | compiled / interpreted |")
    print("|---|---|---|---|")
    for gap, what in (("0 ms", "hot: scans back to back"), ("10 ms", "a lone 100 Hz node: 10 ms apart")):
        a, b = statistics.median(rows[("interpreted", gap)]), statistics.median(rows[("compiled", gap)])
        print(f"| {what} | {a:.0f} | {b:.0f} | {b / a:.2f}x |")


def time_fleet(trees: dict[str, Path], nodes_100: str, nodes_1k: str, rounds: int, duration: float) -> None:
    cpu: dict[tuple[str, str, str], list[float]] = {}
    stale: dict[tuple[str, str, str], list[int]] = {}  # (the stale marks of each run, as bench_fleet counts them)
    for _ in range(rounds):
        for name, tree in trees.items():
            done = subprocess.run([sys.executable, str(tree / "benchmarks" / "bench_fleet.py"), "--only", "fleet",
                                   "--nodes-100", nodes_100, "--nodes-1k", nodes_1k, "--per-bus", "4", "--duration",
                                   f"{duration:g}", "--go-on", "--sender-procs", "4", "--pin"],
                                  capture_output=True, text=True, cwd=tree)
            if done.returncode != 0:
                raise SystemExit(f"bench_compiled: bench_fleet.py in {tree} failed:\n{done.stderr[-2000:]}")
            for line in done.stdout.splitlines():
                cells = [c.strip() for c in line.strip("|").split("|")]
                if len(cells) > 5 and cells[0] == "one bridge":
                    key = (name, cells[1], cells[2])
                    cpu.setdefault(key, []).append(float(cells[3].rstrip(" %")))
                    stale.setdefault(key, []).append(int(cells[6]))
    print("| fleet (bench_fleet.py --only fleet) | interpreted bridge CPU, stale marks | compiled bridge CPU, "
          "stale marks | CPU compiled / interpreted |")
    print("|---|---|---|---|")
    steps = sorted((k[1:] for k in cpu if k[0] == "interpreted"), key=lambda rn: (float(rn[0].split()[0]), int(rn[1])))
    for rate, nodes in steps:
        i, c = ("interpreted", rate, nodes), ("compiled", rate, nodes)
        a, b = statistics.median(cpu[i]), statistics.median(cpu[c])
        print(f"| {nodes} nodes at {rate} | {a:.1f} %, {'/'.join(map(str, stale[i]))} | {b:.1f} %, "
              f"{'/'.join(map(str, stale[c]))} | {b / a:.2f}x |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--worker", nargs=3, help=argparse.SUPPRESS)
    ap.add_argument("--rounds", type=int, default=3, help="runs of each tree, alternately (default 3)")
    ap.add_argument("--fleet", metavar="N,...", help="also the fleet's bridge CPU at these counts of 100 Hz nodes")
    ap.add_argument("--fleet-1k", metavar="N,...", default="4", help="with --fleet: 1 kHz node counts (default 4)")
    ap.add_argument("--fleet-duration", type=float, default=15.0, help="with --fleet: seconds a step (default 15)")
    ap.add_argument("--fleet-rounds", type=int, default=1,
                    help="with --fleet: runs of each tree, alternately (default 1: a run takes minutes)")
    ap.add_argument("--keep", metavar="DIR", help="build the compiled copy in DIR (new) and keep it")
    args = ap.parse_args()
    if args.worker:
        _worker(*args.worker)
        return
    if shutil.which("gcc") is None:
        ap.error("needs gcc (Debian: apt-get install gcc)")
    cmd = " ".join(["benchmarks/bench_compiled.py", *sys.argv[1:]])
    print(f"# .venv/bin/python {cmd}")
    print(f"# {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())} on {describe()}, load average "
          f"{os.getloadavg()[0]:.1f}")
    work = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="eskin-compiled-"))
    try:
        if args.keep:
            work.mkdir(parents=True)
        seconds = build(work)
        print(f"# mypyc built detect/ but {', '.join(INTERPRETED)} in {seconds:.0f} s")
        trees = {"interpreted": ROOT, "compiled": work}
        check_updates(trees)
        time_frames(trees, args.rounds)
        time_steps(trees, args.rounds)
        if args.fleet:
            time_fleet(trees, args.fleet, args.fleet_1k, args.fleet_rounds, args.fleet_duration)
    finally:
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
