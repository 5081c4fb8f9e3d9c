"""A full disk under the files the outputs open: the bridge says so in one line and
goes on, and a PLC reading the served block beside it sees the sensor's data, valid,
the slip in it.  Before: a Sparkplug store on a full disk at start was a 45-line
``sqlite3.OperationalError: disk I/O error`` traceback from ``Forwarder.__init__``,
exit 1, and the PLC never served; a store that filled mid-run dropped every message
of the outage from then on; an OPC UA server that could not write its certificate
stopped the bridge the same way.

The disk fills for real: the bridge runs under a file-size limit (RLIMIT_FSIZE), so
that the kernel refuses a write past it as a full disk would (EFBIG; SIGXFSZ
ignored).  Its log comes through a pipe (a pipe has no size limit); a real mosquitto
receives the Sparkplug data, ``mosquitto_sub`` decodes nothing but stores it."""

from __future__ import annotations

import json
import resource
import signal
import sqlite3
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

from eskin_industrial.outputs.plc.image import Status
from eskin_industrial.outputs.sparkplug.metrics import DEVICE_METRICS
from eskin_industrial.recording import write_recording
from tests.helpers import sparkplug as spb
from tests.helpers.bridge import BlockPoller, wait_for
from tests.helpers.modbus import free_port, need, slip_recording
from tests.helpers.paths import PROFILES
from tests.helpers.sparkplug import state_home  # noqa: F401  (autouse: a state folder of its own)

PAPER = str(PROFILES / "paper-5x5.toml")
FORCE_N = 6.0  #: the recording's total force: what a valid read of the sensor's data shows
STATE_CODE = 1000 + next(i for i, m in enumerate(DEVICE_METRICS) if m.name == "State Code")
SLIP = 3


def _limit(n_bytes: int) -> Any:
    def apply() -> None:  # (the soft limit only: :meth:`Run.free_the_disk` lifts it)
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (n_bytes, resource.RLIM_INFINITY))
    return apply


class Run:
    """The bridge as a subprocess under a file-size limit; its JSON log lines as they come."""

    def __init__(self, tmp: Path, limit: int, *args: str, still_s: float = 1.5, after_s: float = 4.0) -> None:
        t, f, self.onset = slip_recording(still_s=still_s, slip_s=0.3, after_s=after_s, force=FORCE_N)
        rec = tmp / "slip.csv"
        write_recording(rec, t, f)
        self.plc_port = free_port()
        duration = f"{still_s + 0.3 + after_s:g}"  # the recording's length (it ends there)
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "eskin_industrial", "bridge", "-p", PAPER, "--source", f"recording:{rec}",
             "--plc", f"serve:127.0.0.1:{self.plc_port}", "--log-format", "json", "--status-every", "0",
             "--duration", duration, *args],
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, preexec_fn=_limit(limit))
        self.lines: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stderr is not None
        for line in self.proc.stderr:
            self.lines.append(line.rstrip("\n"))

    def events(self, name: str | None = None) -> list[dict[str, Any]]:
        out = [json.loads(line) for line in list(self.lines) if line.startswith("{")]
        return out if name is None else [e for e in out if e["event"] == name]

    def poller(self) -> BlockPoller:
        """A PLC reading the block, once the server listens (it never does if the bridge died)."""
        import socket

        deadline = time.monotonic() + 20
        while True:
            assert self.proc.poll() is None, "\n".join(self.lines[-60:])
            with socket.socket() as s:
                if s.connect_ex(("127.0.0.1", self.plc_port)) == 0:
                    break
            assert time.monotonic() < deadline, "the PLC block is not served"
            time.sleep(0.05)
        return BlockPoller(self.plc_port, every_s=0.01)

    def free_the_disk(self) -> None:
        """The file-size limit lifted, as a disk that has room again."""
        resource.prlimit(self.proc.pid, resource.RLIMIT_FSIZE, (resource.RLIM_INFINITY, resource.RLIM_INFINITY))

    def saw_slip(self) -> None:
        """The bridge logged the slip, and the PLC had a moment to read it."""
        wait_for(lambda: any(e.get("state") == "slip" for e in self.events("state")), timeout_s=15, what="the slip")
        time.sleep(0.5)

    def finish(self, timeout_s: float = 30) -> int:
        try:
            rc = self.proc.wait(timeout_s)
        finally:
            if self.proc.poll() is None:
                self.proc.kill()
                self.proc.wait(5)
        self._reader.join(5)
        return rc

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(5)
        self._reader.join(5)
        if self.proc.stderr is not None:
            self.proc.stderr.close()


@contextmanager
def bridge(tmp: Path, limit: int, *args: str, **kw: Any) -> Iterator[Run]:
    run = Run(tmp, limit, *args, **kw)
    try:
        yield run
    finally:
        run.close()


def every_line_is_one_event(run: Run) -> None:
    """Nothing but log lines: no traceback, every failure one line."""
    assert not any("Traceback" in line for line in run.lines), "\n".join(run.lines[-60:])
    assert all(line.startswith("{") for line in run.lines), [line for line in run.lines if not line.startswith("{")]


def the_plc_read_the_sensor(reads: list[tuple[float, int, float, int]]) -> None:
    """Valid reads, each of the sensor's force, and the slip among them."""
    valid = [(status, f_sum) for _, status, f_sum, _ in reads if status & Status.DATA_VALID]
    assert len(valid) > 50, f"{len(valid)} valid reads of {len(reads)}"
    wrong = [(status, f_sum) for status, f_sum in valid if abs(f_sum - FORCE_N) > 0.5]
    assert not wrong, f"DATA_VALID on data that is not the sensor's: {wrong[:5]}"
    assert any(status & Status.SLIP for status, _ in valid), "the slip never reached the PLC"


def store_lines(run: Run) -> list[dict[str, Any]]:
    """The lines that report a store's failure (an error or a warning that names a fault)."""
    return [e for e in run.events() if e["event"].startswith("sparkplug_store")
            and e["event"] not in ("sparkplug_store_holding", "sparkplug_store_forwarded")]


def ddata(msgs: list[tuple[str, bytes]]) -> list[tuple[int | None, bool]]:
    """(State Code or None, historical) of every DDATA, in arrival order."""
    out = []
    for topic, body in msgs:
        if "/DDATA/" in topic:
            p = spb.parse(body)
            states = [spb.value(m) for m in p.metrics if m.alias == STATE_CODE]
            out.append((states[0] if states else None, all(m.is_historical for m in p.metrics)))
    return out


@pytest.mark.slow
def test_a_full_disk_at_start_puts_the_store_in_memory_and_the_plc_is_served(tmp_path: Path) -> None:
    """The store cannot even be made (4 kB per file: SQLite's shared memory file needs
    32 kB): one line names the file and the OS error, Sparkplug publishes to the broker,
    the PLC reads the slip."""
    store = tmp_path / "store"
    with spb.broker(tmp_path) as port:
        cap = spb.Capture(port, tmp_path / "sub.txt")
        try:
            with bridge(tmp_path, 4096, "--sparkplug", f"mqtt://127.0.0.1:{port}", "--group-id", "g",
                        "--edge-node-id", "e", "--sparkplug-store-dir", str(store)) as run:
                with run.poller() as plc:
                    run.saw_slip()
                rc = run.finish()
            msgs = cap.wait(lambda m: any(s == SLIP for s, _ in ddata(m)))
        finally:
            cap.close()
    assert rc == 0, "\n".join(run.lines[-60:])
    every_line_is_one_event(run)
    (line,) = store_lines(run)
    assert line["event"] == "sparkplug_store_in_memory" and line["level"] == "error", line
    assert line["store"] == str(store / "g-e.sqlite3") and line["error"].startswith("File too large"), line
    (final,) = run.events("final")
    assert final["sparkplug_store_in_memory"] == 1 and final["sparkplug_store_overflow"] == 0, final
    the_plc_read_the_sensor(plc.reads)
    assert ddata(msgs), "no DDATA at the broker"


@pytest.mark.slow
def test_a_disk_that_fills_mid_run_moves_the_store_to_memory_and_loses_nothing(tmp_path: Path) -> None:
    """The primary host not online yet: the node holds its data, its file fills until
    the disk refuses (48 kB per file); one line, then the rest is held in memory and,
    once the host's STATE says online, sent as historical after the births; what the
    file holds stays in it, whole, and the next start on the same folder sends it.  The
    PLC reads the slip throughout."""
    store = tmp_path / "store"
    with spb.broker(tmp_path) as port:
        cap = spb.Capture(port, tmp_path / "sub.txt")
        try:
            with bridge(tmp_path, 48 * 1024, "--sparkplug", f"mqtt://127.0.0.1:{port}", "--group-id", "g",
                        "--edge-node-id", "e", "--sparkplug-store-dir", str(store), "--sparkplug-primary-host",
                        "scada", still_s=1.5, after_s=7.0) as run:
                with run.poller() as plc:
                    wait_for(lambda: run.events("sparkplug_store_in_memory"), timeout_s=15, what="the file given up")
                    run.saw_slip()  # (held in memory, past the file's end)
                    state = json.dumps({"online": True, "timestamp": int(time.time() * 1000)})
                    subprocess.run([need("mosquitto_pub"), "-h", "127.0.0.1", "-p", str(port), "-q", "1", "-r",
                                    "-t", "spBv1.0/STATE/scada", "-m", state], check=True, timeout=10)
                    cap.wait(lambda m: any("/NDATA/" in t for t, _ in m), timeout_s=10)
                rc = run.finish()
            msgs = [(t, p) for t, p in cap.messages() if "/STATE/" not in t]
        finally:
            cap.close()
    assert rc == 0, "\n".join(run.lines[-60:])
    every_line_is_one_event(run)
    (line,) = store_lines(run)
    assert line["event"] == "sparkplug_store_in_memory" and line["error"].startswith("File too large"), line
    left = line["left_on_disk"]
    assert left >= 1, line
    (final,) = run.events("final")
    assert final["sparkplug_store_overflow"] == 0 and final["sparkplug_store_left_on_disk"] == left, final
    in_memory = final["sparkplug_store_held"] - left
    assert in_memory >= 1 and final["sparkplug_store_forwarded"] == in_memory, final
    kinds = [t.split("/")[2] for t, _ in msgs]
    assert kinds[:2] == ["NBIRTH", "DBIRTH"], kinds[:5]
    historical = [s for s, h in ddata(msgs) if h]
    assert len(historical) == in_memory, (len(historical), final)
    the_plc_read_the_sensor(plc.reads)
    # The file: whole, what it held when given up, sent by the next start
    with sqlite3.connect(store / "g-e.sqlite3") as db:
        assert db.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
        assert db.execute("SELECT COUNT(*) FROM held").fetchone()[0] == left
    from eskin_industrial.outputs.sparkplug.kind import open_edge
    from eskin_industrial.outputs.sparkplug.options import SparkplugOptions

    with spb.broker(tmp_path) as port2:
        cap2 = spb.Capture(port2, tmp_path / "sub2.txt")
        again = open_edge(SparkplugOptions(f"mqtt://127.0.0.1:{port2}", "g", "e", store_dir=str(store)),
                          [("node", {})])
        try:
            again.start()
            msgs2 = cap2.wait(lambda m: any("/NDATA/" in t for t, _ in m))
        finally:
            again.close()
            cap2.close()
    assert [h for _, h in ddata(msgs2)] == [True] * left
    # the outage's slip, in the file or in memory, reached a host
    assert SLIP in historical + [s for s, _ in ddata(msgs2)]


@pytest.mark.slow
def test_an_opcua_pki_dir_on_a_full_disk_is_one_line_and_the_plc_is_served(tmp_path: Path) -> None:
    """The server's certificate cannot be written (1 kB per file): one line names the
    folder and the OS error, the OPC UA output is down and tried again after its
    back-off (each try one line), the PLC reads the slip; nothing half-written is left
    for the next try to refuse, and once the disk has room the server comes up."""
    pki = tmp_path / "pki"
    with bridge(tmp_path, 1024, "--opcua", f"opc.tcp://127.0.0.1:{free_port()}", "--opcua-security",
                "Basic256Sha256_SignAndEncrypt", "--opcua-pki-dir", str(pki), after_s=40.0) as run:
        with run.poller() as plc:
            wait_for(lambda: run.events("output_restart_failed"), timeout_s=10, what="a second try")
            assert not [p for p in pki.rglob("*") if p.is_file()], "a half-written certificate or key"
            run.free_the_disk()  # (the next try comes after 2 s, doubling from the default 1 s)
            run.saw_slip()
            # a bound, not a pace: the server's start (its key made, its process up) took
            # over 9 s on a loaded machine; the recording runs 40 s, stopped once it is up
            wait_for(lambda: run.events("output_restarted"), timeout_s=35, what="the server up")
        run.proc.send_signal(signal.SIGTERM)  # a stop, with its summary
        rc = run.finish()
    assert rc == 0, "\n".join(run.lines[-60:])
    every_line_is_one_event(run)
    (failed,) = run.events("output_failed")
    assert failed["output"] == "opcua" and failed["call"] == "open", failed
    assert failed["error"] == f"OutputFileError: pki_dir: {pki}: cannot write the certificate: file too large", failed
    retries = run.events("output_restart_failed")
    assert retries and all(e["error"] == failed["error"] for e in retries), retries
    the_plc_read_the_sensor(plc.reads)
    (final,) = run.events("final")
    assert final["opcua_output_up"] == 1 and final["opcua_output_restarts"] == 1, final
    assert sorted(p.relative_to(pki).as_posix() for p in pki.rglob("*") if p.is_file()) == [
        "own/cert.der", "own/private/key.pem"]


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="no /dev/full here")
def test_a_record_on_a_full_device_is_one_line_to_the_end_and_the_plc_is_served(tmp_path: Path) -> None:
    """Every write of the record refused (``/dev/full``): one line, and no word that the
    writes work again at the end (before: ``record_write_ok`` when the last flush had
    nothing to write), the rows counted lost; the PLC reads the slip."""
    with bridge(tmp_path, 1 << 20, "--record", "/dev/full") as run:
        with run.poller() as plc:
            run.saw_slip()
        rc = run.finish()
    assert rc == 0, "\n".join(run.lines[-60:])
    every_line_is_one_event(run)
    (failed,) = run.events("record_write_failed")
    assert failed["path"] == "/dev/full" and failed["error"] == "No space left on device", failed
    assert not run.events("record_write_ok"), run.events("record_write_ok")
    (final,) = run.events("final")
    assert final["record_lost_rows"] == final["recorded_updates"] + 1, final  # (the header line too)
    the_plc_read_the_sensor(plc.reads)


def test_an_output_that_cannot_open_at_start_is_opened_later_and_takes_the_updates(tmp_path: Path) -> None:
    """The recorder's folder gone between the check and the open (in this process): the
    bridge starts all the same, one line (``output_failed``, ``call=open``), the PLC's
    block served; once the folder is back the recorder opens after its back-off and
    records the updates from then on (the loop hands them to it: it asked for them
    while not open).  Before: the bridge did not start."""
    from eskin_industrial.bridge.config import BridgeConfig, LogSettings, NodeConfig, SupervisionSettings, resolve
    from eskin_industrial.bridge.logs import EventLog
    from eskin_industrial.bridge.runtime import Bridge
    from eskin_industrial.outputs.plc.options import PlcOptions
    from eskin_industrial.outputs.recorder.kind import RecorderOptions
    from tests.helpers.bridge import LogCapture

    folder = tmp_path / "records"
    folder.mkdir()
    record = folder / "grip.csv"
    plc_port = free_port()
    config = BridgeConfig((NodeConfig.of("grip", PAPER, "scene", scene="case2"),),
                          {"plc": PlcOptions(mode="server", host="127.0.0.1", port=plc_port, offline_linger_s=0.0),
                           "recorder": RecorderOptions(str(record), flush_every_s=0.05)},
                          LogSettings(format="json", status_every_s=0),
                          supervision=SupervisionSettings(backoff_s=0.2, backoff_max_s=0.4))
    nodes = resolve(config)  # (the check: the folder is there)
    folder.rmdir()
    capture = LogCapture()
    log = EventLog(capture, "json", "debug")
    bridge = Bridge(config, nodes, log)
    try:
        bridge.open()
        bridge.start()
        (failed,) = capture.events("output_failed")
        assert failed["output"] == "recorder" and failed["call"] == "open", failed
        assert str(record) in failed["error"] and "No such file or directory" in failed["error"], failed
        with BlockPoller(plc_port, every_s=0.01) as plc:
            wait_for(lambda: any(status & Status.DATA_VALID for _, status, _, _ in plc.reads), timeout_s=10,
                     what="the block served, valid")
            folder.mkdir()
            wait_for(lambda: capture.events("output_restarted"), timeout_s=10, what="the recorder open")
            wait_for(lambda: record.exists() and len(record.read_text().splitlines()) > 20, timeout_s=10,
                     what="updates recorded")
    finally:
        bridge.stop()
        log.close()
    counters = next(s for s in bridge.runs[0].sinks if s.kind == "recorder").counters()
    assert counters["recorder_output_up"] == 1 and counters["recorder_output_failures"] == 1, counters
    assert counters["recorded_updates"] >= 20, counters
