"""Sparkplug transport security on a real mosquitto: TLS with a CA and a server
certificate made by the test (``openssl``), a client certificate the broker asks for,
and usernames and passwords from a ``mosquitto_passwd`` file; the password from a file
or an environment variable, never from the command line; a wrong one is one log line,
retried with back-off, never a crash."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest

from eskin_industrial.bridge.config import BridgeConfig, LogSettings, NodeConfig
from eskin_industrial.cli.outputs import output_options
from eskin_industrial.outputs.sparkplug.kind import SparkplugKind
from eskin_industrial.outputs.sparkplug.options import SparkplugOptions
from eskin_industrial.outputs.sparkplug.transport import check_files, parse_broker, password
from tests.helpers import sparkplug as spb
from tests.helpers.bridge import PAPER, running_bridge
from tests.helpers.paths import PROFILES
from tests.helpers.sparkplug import state_home  # noqa: F401  (autouse: a state folder of its own)


def _opts(**kw) -> SparkplugOptions:
    return SparkplugOptions(kw.pop("broker", "mqtts://127.0.0.1:8883"), "g", "e", **kw)


def test_urls_and_the_rules_between_the_keys(tmp_path, monkeypatch):
    assert parse_broker("mqtts://broker.plant") == ("broker.plant", 8883, True)
    assert parse_broker("mqtt://broker.plant") == ("broker.plant", 1883, False)
    with pytest.raises(ValueError, match="expected mqtt://HOST:PORT or mqtts://HOST:PORT, got 'mqtts://h:0'"):
        parse_broker("mqtts://h:0")
    with pytest.raises(ValueError, match="ca_file: only with an mqtts:// broker"):
        _opts(broker="mqtt://h:1", ca_file="ca.pem")
    with pytest.raises(ValueError, match="cert_file: give the client certificate and its key_file together"):
        _opts(cert_file="c.pem")
    with pytest.raises(ValueError, match="password_file: give password_file or password_env, not both"):
        _opts(username="u", password_file="f", password_env="E")
    with pytest.raises(ValueError, match="a password needs a username"):
        _opts(password_env="E")
    with pytest.raises(ValueError, match="ca_file: '/nonexistent/ca.pem' does not exist"):
        check_files(_opts(ca_file="/nonexistent/ca.pem"))
    monkeypatch.delenv("ESKIN_TEST_PW", raising=False)
    with pytest.raises(ValueError, match="password_env: the environment variable ESKIN_TEST_PW is not set"):
        check_files(_opts(username="u", password_env="ESKIN_TEST_PW"))
    monkeypatch.setenv("ESKIN_TEST_PW", "s3cret")
    assert password(_opts(username="u", password_env="ESKIN_TEST_PW")) == "s3cret"
    f = tmp_path / "pw"
    f.write_text("s3cret\n")
    assert password(_opts(username="u", password_file=str(f))) == "s3cret"
    f.write_text("\n")
    with pytest.raises(ValueError, match="is empty"):
        password(_opts(username="u", password_file=str(f)))


def test_no_option_takes_the_password_itself():
    import click

    cmd = output_options(lambda **kw: None)
    flags = [f for p in click.command()(cmd).params for f in p.opts]
    assert "--sparkplug-password-file" in flags and "--sparkplug-password-env" in flags
    assert not [f for f in flags if f.endswith("password") or f == "--password"]
    with pytest.raises(ValueError, match="--sparkplug-cert-file: give the client certificate"):
        SparkplugKind.options_from_cli({"sparkplug": "mqtts://h:1", "group_id": "g", "edge_node_id": "e",
                                          "sparkplug_cert_file": "c.pem"})


def _config(opts: SparkplugOptions) -> BridgeConfig:
    return BridgeConfig((NodeConfig.of("grip", PAPER, "scene", scene="hold"),), {"sparkplug": opts},
                        LogSettings(format="json", status_every_s=0))


@pytest.mark.slow
def test_tls_with_client_certificates_and_a_password_from_the_environment(tmp_path, monkeypatch):
    certs = spb.certificates(tmp_path)
    users = spb.password_file(tmp_path, {"cell7": "right-pw", "scada": "scada-pw"})
    conf = (f"cafile {certs['ca']}\ncertfile {certs['server']}\nkeyfile {certs['server_key']}\n"
            f"require_certificate true\nallow_anonymous false\npassword_file {users}\n")
    broker = spb.Broker(tmp_path, conf_lines=conf)
    tls = ("--cafile", str(certs["ca"]), "--cert", str(certs["client"]), "--key", str(certs["client_key"]))
    cap = spb.Capture(broker.port, tmp_path / "sub.txt", *tls, "-u", "scada", "-P", "scada-pw")
    monkeypatch.setenv("ESKIN_TEST_MQTT_PW", "right-pw")
    try:
        opts = SparkplugOptions(f"mqtts://127.0.0.1:{broker.port}", "g", "e", ca_file=str(certs["ca"]),
                                cert_file=str(certs["client"]), key_file=str(certs["client_key"]),
                                username="cell7", password_env="ESKIN_TEST_MQTT_PW")
        with running_bridge(_config(opts)):
            msgs = cap.wait(lambda m: any("/DDATA/" in t for t, _ in m))
        msgs = cap.wait(lambda m: any("/NDEATH/" in t for t, _ in m))
    finally:
        cap.close()
        broker.kill()
    kinds = [t.split("/")[2] for t, _ in msgs]
    assert kinds[:2] == ["NBIRTH", "DBIRTH"] and kinds[-1] == "NDEATH"
    assert spb.parse(msgs[0][1]).seq == 0


@pytest.mark.slow
def test_a_wrong_password_is_one_line_and_retried_with_back_off(tmp_path):
    users = spb.password_file(tmp_path, {"cell7": "right-pw"})
    broker = spb.Broker(tmp_path, conf_lines=f"allow_anonymous false\npassword_file {users}\n")
    wrong = tmp_path / "wrong.pass"
    wrong.write_text("not-the-pw\n")
    try:
        opts = SparkplugOptions(f"mqtt://127.0.0.1:{broker.port}", "g", "e", username="cell7",
                                password_file=str(wrong), reconnect_min_s=0.2, reconnect_max_s=0.8)
        with running_bridge(_config(opts)) as run:
            c = lambda: run.counters("grip")  # noqa: E731
            seen: list[float] = []  # when each refusal was counted, watched from outside
            base = c()["sparkplug_failures"]
            end = time.monotonic() + 3.5
            while time.monotonic() < end:
                n = c()["sparkplug_failures"] - base
                seen += [time.monotonic()] * (n - len(seen))
                time.sleep(0.01)
            assert c()["sparkplug_connects"] == 0
            events = run.log.events()
    finally:
        broker.kill()
    gaps = [b - a for a, b in zip(seen, seen[1:])]
    # doubling from 0.2 s up to the cap of 0.8 s (a refusal takes a few ms more)
    assert len(gaps) >= 3 and all(0.15 < g < 1.3 for g in gaps) and gaps[0] < 0.6, gaps
    assert all(0.7 < g for g in gaps[-2:]), gaps
    refused = [e for e in events if e["event"] == "sparkplug_unreachable"]
    assert len(refused) == 1 and "Not authorized" in refused[0]["error"] and refused[0]["level"] == "warning"
    assert not [e for e in events if e["level"] == "error"]


@pytest.mark.slow
def test_the_command_line_reads_the_password_from_a_file(tmp_path):
    users = spb.password_file(tmp_path, {"cell7": "right-pw", "scada": "scada-pw"})
    broker = spb.Broker(tmp_path, conf_lines=f"allow_anonymous false\npassword_file {users}\n")
    cap = spb.Capture(broker.port, tmp_path / "sub.txt", "-u", "scada", "-P", "scada-pw")
    pw = tmp_path / "mqtt.pass"
    pw.write_text("right-pw\n")
    proc = subprocess.Popen([sys.executable, "-m", "eskin_industrial", "bridge", "-p", str(PROFILES / "paper-5x5.toml"),
                             "--source", "scene:case2", "--sparkplug", f"mqtt://127.0.0.1:{broker.port}",
                             "--group-id", "g", "--edge-node-id", "e", "--sparkplug-username", "cell7",
                             "--sparkplug-password-file", str(pw)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            env={**os.environ, "PYTHONPATH": os.getcwd()})
    try:
        msgs = cap.wait(lambda m: any("/DDATA/" in t for t, _ in m), timeout_s=20)
    finally:
        proc.terminate()
        proc.wait(10)
        cap.close()
        broker.kill()
    assert [t.split("/")[2] for t, _ in msgs][:2] == ["NBIRTH", "DBIRTH"]
    bad = subprocess.run([sys.executable, "-m", "eskin_industrial", "bridge", "-p", str(PROFILES / "paper-5x5.toml"),
                          "--source", "scene:case2", "--sparkplug", "mqtt://127.0.0.1:1", "--group-id", "g",
                          "--edge-node-id", "e", "--sparkplug-username", "cell7", "--sparkplug-password-env",
                          "ESKIN_TEST_UNSET_PW", "--check"], capture_output=True, text=True, timeout=60,
                         env={k: v for k, v in {**os.environ, "PYTHONPATH": os.getcwd()}.items()
                              if k != "ESKIN_TEST_UNSET_PW"})
    assert bad.returncode == 2, bad.stderr
    assert "password_env: the environment variable ESKIN_TEST_UNSET_PW is not set" in bad.stderr
