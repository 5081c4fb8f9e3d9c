"""`eskin-bus detect` as a user runs it: the real entry point in a subprocess."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from eskin_industrial.recording import read_updates, write_recording
from tests.helpers.paths import PROFILES
from tests.helpers.scenes import grasp

PAPER = str(PROFILES / "paper-5x5.toml")


def cli(*args: str, stdin: str | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "eskin_industrial", *args], input=stdin,
                          capture_output=True, text=True, timeout=120)


@pytest.fixture
def rec(tmp_path) -> Path:
    f = grasp(1000, seed=11)
    f[:200] = 0.0
    path = tmp_path / "rec.csv"
    write_recording(path, np.arange(1000) / 200.0, f)  # 200 Hz: the rate comes from t
    return path


def test_detect_writes_one_row_per_update(rec, tmp_path):
    out = tmp_path / "out.csv"
    res = cli("detect", "--profile", PAPER, "--method", "paper", str(rec), "-o", str(out))
    assert res.returncode == 0, res.stderr
    assert "200.0 Hz" in res.stderr
    cols = read_updates(out)
    assert out.read_text().startswith("t,r_coe,r_dw,state,valid")
    # 1000 frames, hop 20 samples at 200 Hz, window 80: (1000 - 80) / 20 + 1 updates
    assert len(cols["t"]) == 47
    assert set(cols["state"]) <= {"no_contact", "stable", "variable_force", "slip"}
    assert cols["state"][0] == "no_contact" and cols["state"][-1] == "stable"
    # t is the time of the newest frame used
    np.testing.assert_allclose(cols["t"][0], 79 / 200.0)


def test_stdin_stdout_and_engines_agree(rec, tmp_path):
    text = rec.read_text()
    batch = cli("detect", "-p", PAPER, "--method", "paper", "-", "-q", stdin=text)
    stream = cli("detect", "-p", PAPER, "--method", "paper", "-", "-q", "--engine", "stream", stdin=text)
    assert batch.returncode == 0 and batch.stderr == ""
    assert batch.stdout.count("\n") == 48
    # the same answer to rounding: the engines sum in different orders, so the last of
    # the ten printed digits may differ (it does under numpy 2.4); states exactly
    (tmp_path / "batch.csv").write_text(batch.stdout)
    (tmp_path / "stream.csv").write_text(stream.stdout)
    a, b = read_updates(tmp_path / "batch.csv"), read_updates(tmp_path / "stream.csv")
    assert list(a) == list(b)
    for col in a:
        if col == "state":
            assert list(a[col]) == list(b[col])
        else:
            np.testing.assert_allclose(a[col], b[col], rtol=1e-8, atol=1e-12, err_msg=col)


def test_raw_unit_csv_goes_through_calibration(tmp_path, rec):
    t = np.arange(1000) / 200.0
    f = grasp(1000, seed=11)
    f[:200] = 0.0
    raw = (1400.0 - 181.0 * f) / 0.1  # the profile's model, 0.1 ohm per LSB
    raw[:, 12] = (1392.0 - 178.5 * f[:, 12]) / 0.1  # taxel 12 has its own calibration
    write_recording(tmp_path / "raw.csv", t, raw, unit="raw")
    a = cli("detect", "-p", PAPER, str(tmp_path / "raw.csv"), "-q")
    b = cli("detect", "-p", PAPER, str(rec), "-q")
    assert a.returncode == 0, a.stderr
    ra, rb = (np.loadtxt(x.stdout.splitlines()[1:], delimiter=",", usecols=(1, 2, 5)) for x in (a, b))
    np.testing.assert_allclose(ra, rb, rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize("content,expect", [
    ("", "empty file"),
    ("time,f0\n0,1\n", "line 1: expected a header starting with 't'"),
    ("t," + ",".join(f"f{i}" for i in range(24)) + "\n", "24 taxel columns, but the profile has 25"),
    ("t," + ",".join(f"f{i}" for i in range(25)) + "\n", "no data rows"),
    ("t," + ",".join(f"f{i}" for i in range(25)) + "\n" + ",".join(["0"] * 26) + "\n0.01," + ",".join(["1"] * 10) + "\n",
     "line 3: 11 cells, expected 26"),
    ("t," + ",".join(f"f{i}" for i in range(25)) + "\n" + ",".join(["0"] * 26) + "\n0.01," + ",".join(["1"] * 12) + ",abc," + ",".join(["1"] * 12) + "\n",
     "line 3, column 14: not a number: 'abc'"),
    ("t,f0,f2\n", "line 1, column 3: expected 'f1'"),
])
def test_malformed_input_is_one_line_and_exit_2(tmp_path, content, expect):
    path = tmp_path / "bad.csv"
    path.write_text(content)
    res = cli("detect", "-p", PAPER, str(path))
    assert res.returncode == 2
    assert res.stderr.count("\n") == 1 and "Traceback" not in res.stderr
    assert expect in res.stderr and "bad.csv" in res.stderr


def test_missing_file_and_bad_profile(tmp_path, rec):
    res = cli("detect", "-p", PAPER, str(tmp_path / "nope.csv"))
    assert res.returncode == 2 and "cannot read" in res.stderr
    bad = tmp_path / "p.toml"
    bad.write_text("[sensor]\nname = 1\n")
    res = cli("detect", "-p", str(bad), str(rec))
    assert res.returncode == 2 and "[sensor] name: expected a string" in res.stderr


def test_changes_only(rec):
    full = cli("detect", "-p", PAPER, str(rec), "-q")
    changes = cli("detect", "-p", PAPER, str(rec), "-q", "--changes")
    assert changes.returncode == 0
    rows = [r.split(",") for r in full.stdout.splitlines()[1:]]
    expect = [r for i, r in enumerate(rows) if i == 0 or r[3] != rows[i - 1][3]]
    assert [r.split(",") for r in changes.stdout.splitlines()[1:]] == expect
    assert 1 < len(expect) < len(rows)
