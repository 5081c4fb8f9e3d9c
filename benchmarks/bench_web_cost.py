"""Where the web console's cost per scan and per message goes, without a bridge: the
node's side of the console (the sink's publish, on_update and on_frame, as the web
output's handover thread calls them once a scan) and the server's display frame (the
feed's tick and the message each of 1 or 5 viewers watching the node is sent), each
timed over many calls on a 5 x 5 and a 16 x 16 grid.  CPU-bound and single-threaded, so it
reads the same on a loaded machine within a few per cent; run it against an older
checkout (``PYTHONPATH=OLD python benchmarks/bench_web_cost.py``) to compare.

    .venv/bin/python benchmarks/bench_web_cost.py
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.append(str(ROOT))  # tests.helpers; the package from PYTHONPATH when given

from eskin_industrial.detect.updates import Update  # noqa: E402
from eskin_industrial.frames import Frame  # noqa: E402
from eskin_industrial.outputs.web import server as web_server  # noqa: E402
from eskin_industrial.outputs.web.hub import NodeFeed  # noqa: E402
from eskin_industrial.outputs.web.options import WebOptions  # noqa: E402
from tests.helpers.snapshots import made  # noqa: E402


def per_call_us(call, n: int) -> float:
    best = float("inf")
    for _ in range(5):  # the best of five: the machine's other load left out
        t0 = time.perf_counter()
        for k in range(n):
            call(k)
        best = min(best, (time.perf_counter() - t0) / n)
    return best * 1e6


def grid_row(rows: int, cols: int) -> str:
    feed = NodeFeed(0, 1000.0, 2.0, 1.0, 0.03)
    view = web_server.NodeView("n", rows, cols, [0.0] * rows * cols, [0.0] * rows * cols, [], "cof-track",
                               ("a", "b"), (1.0, 1.0), (None, None), 1000.0)
    server = web_server.WebServer(WebOptions(), [view], [feed], ())
    forces = [np.random.default_rng(k).random(rows * cols) * 2.0 for k in range(64)]
    snaps = [made(scans=k, t=k / 1000.0, urgent=False) for k in range(64)]
    updates = [Update(k / 1000.0, 0.1, 0.2, 1, True, 5.0, 10.0, 10.0, 0, 0.3, 0.4) for k in range(64)]

    def scan(k: int) -> None:
        feed.publish(snaps[k % 64])
        feed.update(updates[k % 64])
        feed.frame(Frame(k, k / 1000.0, forces[k % 64]))

    scan_us = per_call_us(scan, 20000)
    sizes: list[int] = []
    display: dict[int, float] = {}
    for viewers in (1, 5):
        clients = [web_server.Client(ws=None, watch=0) for _ in range(viewers)]  # type: ignore[arg-type]

        def frame(k: int, clients: list = clients) -> None:
            scan(k)  # a new snapshot and frame at every display frame, as at any rate
            if hasattr(feed, "tick"):
                feed.tick(time.monotonic())
            else:
                feed.freeze_captures()
            for c in clients:
                out = server._message(c)
                sizes.append(len(out) if out is not None else 0)

        display[viewers] = per_call_us(frame, 1000) - scan_us
    at_1k = (1000 * scan_us + (1 / 0.03) * display[5]) / 1e6 * 100
    return (f"| {rows} x {cols} | {scan_us:.1f} us | {display[1]:.0f} us | {display[5]:.0f} us | "
          f"{(display[5] - display[1]) / 4:.0f} us | {int(np.median(sizes))} bytes | {at_1k:.2f} % |")


def main() -> None:
    print(f"# package: {web_server.__file__}")
    print("| grid | node's side a scan (publish + on_update + on_frame) | a display frame, 1 viewer | 5 viewers "
          "| per viewer more | a message's size | the console at 1 kHz, 5 viewers: % of a core |")
    print("|---|---|---|---|---|---|---|")
    for rows, cols in ((5, 5), (16, 16)):
        print(grid_row(rows, cols), flush=True)


if __name__ == "__main__":
    main()
