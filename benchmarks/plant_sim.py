"""A plant on one host: ``--cells`` bridge processes (``eskin-bus bridge``, each one
Sparkplug edge node ``cellNN`` of group ``plant``) publish to one mosquitto for
``--duration`` seconds; one ``mosquitto_sub`` on ``spBv1.0/#`` captures everything.

    .venv/bin/python benchmarks/plant_sim.py                       # 20 cells, 10 minutes
    .venv/bin/python benchmarks/plant_sim.py --cells 5 --duration 30

Each cell: ``--source scene:slip-train.toml`` (the slip train of ``bench_bridge.py``,
looped by the scene source: a slide every 1.2 s, about 50 slips a minute), no PLC,
then SIGTERM.  Checked from the capture alone, payloads decoded with the ``protobuf``
package from the tests' schema (not the package's codec):

- births: each edge node's first message is its NBIRTH (seq 0), its device's DBIRTH
  comes before the device's first DDATA;
- deaths: after SIGTERM, the device's DDEATH, then the NDEATH whose ``bdSeq`` is the
  NBIRTH's; nothing from the node after it;
- seq: consecutive (mod 256) over each node's NBIRTH, DBIRTH, DDATA and DDEATH;
- slips: every slip the bridge decided (its own ``state`` log lines, ``state=slip``)
  arrives as a DDATA whose ``State Code`` is 3, and the last ``Counters/Slip Events``
  received equals that count.  The scene's ground truth (its slides, in the scans the
  bridge took) is printed beside it: the detector's recall, not a transport matter.

Printed: per cell the bridge's CPU and resident memory, messages/s per cell, the
broker's messages/s (at the subscriber) and its CPU: the figures an estimate for a
larger plant rests on.
"""

from __future__ import annotations

import argparse
import json
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter, defaultdict
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_bridge import PROFILE, slip_train_toml  # noqa: E402
from bench_fleet import Subscriber, proc_cpu_s  # noqa: E402
from machine import describe  # noqa: E402

from tests.helpers import sparkplug as spb  # noqa: E402

GROUP = "plant"
DEVICE = "grip"
STATE_CODE, SLIP_EVENTS = 1, 15  # alias offsets in a device's block (DEVICE_METRICS order)


def rss_kib(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    return 0


def truth_slips(scene: Path, rate: float, scans: int) -> int:
    """Slides begun in the first ``scans`` scans of the scene played in a loop."""
    from eskin_industrial.scenes import render

    labels = render(str(scene), rate, 0).labels
    played = np.resize(labels == "slip", scans)
    return int(played[0]) + int(np.count_nonzero(played[1:] & ~played[:-1]))


def bridge_log(path: Path) -> tuple[int, dict[str, Any]]:
    """(slips the bridge decided, its final counters) from its JSON log."""
    slips, final = 0, {}
    for line in path.read_text().splitlines():
        try:
            e = json.loads(line)
        except ValueError:
            continue
        if e.get("event") == "state" and e.get("state") == "slip":
            slips += 1
        elif e.get("event") == "final":
            final = e
    return slips, final


def check_node(edge: str, msgs: list[tuple[str, Any]]) -> dict[str, Any]:
    """The checks of one edge node over its messages in arrival order: (kind, payload)."""
    problems: list[str] = []
    seq_gaps = 0
    births = deaths = 0
    born = False
    bd_seq = None
    device_born = False
    prev_seq = None
    slips_received = 0
    last_code = None
    last_slip_events = None
    dead = False
    for kind, p in msgs:
        if dead:
            problems.append(f"{kind} after NDEATH")
        if kind == "NBIRTH":
            births += 1
            born = True
            bd_seq = spb.metric_value(p, "bdSeq")
            if p.seq != 0:
                problems.append(f"NBIRTH seq {p.seq}")
            prev_seq = p.seq
            continue
        if kind == "NDEATH":
            deaths += 1
            dead = True
            if spb.metric_value(p, "bdSeq") != bd_seq:
                problems.append("NDEATH bdSeq is not the NBIRTH's")
            continue
        if not born:
            problems.append(f"{kind} before NBIRTH")
        if kind in ("DBIRTH", "DDATA", "DDEATH", "NDATA"):
            if prev_seq is not None and p.seq != (prev_seq + 1) % 256:
                seq_gaps += 1
            prev_seq = p.seq
        if kind == "DBIRTH":
            device_born = True
            last_code = None
            for m in p.metrics:
                if m.name == "State Code":
                    last_code = spb.value(m)
        elif kind == "DDATA":
            if not device_born:
                problems.append("DDATA before DBIRTH")
            for m in p.metrics:
                if m.alias % 1000 == STATE_CODE:
                    code = spb.value(m)
                    if code == 3 and last_code != 3:
                        slips_received += 1
                    last_code = code
                elif m.alias % 1000 == SLIP_EVENTS:
                    last_slip_events = spb.value(m)
        elif kind == "DDEATH":
            device_born = False
    kinds = [k for k, _ in msgs]
    if not kinds or kinds[-1] != "NDEATH":
        problems.append("no NDEATH at the end")
    elif len(kinds) < 2 or kinds[-2] != "DDEATH":
        problems.append("no DDEATH before the NDEATH")
    counted = Counter(problems)  # one line per kind of problem
    return dict(births=births, deaths=deaths, seq_gaps=seq_gaps, slips=slips_received, slip_events=last_slip_events,
                problems=[f"{p} (x{n})" if n > 1 else p for p, n in counted.items()], messages=len(msgs))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cells", type=int, default=20)
    ap.add_argument("--duration", type=float, default=600.0, help="seconds (default 600)")
    ap.add_argument("--rate", type=float, default=100.0, help="scan rate of every cell (default 100 Hz)")
    ap.add_argument("--keep", type=Path, help="keep the capture and the logs in this folder")
    args = ap.parse_args()
    print(f"# .venv/bin/python benchmarks/plant_sim.py --cells {args.cells} --duration {args.duration:g} "
          f"--rate {args.rate:g}")
    print(f"# {time.strftime('%Y-%m-%d', time.gmtime())} on {describe()}")
    with tempfile.TemporaryDirectory() as d:
        tmp = args.keep or Path(d)
        tmp.mkdir(parents=True, exist_ok=True)
        scene = tmp / "slip-train.toml"
        scene.write_text(slip_train_toml(24.0))
        broker = spb.Broker(tmp)
        sub = Subscriber(broker.port, tmp / "capture.txt")
        cells = [f"cell{i + 1:02d}" for i in range(args.cells)]
        procs: dict[str, subprocess.Popen] = {}
        logs: dict[str, Path] = {}
        try:
            for cell in cells:
                logs[cell] = tmp / f"{cell}.log"
                with open(logs[cell], "w") as err:
                    procs[cell] = subprocess.Popen(
                        [str(ROOT / ".venv/bin/eskin-bus"), "bridge", "-p", str(PROFILE), "--source", f"scene:{scene}",
                         "--rate", f"{args.rate:g}", "--name", DEVICE, "--sparkplug", f"mqtt://127.0.0.1:{broker.port}",
                         "--group-id", GROUP, "--edge-node-id", cell, "--log-format", "json", "--status-every", "0"],
                        stdout=subprocess.DEVNULL, stderr=err)
            time.sleep(min(10.0, args.duration / 3))  # started, connected (the imports take a while on 2 cores)
            cpu0 = {c: proc_cpu_s(p.pid) for c, p in procs.items()}
            b0, m0, t0 = proc_cpu_s(broker.proc.pid), sub.count(), time.monotonic()
            time.sleep(max(0.0, args.duration - min(10.0, args.duration / 3)))
            wall = time.monotonic() - t0
            cpu = {c: (proc_cpu_s(p.pid) - cpu0[c]) / wall for c, p in procs.items()}
            rss = {c: rss_kib(p.pid) for c, p in procs.items()}
            broker_cpu, msgs_s = (proc_cpu_s(broker.proc.pid) - b0) / wall, (sub.count() - m0) / wall
            for p in procs.values():
                p.send_signal(signal.SIGTERM)
            codes = {c: p.wait(30) for c, p in procs.items()}
            time.sleep(1.0)
        finally:
            for p in procs.values():
                if p.poll() is None:
                    p.kill()
            sub.close()
            broker.kill()
        by_node: dict[str, list[tuple[str, Any]]] = defaultdict(list)
        sizes: dict[str, list[int]] = defaultdict(list)
        for _t, topic, data in sub.messages():
            parts = topic.split("/")
            if len(parts) >= 4 and parts[1] == GROUP:
                by_node[parts[3]].append((parts[2], spb.parse(data)))
                sizes[parts[2]].append(len(data))
        print("| cell | exit | messages | births / deaths | seq gaps | slips: truth / decided / received "
              "| last Slip Events | problems |")
        print("|---|---|---|---|---|---|---|---|")
        total = defaultdict(int)
        failed = []
        for cell in cells:
            r = check_node(cell, by_node.get(cell, []))
            decided, final = bridge_log(logs[cell])
            truth = truth_slips(scene, args.rate, int(final.get("scans", 0)))
            ok = (codes[cell] == 0 and not r["problems"] and r["seq_gaps"] == 0 and r["slips"] == decided
                  and r["slip_events"] == decided)
            if not ok:
                failed.append(cell)
            for k, v in (("messages", r["messages"]), ("gaps", r["seq_gaps"]), ("truth", truth), ("decided", decided),
                         ("received", r["slips"])):
                total[k] += v
            print(f"| {cell} | {codes[cell]} | {r['messages']} | {r['births']} / {r['deaths']} | {r['seq_gaps']} "
                  f"| {truth} / {decided} / {r['slips']} | {r['slip_events']} | {'; '.join(r['problems']) or '-'} |")
        print(f"| all {len(cells)} | | {total['messages']} | | {total['gaps']} "
              f"| {total['truth']} / {total['decided']} / {total['received']} | | "
              f"{'every check passed' if not failed else 'FAILED: ' + ', '.join(failed)} |")
        c, m = np.array(list(cpu.values())), np.array(list(rss.values())) / 1024
        print(f"# bridge CPU per cell: median {np.median(c) * 100:.1f} %, max {c.max() * 100:.1f} % of a core; "
              f"RSS per cell: median {np.median(m):.0f} MiB, max {m.max():.0f} MiB")
        print(f"# broker: {msgs_s:.0f} messages/s at the subscriber ({msgs_s / len(cells):.1f} per cell), "
              f"CPU {broker_cpu * 100:.1f} % of a core ({broker_cpu * 1e6 / max(msgs_s, 1e-9):.0f} us per message "
              f"in and out)")
        print("# payload bytes, median (max): " + ", ".join(
            f"{k} {int(np.median(v))} ({max(v)})" for k, v in sorted(sizes.items())))
        if failed:
            sys.exit(1)


if __name__ == "__main__":
    main()
