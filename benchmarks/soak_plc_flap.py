"""The flapping-PLC soak: the bridge writes a PLC that goes away and comes back every
20 s; reconnects stay bounded, each outage is logged once at its start and once at
its end, and no slip's latch is lost.

    .venv/bin/python benchmarks/soak_plc_flap.py                    # 10 minutes
    .venv/bin/python benchmarks/soak_plc_flap.py --duration 60      # a short check

The product's :class:`~eskin_industrial.bridge.runtime.Bridge` runs one node on a
scene source (the benchmark "slip train": an 8 N grasp with a slide every 1.2 s, at
the profile's 100 Hz, looped) in client mode over Modbus TCP on loopback, to the PLC
stand-in of the tests (``tests/helpers/plc_standin.py``, its own framing).  Every
``--flap`` seconds the stand-in goes away (its connections reset, new ones refused)
or comes back.  As a PLC program would, it acknowledges each slip latch it reads
(COMMAND bit 0), so that every slip latches anew.  At the end:

- outages: the PLC's down phases, the ``plc_unreachable`` / ``plc_connected`` pairs
  in the bridge's log, and anything unpaired;
- reconnects: connection attempts per outage (from ``plc_connected``'s ``attempts``),
  against the most a doubling back-off allows in one down phase; connections the
  stand-in accepted per up phase; time from the PLC's return to its first write;
- the latch: every rise of SLIP_EVENTS the PLC received came with SLIP_LATCHED set,
  the slips during outages included (the newest image, latch and all, is the first
  written on return); the PLC's last SLIP_EVENTS against the bridge's count;
- process CPU share (bridge and stand-in together).
"""

from __future__ import annotations

import argparse
import datetime as dt
import os
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_bridge import PROFILE, slip_train_toml  # noqa: E402
from machine import describe  # noqa: E402

from eskin_industrial.outputs.plc.image import REG, Status  # noqa: E402
from tests.helpers.bridge import LogCapture  # noqa: E402
from tests.helpers.plc_standin import PlcStandIn  # noqa: E402

SLIP_AT = REG["SLIP_EVENTS"].offset
COMMAND_AT = REG["COMMAND"].offset


class AckingPlc(PlcStandIn):
    """The stand-in with a PLC program: a latched slip it has not acknowledged yet is
    acknowledged (COMMAND bit 0), as a gripper's program does once it has reacted."""

    acked = 0

    def _answer(self, frame: bytes) -> bytes | None:
        answer = super()._answer(frame)
        if self.mode == "ok" and frame[7] == 16 and self.seen.writes:
            _, address, values = self.seen.writes[-1]
            if address == 0 and values[0] & Status.SLIP_LATCHED:
                count = values[SLIP_AT] << 16 | values[SLIP_AT + 1]
                if count > self.acked:
                    self.acked = count
                    self.regs[COMMAND_AT] = 1
        return answer


def most_attempts(span_s: float, backoff_s: float, backoff_max_s: float, jitter: float) -> int:
    """Connection attempts a doubling back-off allows in ``span_s`` (waits as short as
    the jitter makes them, one attempt more for the first)."""
    n, t, d = 1, 0.0, backoff_s
    while True:
        t += d * (1 - jitter)
        if t > span_s:
            return n
        n += 1
        d = min(2 * d, backoff_max_s)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration", type=float, default=600.0, help="seconds (default 600)")
    ap.add_argument("--flap", type=float, default=20.0, help="the PLC goes away or comes back every FLAP s (default 20)")
    args = ap.parse_args()

    from eskin_industrial.bridge.config import BridgeConfig, LogSettings, NodeConfig, resolve
    from eskin_industrial.bridge.logs import EventLog
    from eskin_industrial.bridge.runtime import Bridge
    from eskin_industrial.outputs.plc.client import JITTER
    from eskin_industrial.outputs.plc.options import PlcOptions

    print(f"# .venv/bin/python benchmarks/soak_plc_flap.py --duration {args.duration:g} --flap {args.flap:g}")
    print(f"# {time.strftime('%Y-%m-%d %H:%M', time.gmtime())} UTC on {describe()}", flush=True)
    scene = Path(tempfile.mkdtemp()) / "slip-train.toml"
    scene.write_text(slip_train_toml(60.0))
    plc = AckingPlc("ok").start()
    node = NodeConfig.of("grip", str(PROFILE), "scene", scene=str(scene))
    cfg = BridgeConfig(node=(node,), outputs={"plc": PlcOptions(mode="client", host="127.0.0.1", port=plc.port)},
                       log=LogSettings(format="json", status_every_s=0))
    nodes = resolve(cfg)
    settings = nodes[0].profile.modbus.plc
    capture = LogCapture()
    log = EventLog(capture, "json", "info")
    br = Bridge(cfg, nodes, log).open()
    phases: list[tuple[str, float]] = [("up", time.monotonic())]  # (up/down, monotonic)
    stop = threading.Event()

    def flapper() -> None:
        while not stop.wait(args.flap):
            if phases[-1][0] == "up":
                plc.go_down()
                phases.append(("down", time.monotonic()))
            else:
                plc.come_back()
                phases.append(("up", time.monotonic()))

    cpu0, t0 = time.process_time(), time.monotonic()
    br.start()
    flap = threading.Thread(target=flapper, daemon=True)
    flap.start()
    writer = br.runs[0].sinks[0]
    next_print = t0 + 120
    try:
        while time.monotonic() - t0 < args.duration:
            time.sleep(1.0)
            if time.monotonic() >= next_print:
                next_print += 120
                c = br.counters()["grip"]
                print(f"  {time.monotonic() - t0:5.0f} s  outages {c['plc_outages']}  attempts "
                      f"{c['plc_connect_attempts']}  writes {c['plc_writes']}  slips {br.runs[0].loop.status.slip_events}",
                      flush=True)
    finally:
        stop.set()
        flap.join(5)
        if phases[-1][0] == "down":  # end with the PLC up, so that the last outage ends
            plc.come_back()
            phases.append(("up", time.monotonic()))
        deadline = time.monotonic() + settings.backoff_max_s + 3
        while getattr(writer, "in_outage", False) and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(0.5)
        wall = time.monotonic() - t0
        cpu = time.process_time() - cpu0
        br.stop()  # the offline image, with the last count, is written before the writer lets go
        bridge_slips = br.runs[0].loop.status.slip_events
        c = br.counters()["grip"]
        log.close()
        plc.go_down()

    events = capture.events()
    downs = [(t, phases[i + 1][1] if i + 1 < len(phases) else None)
             for i, (kind, t) in enumerate(phases) if kind == "down"]
    starts = [e for e in events if e["event"] == "plc_unreachable"]
    ends = [e for e in events if e["event"] == "plc_connected" and e["cause"] != "-"]
    sequence = [e["event"] for e in events if e["event"] in ("plc_unreachable", "plc_connected")]
    alternating = sequence[:1] == ["plc_connected"] and all(
        a != b for a, b in zip(sequence[1:], sequence[2:]))
    attempts = [e["attempts"] for e in ends]
    bound = most_attempts(args.flap, settings.backoff_s, settings.backoff_max_s, JITTER) + 1

    # The PLC's side: connections per up phase, time from return to the first write.
    ups = [(t, phases[i + 1][1] if i + 1 < len(phases) else float("inf"))
           for i, (kind, t) in enumerate(phases) if kind == "up"]
    per_up = [sum(lo <= t < hi for t in plc.seen.connects) for lo, hi in ups]
    writes = [(t, v) for t, a, v in plc.seen.writes if a == 0]
    to_first = []
    for lo, hi in ups[1:]:
        first = next((t for t, _ in writes if lo <= t < hi), None)
        if first is not None:
            to_first.append(first - lo)

    # The latch: each rise of SLIP_EVENTS the PLC got came latched.
    rises = unlatched = 0
    after_outage = after_outage_latched = 0
    prev = 0
    returned = {next((t for t, _ in writes if lo <= t < hi), None) for lo, hi in ups[1:]}
    for t, v in writes:
        count = v[SLIP_AT] << 16 | v[SLIP_AT + 1]
        if count > prev:
            rises += 1
            latched = bool(v[0] & Status.SLIP_LATCHED)
            unlatched += not latched
            if t in returned:
                after_outage += 1
                after_outage_latched += latched
        prev = max(prev, count)

    print(f"ran {wall:.0f} s; the PLC went away {len(downs)} times for {args.flap:g} s, came back {len(ups) - 1}")
    print(f"log: {len(starts)} plc_unreachable, {len(ends)} plc_connected ending an outage; "
          f"{'one pair per outage, in order' if alternating and len(starts) == len(ends) == len(downs) else 'NOT one pair per outage'}"
          f"; outage_s median {statistics.median([e['outage_s'] for e in ends]) if ends else float('nan'):.1f}, "
          f"superseded per outage median {statistics.median([e['superseded'] for e in ends]) if ends else 0:.0f}")
    print(f"reconnect attempts per outage: min {min(attempts, default=0)}, median "
          f"{statistics.median(attempts) if attempts else 0:.0f}, max {max(attempts, default=0)} "
          f"(a doubling back-off from {settings.backoff_s:g} to {settings.backoff_max_s:g} s allows at most {bound} in "
          f"{args.flap:g} s); connections accepted per up phase: max {max(per_up, default=0)}")
    if to_first:
        print(f"PLC back -> first write: median {statistics.median(to_first):.2f} s, max {max(to_first):.2f} s")
    print(f"latch: {rises} rises of SLIP_EVENTS reached the PLC, {rises - unlatched} with SLIP_LATCHED, "
          f"{unlatched} without; {after_outage} in the first write after an outage, {after_outage_latched} latched; "
          f"the PLC's last SLIP_EVENTS {prev}, the bridge's {bridge_slips}")
    print(f"counters: plc_writes {c['plc_writes']}, plc_write_failures {c['plc_write_failures']}, plc_connects "
          f"{c['plc_connects']}, plc_connect_attempts {c['plc_connect_attempts']}, plc_outages {c['plc_outages']}, "
          f"plc_superseded {c['plc_superseded']}; process CPU {cpu / wall * 100:.1f} % of one core")
    ok = (alternating and len(starts) == len(ends) == len(downs) and max(attempts, default=0) <= bound
          and unlatched == 0 and prev == bridge_slips and max(per_up, default=0) <= 1)
    print(f"{dt.datetime.now(dt.UTC):%Y-%m-%d %H:%M} UTC: {'PASS' if ok else 'FAIL'}")
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    main()
