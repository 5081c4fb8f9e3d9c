"""CAN decode + detection speed against what a bus can carry, and a vcan burst.

    .venv/bin/python benchmarks/bench_can.py                  # decode + detect, one core
    .venv/bin/python benchmarks/bench_can.py --vcan-burst 60  # 60 s on vcan0 (emulated machine if needed)

The first measures the live path (frame by frame through the scan assembler, then the
pipeline: calibration and the streaming detector) in one thread, on frames already in
memory, and compares frames per second with a saturated bus: classic CAN at 1 Mbit/s
carries 7,400 to 9,000 eight-byte frames per second (with and without worst-case bit
stuffing), CAN FD with 64-byte frames at 5 Mbit/s about 5,900.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import can
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from machine import describe  # noqa: E402  (benchmarks/machine.py)

from eskin_industrial import Calibrator, load_profile  # noqa: E402
from eskin_industrial.bus.can.layout import CanLayout, ScanAssembler  # noqa: E402
from eskin_industrial.pipeline import Pipeline  # noqa: E402

CLASSIC_LIMIT = 9_000  # eight-byte frames per second at 1 Mbit/s, no stuffing (7,400 worst case)
FD_LIMIT = 5_900  # 64-byte frames per second at 1/5 Mbit/s


def classic_frame_bits(dlc: int, worst_stuffing: bool) -> int:
    """Bits on the wire of a standard-ID classic frame, with the 3-bit interframe space."""
    bits = 47 + 8 * dlc
    if worst_stuffing:
        bits += (34 + 8 * dlc - 1) // 4
    return bits


def machine() -> str:
    return describe()


def grasp_raw(profile, k: int) -> np.ndarray:
    rng = np.random.default_rng(0)
    n = profile.taxels
    t = np.arange(k) / profile.sensor.rate_hz
    col = np.arange(n) % profile.layout.cols
    centre = 2.0 + np.sin(2 * np.pi * 0.3 * t)
    f = 4.0 * np.exp(-((col[None, :] - centre[:, None]) ** 2)) + rng.normal(0, 0.01, (k, n))
    return np.rint(Calibrator.from_section(profile.calibration, n).to_raw(np.clip(f, 0, 6)))


def decode_detect(profile_path: str, fd: bool, scans: int) -> dict:
    prof = load_profile(profile_path)
    layout = CanLayout.from_profile(prof, fd=fd)
    rate = prof.sensor.rate_hz
    msgs = [can.Message(arbitration_id=i, data=d, timestamp=k / rate, is_fd=fd, is_extended_id=False)
            for k, frames in enumerate(layout.encode(np.arange(scans), grasp_raw(prof, scans))) for i, d in frames]
    best = {}
    for label, detect in (("decode", False), ("decode+detect", True)):
        times = []
        for _ in range(3):
            asm, pipe = ScanAssembler(layout, rate), Pipeline(prof)
            feed, push = asm.feed, pipe.push
            start = time.perf_counter()
            for m in msgs:
                scan = feed(m)
                if scan is not None and detect:
                    push(scan)
            times.append(time.perf_counter() - start)
            assert asm.counters["frames"] == len(msgs) and asm.counters["torn_scans"] == 0
        best[label] = len(msgs) / min(times)
    limit = FD_LIMIT if fd else CLASSIC_LIMIT
    return {"profile": prof.name, "variant": "fd" if fd else "classic", "bits": layout.bits,
            "frames_per_scan": layout.segments, "bytes_per_scan": layout.bytes_per_scan, "frames": len(msgs),
            "decode_fps": best["decode"], "decode_detect_fps": best["decode+detect"],
            "scans_per_s": best["decode+detect"] / layout.segments,
            "limit_fps": limit, "ratio_to_classic_limit": best["decode+detect"] / CLASSIC_LIMIT}


def bus_scan_rates() -> list[str]:
    """How many scans per second a saturated 1 Mbit/s classic bus carries, per layout."""
    out = []
    for taxels, bits in ((25, 12), (25, 16), (20, 12), (20, 16)):
        lay = CanLayout(taxels, bits, "little", 0)
        lo = sum(classic_frame_bits(lay.frame_length(s), True) for s in range(lay.segments))
        hi = sum(classic_frame_bits(lay.frame_length(s), False) for s in range(lay.segments))
        out.append(f"| {taxels} | {bits} | {lay.segments} | {lay.bytes_per_scan} | {hi} to {lo} | "
                   f"{1e6 / lo:.0f} to {1e6 / hi:.0f} |")
    return out


def write_candump(path: Path, profile, seconds: float, scan_rate: float) -> int:
    """``seconds`` of the node's traffic at ``scan_rate`` as a candump log (the format
    canplayer replays), heartbeats included; returns the number of frames."""
    layout = CanLayout.from_profile(profile)
    k = int(round(seconds * scan_rate))
    raw = grasp_raw(profile, min(k, 4096))
    every = max(1, int(round(profile.can.heartbeat_s * scan_rate)))
    from eskin_industrial.bus.can.layout import NodeState, NodeStatus

    frames = layout.encode(np.arange(len(raw)), raw)
    n = 0
    with open(path, "w") as out:
        for i in range(k):
            t = 1000.0 + i / scan_rate
            for can_id, data in frames[i % len(frames)]:
                data = layout.header(i, can_id - layout.base_id) + data[2:]
                out.write(f"({t:.6f}) can0 {can_id:03X}#{data.hex().upper()}\n")
                n += 1
            if i % every == every - 1:
                hb = layout.encode_status(NodeStatus(layout.node_id, NodeState.RUNNING, 0, 0, int(scan_rate), i))
                out.write(f"({t:.6f}) can0 {layout.status_id:03X}#{hb.hex().upper()}\n")
                n += 1
    return n


def vcan_burst(seconds: float, profile: str, rate: float | None, burst: bool, feeder: str, cpus: int = 2) -> int:
    sys.path.insert(0, str(ROOT / "tests" / "vcan"))
    import vm  # the harness the vcan tests use

    prof = load_profile(ROOT / profile)
    layout = CanLayout.from_profile(prof)
    scan_rate = rate or (CLASSIC_LIMIT * 0.9 / layout.segments)
    out = vm.CACHE / f"bench-{os.getpid()}"
    out.mkdir(parents=True, exist_ok=True)
    if feeder == "canplayer":  # can-utils sends, paced by the log's timestamps (-t: no pacing)
        log = out / "traffic.log"
        sent = write_candump(log, prof, seconds, scan_rate)
        feed = f"canplayer {'-t' if burst else ''} -I {log} vcan0=can0"
    else:  # our node simulator
        from eskin_industrial.recording import write_recording

        rec = out / "rec.csv"
        write_recording(rec, np.arange(2000) / scan_rate, grasp_raw(prof, 2000), unit="raw")
        sent = None
        feed = (f"eskin-bus node -p {profile} -i socketcan -c vcan0 --recording {rec} --rate {scan_rate:.6g} "
                f"--duration {seconds:g} {'--burst' if burst else ''} -q")
    script = f"""
eskin-bus receive -p {profile} -i socketcan -c vcan0 --rate {scan_rate:.6g} --idle-exit 10 \
   --duration {seconds * 3 + 120:.0f} 2> "$ESKIN_VCAN_OUT/receive.json" &
rx=$!
sleep 20
start=$(date +%s)
{feed}
echo $(( $(date +%s) - start )) > "$ESKIN_VCAN_OUT/feed_s.txt"
wait $rx
"""
    if vm.native_can() and vm.native_vcan("vcan0") == "":
        env = {**os.environ, "ESKIN_VCAN_OUT": str(out), "PATH": f"{ROOT}/.venv/bin:{os.environ['PATH']}"}
        subprocess.run(["sh", "-c", f"cd {ROOT} && {script}"], env=env, timeout=seconds * 4 + 300)
        where = "native vcan0"
    else:
        missing = vm.missing_prerequisites()
        if missing:
            print(f"bench: cannot run the emulated machine: missing {', '.join(missing)}", file=sys.stderr)
            return 2
        script += "python benchmarks/bench_can.py --scans 2000 > \"$ESKIN_VCAN_OUT/decode.txt\"\n"
        run = vm.run_in_vm(script, out, timeout_s=seconds * 4 + 400, cpus=cpus)
        where = f"vcan0 in the emulated machine (qemu TCG, {cpus} vCPU)"
        if run.rc != 0:
            print(run.console, run.boot_log[-2000:], file=sys.stderr)
            return 1
    rx = json.loads((out / "receive.json").read_text().strip().splitlines()[-1])
    feed_s = (out / "feed_s.txt").read_text().strip()
    expected = int(round(seconds * scan_rate))
    drops = rx["rx_queue_drops"] + rx["lost_scans"] + rx["torn_scans"] + (expected - rx["scans"] - rx["lost_scans"])
    print(f"# {time.strftime('%Y-%m-%d')} | {machine()} | {where}")
    print(f"# command: .venv/bin/python benchmarks/bench_can.py --vcan-burst {seconds:g} --profile {profile} "
          f"--rate {scan_rate:.6g} --feeder {feeder}{' --burst' if burst else ''}")
    print(f"receiver: {json.dumps(rx)}")
    if (out / "decode.txt").exists():
        print("decode + detect inside the emulated machine:")
        print((out / "decode.txt").read_text())
    print(f"RESULT: {seconds:g} s of traffic at {scan_rate:.0f} scans/s ({scan_rate * layout.segments:.0f} frames/s"
          f"{', sent unpaced' if burst else ''}) by {feeder}, sent in {feed_s} s: {sent if sent else '?'} frames; "
          f"received {rx['frames']} frames, {rx['scans']} of {expected} scans; drops {drops} "
          f"(queue {rx['rx_queue_drops']}, lost scans {rx['lost_scans']}, torn {rx['torn_scans']})")
    return 0


def virtual_burst(seconds: float, profile: str, rate: float | None) -> int:
    """The same run on python-can's in-process virtual bus (no kernel): the node in a
    thread, the receiver's reader thread and the detector in this process."""
    import threading

    from eskin_industrial.bus.can.reader import BusReader, CanSource, open_bus
    from eskin_industrial.sim.can_node import CanNode

    prof = load_profile(ROOT / profile)
    layout = CanLayout.from_profile(prof)
    scan_rate = rate or (CLASSIC_LIMIT * 0.9 / layout.segments)
    channel = f"bench-{os.getpid()}"
    reader = BusReader(lambda: open_bus("virtual", channel)).start()
    source = CanSource(reader, ScanAssembler(layout, scan_rate), Pipeline(prof, rate_hz=scan_rate))
    tx = open_bus("virtual", channel)
    node = CanNode(layout, tx, grasp_raw(prof, 2000), scan_rate, prof.can.heartbeat_s, duration_s=seconds)
    th = threading.Thread(target=node.run)
    th.start()
    source.run(idle_timeout_s=2.0, duration_s=seconds * 3 + 10)
    th.join()
    tx.shutdown()
    c, x = source.pipeline.counters, source.counters()
    expected = int(round(seconds * scan_rate))
    print(f"# {time.strftime('%Y-%m-%d')} | {machine()} | python-can virtual bus, one process")
    print(f"# command: .venv/bin/python benchmarks/bench_can.py --virtual-burst {seconds:g} --profile {profile}")
    print(f"RESULT: {seconds:g} s at {scan_rate:.0f} scans/s ({scan_rate * layout.segments:.0f} frames/s, paced; "
          f"node worst lateness {node.stats.late_s * 1000:.1f} ms): {node.stats.frames_sent} frames sent, "
          f"{x['frames']} received, {c.scans} of {expected} scans; drops: queue {x['rx_queue_drops']}, "
          f"lost scans {c.lost_scans}, torn {x['torn_scans']}")
    return 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scans", type=int, default=20_000, help="scans per run (default 20000)")
    ap.add_argument("--vcan-burst", type=float, default=None, metavar="SECONDS",
                    help="instead: send for SECONDS on vcan0 and count what the receiver lost")
    ap.add_argument("--virtual-burst", type=float, default=None, metavar="SECONDS",
                    help="instead: the same on python-can's in-process virtual bus")
    ap.add_argument("--profile", default="profiles/paper-5x5.toml")
    ap.add_argument("--rate", type=float, default=None,
                    help="scan rate of the vcan run (default: what fills 90%% of a 1 Mbit/s classic bus)")
    ap.add_argument("--burst", action="store_true", help="vcan run: no pacing, as fast as the bus takes frames")
    ap.add_argument("--vm-cpus", type=int, default=2, help="vcan run in the emulated machine: its CPUs")
    ap.add_argument("--feeder", choices=["canplayer", "node"], default="canplayer",
                    help="vcan run: who sends (can-utils canplayer from a log, or eskin-bus node)")
    args = ap.parse_args()
    if args.virtual_burst is not None:
        return virtual_burst(args.virtual_burst, args.profile, args.rate)
    if args.vcan_burst is not None:
        return vcan_burst(args.vcan_burst, args.profile, args.rate, args.burst, args.feeder, args.vm_cpus)
    print(f"# {time.strftime('%Y-%m-%d')} | {machine()}")
    print("# command: .venv/bin/python benchmarks/bench_can.py")
    print("| profile | variant | bits | frames/scan | decode frames/s | decode+detect frames/s | scans/s | "
          "x the bus limit |")
    print("|---|---|---|---|---|---|---|---|")
    for path in ("profiles/paper-5x5.toml", "profiles/hand-4x5.toml"):
        for fd in (False, True):
            r = decode_detect(str(ROOT / path), fd, args.scans)
            print(f"| {r['profile']} | {r['variant']} | {r['bits']} | {r['frames_per_scan']} | "
                  f"{r['decode_fps']:,.0f} | {r['decode_detect_fps']:,.0f} | {r['scans_per_s']:,.0f} | "
                  f"{r['decode_detect_fps'] / r['limit_fps']:.1f} (of {r['limit_fps']:,}/s) |")
    print()
    print("| taxels | bits | frames/scan | bytes/scan | bits on a 1 Mbit/s bus per scan | scans/s on a saturated bus |")
    print("|---|---|---|---|---|---|")
    for line in bus_scan_rates():
        print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
