"""The OPC UA output from the command line and bridge.toml: ``--check`` finds what can
be known before the run (a port in use, an unknown policy, security off beyond
loopback, a users file that is not there or not right) and the run refuses the same
in the same words; the tools of ``eskin-bus opcua``; the missing extra."""

from __future__ import annotations

import socket
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from eskin_industrial.cli import main
from eskin_industrial.outputs.base import SINKS, output_kind
from eskin_industrial.outputs.opcua import model
from tests.helpers.modbus import free_port
from tests.helpers.paths import PROFILES, ROOT

PAPER = str(PROFILES / "paper-5x5.toml")


def run(*args: str, input: str | None = None):
    return CliRunner().invoke(main, list(args), input=input)


def usage_error(res, expected: str) -> None:
    """A usage error: exit 2, the message on its one line."""
    assert res.exit_code == 2, res.output
    lines = [line for line in res.output.splitlines() if line]
    assert len(lines) == 1 and lines[0].startswith("eskin-bus: error: ") and expected in lines[0], res.output


def refused(res, *expected: str) -> str:
    lines = [line for line in res.output.splitlines() if line]
    assert res.exit_code == 2, res.output
    assert len(lines) == 1, res.output
    for text in expected:
        assert text in lines[0], res.output
    return lines[0]


def _toml(tmp_path: Path, opcua: str) -> Path:
    path = tmp_path / "bridge.toml"
    path.write_text(f"[opcua]\n{opcua}\n\n[[node]]\nname = \"grip\"\nprofile = \"paper-5x5\"\nsource = \"scene\"\n"
                    f"scene = \"case2\"\n")
    return path


def test_the_kind_is_one_registry_entry() -> None:
    assert SINKS["opcua"] == "eskin_industrial.outputs.opcua.sink:OpcuaKind"
    assert output_kind("opcua").name == "opcua"


@pytest.mark.slow
def test_check_describes_the_server(tmp_path: Path) -> None:
    port = free_port()
    res = run("bridge", "-p", PAPER, "--source", "scene:case2", "--opcua", f"opc.tcp://127.0.0.1:{port}",
              "--opcua-frame-interval", "0.5", "--check")
    assert res.exit_code == 0, res.output
    assert (f"OPC UA opc.tcp://127.0.0.1:{port} Machines/node (None; no users; anonymous operator, Taxels every "
            f"0.5 s (5 x 5))") in res.output


@pytest.mark.slow
def test_check_and_the_run_refuse_a_port_in_use() -> None:
    with socket.socket() as taken:
        taken.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        why = f"[opcua] endpoint: cannot listen on 127.0.0.1:{port}: address already in use"
        args = ("bridge", "-p", PAPER, "--source", "scene:case2", "--opcua", f"opc.tcp://127.0.0.1:{port}")
        refused(run(*args, "--check"), why)
        res = run(*args, "--duration", "5", "--log-level", "error")
        assert res.exit_code == 2 and f"eskin-bus: error: {why}" in res.output, res.output


@pytest.mark.parametrize(("opcua", "expected"), [
    ('endpoint = "opc.tcp://127.0.0.1:4840"\nsecurity_policies = ["Basic128Rsa15_Sign"]',
     "[opcua] security_policies: expected one of None, Basic256Sha256_Sign"),
    ('endpoint = "opc.tcp://0.0.0.0:4840"\npki_dir = "pki"',
     "[opcua] users_file: on 0.0.0.0, not loopback, clients log in as users"),
    ('endpoint = "opc.tcp://0.0.0.0:4840"\nsecurity_policies = ["None"]\nusers_file = "u.toml"',
     "[opcua] security_policies: 'None' on 0.0.0.0, not loopback: only with allow_insecure = true"),
    ('endpoint = "opc.tcp://127.0.0.1:4840"\nsecurity_policies = ["Basic256Sha256_Sign"]',
     "[opcua] pki_dir: a secure policy needs a folder for the certificates"),
    ('endpoint = "http://127.0.0.1:4840"', "[opcua] endpoint: expected opc.tcp://HOST:PORT, got 'http://127.0.0.1:4840'"),
    ('endpoint = "opc.tcp://127.0.0.1:4840"\nframe_interval_s = 0.01',
     "[opcua] frame_interval_s: expected 0 (off) or a value in [0.05, 3600]"),
    ('endpoint = "opc.tcp://127.0.0.1:4840"\nallow_insecure = "yes"', "[opcua] allow_insecure: expected true or false"),
    ('endpoint = "opc.tcp://127.0.0.1:4840"\nmax_sesions = 4', "[opcua] max_sesions: unknown key; did you mean 'max_sessions'?"),
])
def test_bad_sections_are_one_line(tmp_path: Path, opcua: str, expected: str) -> None:
    refused(run("bridge", "--config", str(_toml(tmp_path, opcua)), "--check"), str(tmp_path / "bridge.toml"), expected)


def test_users_files_are_checked_before_the_run(tmp_path: Path) -> None:
    port = free_port()
    missing = tmp_path / "none.toml"
    conf = _toml(tmp_path, f'endpoint = "opc.tcp://127.0.0.1:{port}"\nusers_file = "{missing}"')
    why = f"users_file: {missing}: no such file"
    refused(run("bridge", "--config", str(conf), "--check"), why)
    res = run("bridge", "--config", str(conf), "--duration", "3", "--log-level", "error")
    assert res.exit_code == 2 and why in res.output, res.output
    bad = tmp_path / "users.toml"
    bad.write_text('[[user]]\nname = "hmi"\nrole = "viewer"\npassword = "x"\n')
    conf = _toml(tmp_path, f'endpoint = "opc.tcp://127.0.0.1:{port}"\nusers_file = "{bad}"')
    refused(run("bridge", "--config", str(conf), "--check"), "[[user]] 0: role: expected one of reader, operator")
    conf = _toml(tmp_path, f'endpoint = "opc.tcp://127.0.0.1:{port}"\nusers_env = "ESKIN_TEST_NO_SUCH_VARIABLE"')
    refused(run("bridge", "--config", str(conf), "--check"),
            "users_env: the environment variable ESKIN_TEST_NO_SUCH_VARIABLE is not set")


def test_the_command_line_options(tmp_path: Path) -> None:
    usage_error(run("bridge", "-p", PAPER, "--source", "scene:case2", "--opcua-pki-dir", "pki", "--check"),
                "--opcua-pki-dir: give --opcua URL too")
    usage_error(run("bridge", "-p", PAPER, "--source", "scene:case2", "--opcua", "opc.tcp://127.0.0.1:4840",
                    "--opcua-security", "None,Basic999", "--check"), "--opcua-security: expected one of None")
    res = run("bridge", "-p", PAPER, "--source", "scene:case2", "--opcua", "opc.tcp://127.0.0.1:4840",
              "--opcua-users-file", "u.toml", "--opcua-users-env", "X", "--check")
    assert res.exit_code == 2 and "give users_file or users_env, not both" in res.output
    # off loopback with allow_insecure: the plan says so
    port = free_port()
    warned = run("bridge", "-p", PAPER, "--source", "scene:case2", "--opcua", f"opc.tcp://0.0.0.0:{port}",
                 "--opcua-allow-insecure", "--check")
    assert warned.exit_code == 0, warned.output
    assert "WARNING: open off loopback: SecurityPolicy None, anonymous sessions (operator)" in warned.output
    assert "--opcua-password" not in run("bridge", "--help").output  # no option takes a secret


def test_user_add_never_takes_the_password_as_an_option(tmp_path: Path) -> None:
    users = tmp_path / "users.toml"
    res = run("opcua", "user", "add", str(users), "scada", "--role", "reader", input="s3cret\n")
    assert res.exit_code == 0, res.output
    assert "s3cret" not in users.read_text() and 'role = "reader"' in users.read_text()
    usage_error(run("opcua", "user", "add", str(users), "x", "--role", "admin", input="pw\n"), "--role")
    assert run("opcua", "user", "add", str(users), "x", "--role", "reader", "--password", "pw").exit_code == 2


def test_cert_refuses_to_replace_without_force(tmp_path: Path) -> None:
    pki = tmp_path / "pki"
    made = run("opcua", "cert", "--pki-dir", str(pki), "--endpoint", "opc.tcp://127.0.0.1:4840")
    assert made.exit_code == 0 and "thumbprint" in made.output, made.output
    again = run("opcua", "cert", "--pki-dir", str(pki))
    assert again.exit_code == 2 and "--force replaces it" in again.output
    assert run("opcua", "cert", "--pki-dir", str(pki), "--force").exit_code == 0
    assert (pki / "own" / "private" / "key.pem").stat().st_mode & 0o777 == 0o600


def test_a_missing_extra_reads_like_the_others(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setitem(sys.modules, "asyncua", None)
    res = run("bridge", "-p", PAPER, "--source", "scene:case2", "--opcua", f"opc.tcp://127.0.0.1:{free_port()}",
              "--duration", "1")
    assert res.exit_code == 4
    assert res.output.strip() == "eskin-bus: error: the opcua output needs asyncua: pip install 'eskin-industrial[opcua]'"
    res = run("opcua", "nodeset", "-o", str(tmp_path / "x.xml"))
    assert res.exit_code == 4 and "eskin-bus opcua nodeset needs asyncua" in res.output


def test_the_model_in_the_docs_is_the_code() -> None:
    text = (ROOT / "docs" / "opcua.md").read_text()
    assert "\n".join(model.model_tree()) in text
    assert "\n".join(model.variable_table()) in text
