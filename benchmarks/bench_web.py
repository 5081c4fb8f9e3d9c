"""The web console's cost and pace: the bridge's CPU with 0, 1 and 2 browsers on a
node page, and the frame rate each page reaches, at 100 Hz and 1 kHz sensor rates.

    .venv/bin/python benchmarks/bench_web.py                       # 100 Hz and 1 kHz, 20 s each
    .venv/bin/python benchmarks/bench_web.py --rates 1000 --duration 10 --viewers 0,1

What runs: the product's own bridge (``Bridge``: the loop thread, the console's server
thread) on a scene source (the hold scene played in real time at the rate), with the
web output alone; the browsers are headless Debian chromium under Selenium (each
viewer a tab of one browser, in its own processes: not counted).  CPU: this process's
user + system time over the run (the scene source plays on the loop's thread), in %
of one core; the page's rate: frames drawn over the run (``Console.seen.frames``).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from eskin_industrial.bridge.config import BridgeConfig, LogSettings, NodeConfig
from eskin_industrial.outputs.web.options import WebOptions
from tests.helpers.bridge import PAPER, running_bridge, wait_for
from tests.helpers.browser import chromium
from tests.helpers.modbus import free_port


def cpu_s() -> float:
    t = os.times()
    return t.user + t.system


def run(rate_hz: float, viewers: int, duration_s: float, driver: Any) -> tuple[float, list[float], int]:
    port = free_port()
    node = NodeConfig.of("grip", PAPER, "scene", rate_hz=rate_hz, scene="hold")
    config = BridgeConfig(node=(node,), outputs={"web": WebOptions(bind=f"127.0.0.1:{port}")},
                          log=LogSettings(format="json", status_every_s=0))
    with running_bridge(config) as bridge:
        tabs = []
        for k in range(viewers):
            if k:
                driver.switch_to.new_window("tab")
            driver.get(f"http://127.0.0.1:{port}/node/0")
            wait_for(lambda: driver.execute_script("return (Console.seen.frames || 0) > 5;"), timeout_s=15,
                     what="frames drawn")
            tabs.append(driver.current_window_handle)
        start_frames = []
        for h in tabs:
            driver.switch_to.window(h)
            start_frames.append(driver.execute_script("return Console.seen.frames;"))
        scans0, c0, t0 = bridge.counters("grip")["scans"], cpu_s(), time.monotonic()
        time.sleep(duration_s)
        c1, t1, scans1 = cpu_s(), time.monotonic(), bridge.counters("grip")["scans"]
        fps = []
        for h, f0 in zip(tabs, start_frames):
            driver.switch_to.window(h)
            fps.append((driver.execute_script("return Console.seen.frames;") - f0) / (t1 - t0))
        for h in tabs[1:]:
            driver.switch_to.window(h)
            driver.close()
        if tabs:
            driver.switch_to.window(tabs[0])
            driver.get("about:blank")
        return 100.0 * (c1 - c0) / (t1 - t0), fps, int((scans1 - scans0) / (t1 - t0))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rates", default="100,1000")
    ap.add_argument("--viewers", default="0,1,2")
    ap.add_argument("--duration", type=float, default=20.0)
    args = ap.parse_args()
    print("rate_hz viewers scans/s bridge_cpu_% page_frames/s")
    with chromium() as driver:
        for rate in (float(r) for r in args.rates.split(",")):
            for viewers in (int(v) for v in args.viewers.split(",")):
                cpu, fps, scans = run(rate, viewers, args.duration, driver)
                shown = ",".join(f"{f:.1f}" for f in fps) or "-"
                print(f"{rate:7.0f} {viewers:7d} {scans:7d} {cpu:12.1f} {shown}", flush=True)


if __name__ == "__main__":
    main()
