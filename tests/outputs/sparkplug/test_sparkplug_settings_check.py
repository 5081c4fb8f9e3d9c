"""What the Sparkplug output would die of at run time is refused by ``--check`` and at
start, in one line and exit 2: TLS files that are not PEM (before: a 43-line
``ssl.SSLError`` traceback once the run began) and identifiers MQTT cannot carry
(before: a 70,000-character group id passed, and paho's thread died of
``struct.error`` with exit 0)."""

from __future__ import annotations

import subprocess
import sys

import pytest
from click.testing import CliRunner

from eskin_industrial.cli import main
from tests.helpers.paths import PROFILES

PAPER = str(PROFILES / "paper-5x5.toml")


def bridge(*args: str, broker: str = "mqtt://127.0.0.1:1883", group: str = "g", edge: str = "e") -> list[str]:
    return ["bridge", "-p", PAPER, "--source", "scene:case2", "--sparkplug", broker, "--group-id", group,
            "--edge-node-id", edge, *args]


def one_line(args: list[str]) -> str:
    """Exit 2 and one error line (a bad command-line value: click's usage lines before it)."""
    res = CliRunner().invoke(main, args)
    lines = [line for line in res.output.splitlines() if line and not line.startswith(("Usage:", "Try "))]
    assert res.exit_code == 2 and len(lines) == 1, res.output[-3000:]
    return lines[0]


@pytest.mark.parametrize(("group", "edge", "expected"), [
    ("g" * 70_000, "e", "group_id: 70000 bytes long (UTF-8); a Sparkplug id here is at most 256"),
    ("g", "\u00e9" * 200, "edge_node_id: 400 bytes long (UTF-8)"),
    ("g", "cell\x007", "edge_node_id: 'cell\\x007' holds the character U+0000"),
    ("pl+ant", "e", "group_id: 'pl+ant' is not a Sparkplug id"),
])
def test_identifiers_mqtt_cannot_carry_are_one_line_at_check(group, edge, expected):
    assert expected in one_line(bridge("--check", group=group, edge=edge))


def test_a_device_id_too_long_is_one_line_at_check(tmp_path):
    cfg = tmp_path / "bridge.toml"
    cfg.write_text(f'[sparkplug]\nbroker = "mqtt://127.0.0.1:1883"\ngroup_id = "g"\nedge_node_id = "e"\n'
                   f'[[node]]\nname = "{"n" * 300}"\nprofile = "{PAPER}"\nsource = "scene"\nscene = "case2"\n')
    assert "device id (node name): 300 bytes long" in one_line(["bridge", "--config", str(cfg), "--check"])


@pytest.mark.parametrize("key", ["ca", "cert", "key"])
def test_tls_files_that_are_not_pem_are_one_line_at_check_and_at_start(tmp_path, key):
    from tests.helpers.sparkplug import certificates

    pem = certificates(tmp_path)
    files = {"ca": pem["ca"], "cert": pem["client"], "key": pem["client_key"]}
    bad = tmp_path / f"{key}.der"
    bad.write_bytes(b"\x30\x82\x01\x0a" + bytes(range(256)))  # DER-looking bytes, not PEM
    files[key] = bad
    tls = ["--sparkplug-ca-file", str(files["ca"]), "--sparkplug-cert-file", str(files["cert"]),
           "--sparkplug-key-file", str(files["key"])]
    args = bridge(*tls, broker="mqtts://127.0.0.1:8883")
    line = one_line([*args, "--check"])
    assert f"{key}_file: '{bad}' is not a PEM" in line
    run = subprocess.run([sys.executable, "-m", "eskin_industrial", *args, "--duration", "3"],
                         capture_output=True, text=True, timeout=60)
    assert (run.returncode, run.stderr.strip()) == (2, line), run.stderr[-3000:]
