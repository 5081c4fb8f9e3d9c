"""``[supervision]`` of ``bridge.toml``: which outputs are essential (on the loop's
thread) and what an output's failure does; a bad key is one line naming the file and
the key, from the loader and from ``bridge --check``."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from eskin_industrial.bridge.config import load_bridge_config
from eskin_industrial.bridge.runtime import policy_of
from eskin_industrial.errors import ProfileError
from tests.helpers.bridge import PAPER

BASE = f"""
[plc]
mode = "server"
host = "127.0.0.1"
port = 1502

[recorder]
path = "rec.csv"

[[node]]
name = "grip"
profile = "{PAPER}"
source = "scene"
scene = "case2"
"""


def _write(tmp_path: Path, extra: str) -> Path:
    path = tmp_path / "bridge.toml"
    path.write_text(BASE + extra)
    return path


def test_by_default_the_plc_is_essential_and_every_output_restarts(tmp_path: Path) -> None:
    config = load_bridge_config(_write(tmp_path, ""))
    plc, recorder = policy_of(config, "plc"), policy_of(config, "recorder")
    assert plc.essential and not recorder.essential
    assert plc.on_failure == recorder.on_failure == "restart"
    assert (recorder.backoff_s, recorder.backoff_max_s, recorder.hang_s) == (1.0, 30.0, 5.0)


def test_global_keys_and_one_outputs_own(tmp_path: Path) -> None:
    config = load_bridge_config(_write(tmp_path, """
[supervision]
essential = ["plc", "recorder"]
backoff_s = 0.5
backoff_max_s = 8.0
hang_s = 2.0
[supervision.output.recorder]
on_failure = "stop"
backoff_s = 2.0
"""))
    plc, recorder = policy_of(config, "plc"), policy_of(config, "recorder")
    assert recorder.essential and recorder.on_failure == "stop" and recorder.backoff_s == 2.0
    assert recorder.backoff_max_s == 8.0 and recorder.hang_s == 2.0
    assert plc.on_failure == "restart" and plc.backoff_s == 0.5


@pytest.mark.parametrize(("extra", "expected"), [
    ('[supervision]\nessential = ["plcc"]', "[supervision] essential: 'plcc' is no output kind; did you mean 'plc'?"),
    ('[supervision]\non_failure = "ignore"', "[supervision] on_failure: expected one of 'restart', 'stop'"),
    ("[supervision]\nhang_s = 0", "[supervision] hang_s: expected a value in [0.05, 600], got 0"),
    ("[supervision]\nbackoff_s = 5.0\nbackoff_max_s = 1.0", "[supervision] backoff_max_s: expected at least backoff_s"),
    ("[supervision]\nbackof_s = 1.0", "[supervision] backof_s: unknown key; did you mean 'backoff_s'?"),
    ('[supervision.output.opcu]\non_failure = "stop"', "[supervision] output: 'opcu' is no output kind; did you mean 'opcua'?"),
    ("[supervision.output.recorder]\nbackoff_max_s = 0.5", "output.recorder.backoff_max_s: expected at least backoff_s"),
])
def test_each_bad_key_is_one_line_naming_file_and_key(tmp_path: Path, extra: str, expected: str) -> None:
    path = _write(tmp_path, extra)
    with pytest.raises(ProfileError) as err:
        load_bridge_config(path)
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith(f"{path}: "), msg
    assert expected in msg, msg


def test_check_refuses_a_bad_supervision_key_with_one_line(tmp_path: Path) -> None:
    path = _write(tmp_path, '[supervision]\non_failure = "ignore"')
    res = subprocess.run([sys.executable, "-m", "eskin_industrial", "bridge", "--config", str(path), "--check"],
                         capture_output=True, text=True, timeout=60, env=dict(os.environ, PYTHONUNBUFFERED="1"))
    assert res.returncode == 2, res.stderr
    (line,) = res.stderr.splitlines()
    assert line.startswith("eskin-bus: error: ") and "[supervision] on_failure:" in line, line
