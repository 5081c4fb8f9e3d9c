"""A recorder whose disk fills: the bridge logs it once, goes on, and the file ends on
its last whole row (before: the CSV was cut mid-line, nothing logged, exit 0 with
``record_write_errors`` only in the counters).  The disk is filled for real: the
bridge runs under a file-size limit (RLIMIT_FSIZE), so that the kernel refuses the
write past it as a full disk would (EFBIG after a short write; SIGXFSZ, which
Python ignores, kills nothing)."""

from __future__ import annotations

import json
import resource
import subprocess
import sys

from tests.helpers.modbus import free_port
from tests.helpers.paths import PROFILES

LIMIT_BYTES = 10_000


def _limit() -> None:
    resource.setrlimit(resource.RLIMIT_FSIZE, (LIMIT_BYTES, LIMIT_BYTES))


def test_a_full_disk_is_logged_once_and_the_record_ends_on_a_whole_row(tmp_path):
    out = tmp_path / "grip.csv"
    res = subprocess.run([sys.executable, "-m", "eskin_industrial", "bridge", "-p", str(PROFILES / "paper-5x5.toml"),
                          "--source", "scene:case2", "--plc", f"serve:127.0.0.1:{free_port()}", "--record", str(out),
                          "--duration", "4", "--log-format", "json"],
                         capture_output=True, text=True, timeout=60, preexec_fn=_limit)
    assert res.returncode == 0, res.stderr[-3000:]  # the recorder's degraded mode: the bridge goes on
    events = [json.loads(line) for line in res.stderr.splitlines() if line.startswith("{")]
    failed = [e for e in events if e["event"] == "record_write_failed"]
    assert len(failed) == 1 and failed[0]["level"] == "error" and failed[0]["path"] == str(out), res.stderr[-3000:]
    final = next(e for e in events if e["event"] == "final")
    assert final["record_write_errors"] >= 1 and final["record_lost_rows"] >= 1
    data = out.read_bytes()
    assert 0 < len(data) <= LIMIT_BYTES and data.endswith(b"\n"), data[-200:]
    rows = data.decode().splitlines()
    width = rows[0].count(",")
    assert all(r.count(",") == width for r in rows), "a row cut short"
    assert final["recorded_updates"] == len(rows) - 1 + final["record_lost_rows"]
