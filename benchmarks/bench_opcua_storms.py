"""The OPC UA output under connection storms, with a well-behaved client reading all
along: how long its worst read takes in each phase (target: at most 50 ms), and
whether every refused client was told why.

    .venv/bin/python benchmarks/bench_opcua.py --only storms --storm-s 8

One bridge, one node (the idle scene at 100 Hz), the OPC UA output with its default
limits (``max_sessions`` 16, ``max_pending`` 8, ``hello_timeout_s`` 2).  A reader (an
asyncua client in a process of its own, its session opened before the storms) reads
``Counters/Scans`` every 10 ms and notes each read's duration, and how late its own
10 ms sleep woke (its process held up by the machine rather than by the server).  Each phase's storm
runs in another process for ``--storm-s`` seconds, one after the other, a quiet
second between:

- quiet: no storm (the baseline);
- idle sockets: 100 sockets that send nothing, each reopened when the server closes
  it (after ``hello_timeout_s``, with BadTimeout);
- connect/close: four threads connecting and closing as fast as they can, every other
  connection after a Hello and its Acknowledge;
- malformed: garbage, HTTP, lying sizes in the Hello and after it, on new connections
  in turn, each answer read;
- 50 at once: bursts of 50 asyncua clients connecting at once, each reading once and
  closing; a refused one must have been told (BadTcpServerTooBusy,
  BadTooManySessions), anything else is counted as a failure.
"""

from __future__ import annotations

import asyncio
import json
import os
import socket
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

NAMESPACE_URI = "urn:eskin-industrial:opcua:grasp"
PHASES = ("quiet", "idle sockets", "connect/close", "malformed", "50 at once")
_PHASE_ARG = {"quiet": "quiet", "idle sockets": "idle", "connect/close": "churn", "malformed": "malformed",
              "50 at once": "burst"}


def _hello(url: str) -> bytes:
    raw = url.encode()
    body = struct.pack("<IIIIIi", 0, 65535, 65535, 0, 0, len(raw)) + raw
    return b"HELF" + struct.pack("<I", 8 + len(body)) + body


def _port(url: str) -> int:
    return int(url.rsplit(":", 1)[1])


# -- the reader (a process of its own) ------------------------------------------------

def reader_main(url: str) -> None:
    """Read ``n01.Counters.Scans`` every 10 ms until stdin closes: ``TIME SECONDS LAG`` a
    read, LAG how late its own 10 ms sleep before it woke (the reader's process
    itself held up by the machine, not by the server)."""
    from asyncua import Client

    async def main() -> None:
        async with Client(url, timeout=30) as client:
            ns = await client.get_namespace_index(NAMESPACE_URI)
            node = client.get_node(f"ns={ns};s=n01.Counters.Scans")
            print("ready", flush=True)
            done = asyncio.get_running_loop().run_in_executor(None, sys.stdin.read)
            lag = 0.0
            while not done.done():
                t0 = time.perf_counter()
                await node.read_data_value(raise_on_bad_status=False)
                t1 = time.perf_counter()
                print(f"{time.time():.6f} {t1 - t0:.6f} {lag:.6f}", flush=True)
                await asyncio.sleep(0.01)
                lag = time.perf_counter() - t1 - 0.01

    asyncio.run(main())


# -- the storms (each a process of its own) -------------------------------------------

def _read_all(s: socket.socket) -> bytes:
    data = b""
    try:
        while chunk := s.recv(65536):
            data += chunk
    except OSError:
        pass
    return data


def _idle(url: str, seconds: float) -> dict[str, Any]:
    """100 silent sockets, each reopened once the server closes it."""
    end = time.monotonic() + seconds
    opened, timed_out, lock = [0], [0], threading.Lock()

    def hold() -> None:
        while time.monotonic() < end:
            with socket.create_connection(("127.0.0.1", _port(url)), timeout=max(end - time.monotonic(), 0.1)) as s:
                with lock:
                    opened[0] += 1
                data = _read_all(s)
                if data[:3] == b"ERR" and struct.unpack_from("<I", data, 8)[0] == 0x800A0000:  # BadTimeout
                    with lock:
                        timed_out[0] += 1

    threads = [threading.Thread(target=hold, daemon=True) for _ in range(100)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(seconds + 10)
    return {"sockets opened": opened[0], "told BadTimeout": timed_out[0]}


def _churn(url: str, seconds: float) -> dict[str, Any]:
    """Four threads connecting and closing, every other connection after its Hello."""
    end = time.monotonic() + seconds
    counts = [0, 0]
    lock = threading.Lock()

    def run() -> None:
        i = 0
        while time.monotonic() < end:
            i += 1
            try:
                with socket.create_connection(("127.0.0.1", _port(url)), timeout=5) as s:
                    if i % 2:
                        s.sendall(_hello(url))
                        s.recv(8)
                with lock:
                    counts[i % 2] += 1
            except OSError:
                pass

    threads = [threading.Thread(target=run, daemon=True) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(seconds + 10)
    return {"bare connections": counts[0], "after a Hello": counts[1]}


def _malformed(url: str, seconds: float) -> dict[str, Any]:
    """Garbage on new connections in turn: how many were answered with an Error."""
    hello = _hello(url)
    garbage = [
        b"GET / HTTP/1.1\r\nHost: x\r\n\r\n",
        b"HELF" + struct.pack("<I", 0xFFFFFFF0) + b"\x00" * 24,
        b"HELF" + struct.pack("<I", 8),
        b"MSGF" + struct.pack("<I", 64) + b"\x00" * 56,
        hello + b"MSGF" + struct.pack("<I", 0xFFFFFFF0) + b"\x00" * 64,
        hello + b"XYZF" + struct.pack("<I", 64) + b"\x00" * 56,
        b"\x00" * 4096,
    ]
    end = time.monotonic() + seconds
    sent = answered = 0
    i = 0
    while time.monotonic() < end:
        data = garbage[i % len(garbage)]
        i += 1
        with socket.create_connection(("127.0.0.1", _port(url)), timeout=5) as s:
            s.sendall(data)
            answer = _read_all(s)
        sent += 1
        answered += b"ERRF" in answer
    return {"sent": sent, "told why": answered}


def _burst(url: str, seconds: float) -> dict[str, Any]:
    """Bursts of 50 asyncua clients at once, each reading once and closing."""
    import logging

    from asyncua import Client
    from asyncua.ua.uaerrors import UaStatusCodeError

    logging.getLogger("asyncua").setLevel(logging.CRITICAL)
    told = {0x807D0000: "BadTcpServerTooBusy", 0x80560000: "BadTooManySessions"}
    counts: dict[str, int] = {"read": 0, "failed": 0, **{name: 0 for name in told.values()}}

    async def one() -> None:
        try:
            async with Client(url, timeout=10) as client:
                ns = await client.get_namespace_index(NAMESPACE_URI)
                await client.get_node(f"ns={ns};s=n01.Method").read_value()
            counts["read"] += 1
        except UaStatusCodeError as exc:
            counts[told.get(exc.code, "failed")] += 1
        except Exception:  # noqa: BLE001 - counted: a refusal not told
            counts["failed"] += 1

    async def main() -> int:
        end, bursts = time.monotonic() + seconds, 0
        while time.monotonic() < end:
            await asyncio.gather(*(one() for _ in range(50)))
            bursts += 1
        return bursts

    bursts = asyncio.run(main())
    return {"bursts": bursts, **counts}


def storm_main(phase: str, url: str, seconds: float) -> None:
    if phase == "quiet":
        time.sleep(seconds)
        out: dict[str, Any] = {}
    else:
        out = {"idle": _idle, "churn": _churn, "malformed": _malformed, "burst": _burst}[phase](url, seconds)
    print(json.dumps(out), flush=True)


# -- the run ----------------------------------------------------------------------------

def run_storms(tmp: Path, phase_s: float, profile: Path) -> list[dict[str, Any]]:
    """Each phase's reads (count, p50, p99, worst, in seconds) and its storm's counts."""
    from eskin_industrial.bridge.config import BridgeConfig, LogSettings, NodeConfig, resolve
    from eskin_industrial.bridge.logs import EventLog
    from eskin_industrial.bridge.runtime import Bridge
    from eskin_industrial.outputs.opcua.options import OpcuaOptions

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = int(s.getsockname()[1])
    url = f"opc.tcp://127.0.0.1:{port}"
    cfg = BridgeConfig(node=(NodeConfig.of("n01", str(profile), "scene", scene="idle"),),
                       outputs={"opcua": OpcuaOptions(endpoint=url, offline_linger_s=0.0)},
                       log=LogSettings(status_every_s=0))
    log = EventLog(open(os.devnull, "w"), "plain", "error")
    br = Bridge(cfg, resolve(cfg), log).open()
    br.start()
    here = str(Path(__file__).resolve())
    out = tmp / "storm-reads.txt"
    windows: list[tuple[str, float, float, dict[str, Any]]] = []
    with open(out, "w") as f:
        reader = subprocess.Popen([sys.executable, here, "reader", url], stdin=subprocess.PIPE, stdout=f,
                                  stderr=subprocess.DEVNULL, text=True)
        try:
            deadline = time.monotonic() + 60
            while "ready" not in out.read_text():
                if time.monotonic() > deadline or reader.poll() is not None:
                    raise RuntimeError("the storms' reader did not connect")
                time.sleep(0.1)
            for phase in PHASES:
                t0 = time.time()
                proc = subprocess.run([sys.executable, here, "storm", _PHASE_ARG[phase], url, str(phase_s)],
                                      capture_output=True, text=True, timeout=phase_s + 120)
                t1 = time.time()
                lines = proc.stdout.strip().splitlines()
                counts = json.loads(lines[-1]) if lines else {"error": proc.stderr.strip()[-200:]}
                windows.append((phase, t0, t1, counts))
                time.sleep(1.0)
        finally:
            assert reader.stdin is not None
            reader.stdin.close()
            try:
                reader.wait(30)
            except subprocess.TimeoutExpired:
                reader.kill()
                reader.wait(10)
    br.stop()
    log.close()
    reads = []
    for line in out.read_text().splitlines():
        parts = line.split()
        if len(parts) == 3:
            reads.append((float(parts[0]), float(parts[1]), float(parts[2])))
    results = []
    for phase, t0, t1, counts in windows:
        took = [d for t, d, _ in reads if t0 <= t <= t1]
        lags = [lag for t, _, lag in reads if t0 <= t <= t1]
        results.append(dict(phase=phase, reads=len(took), p50=_q(took, 50), p99=_q(took, 99),
                            worst=max(took) if took else float("nan"), lag=max(lags) if lags else float("nan"),
                            counts=counts))
    return results


def _q(values: list[float], p: float) -> float:
    return float(np.percentile(values, p)) if values else float("nan")


def print_storms(results: list[dict[str, Any]]) -> None:
    print("| phase | reads | p50 ms | p99 ms | worst ms | reader's own worst lag ms | the storm |")
    print("|---|---|---|---|---|---|---|")
    for r in results:
        counts = ", ".join(f"{k} {v}" for k, v in r["counts"].items()) or "-"
        print(f"| {r['phase']} | {r['reads']} | {r['p50'] * 1e3:.1f} | {r['p99'] * 1e3:.1f} | "
              f"{r['worst'] * 1e3:.1f} | {r['lag'] * 1e3:.1f} | {counts} |", flush=True)


if __name__ == "__main__":
    if sys.argv[1] == "reader":
        reader_main(sys.argv[2])
    elif sys.argv[1] == "storm":
        storm_main(sys.argv[2], sys.argv[3], float(sys.argv[4]))
