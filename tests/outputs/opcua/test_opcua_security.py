"""OPC UA security as an integrator sets it up off loopback (here on loopback with the
same settings: the four secure endpoints, no anonymous sessions, users from a file):
a client's certificate refused and kept in rejected/ until it is trusted, then each
policy and mode with a username, refused without credentials or with a wrong
password, and a reader that cannot call a method or write.  node-opcua and asyncua's
client, each with a certificate of its own."""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest
from click.testing import CliRunner

from eskin_industrial.bridge.config import NodeConfig
from eskin_industrial.cli import main
from eskin_industrial.outputs.opcua.options import SECURE_POLICIES
from eskin_industrial.outputs.opcua.users import add_user
from tests.helpers.bridge import PAPER, running_bridge, wait_for
from tests.helpers.opcua import NAMESPACE_URI, PeerError, node_peer, opcua_config

pytestmark = pytest.mark.slow
_MODES = [tuple(p.rsplit("_", 1)) for p in SECURE_POLICIES]  # (policy, mode)


def _secured(tmp_path: Path) -> tuple[object, Path]:
    users = tmp_path / "users.toml"
    add_user(users, "op", "operator", "op-secret")
    add_user(users, "hmi", "reader", "hmi-secret")
    pki = tmp_path / "pki"
    config = opcua_config(NodeConfig.of("grip", PAPER, "scene", scene="case2"), pki_dir=str(pki),
                          security_policies=list(SECURE_POLICIES), anonymous_role="none", users_file=str(users))
    return config, pki


def test_node_opcua_is_refused_until_trusted_then_connects_with_each_policy(tmp_path: Path) -> None:
    config, pki = _secured(tmp_path)
    url = config.outputs["opcua"].endpoint
    peer_pki = str(tmp_path / "peer-pki")
    with running_bridge(config) as run, node_peer() as peer:
        assert (pki / "own" / "cert.der").is_file()  # made on first start
        assert [e["event"] for e in run.log.events("opcua_certificate_made")] == ["opcua_certificate_made"]
        endpoints = peer.ask("endpoints", url=url)["endpoints"]
        assert sorted((e["policy"], e["mode"]) for e in endpoints) == sorted(_MODES)
        assert all(e["tokens"] == ["UserName"] for e in endpoints)  # no anonymous token off loopback

        # an unknown client certificate: refused, and kept for the operator to look at
        first = peer.try_ask("connect", url=url, policy="Basic256Sha256", mode="SignAndEncrypt", pki=peer_pki,
                             user="op", password="op-secret", timeout_s=60)
        assert not first["ok"], first
        wait_for(lambda: list((pki / "rejected").glob("*.der")), 5, "the refused certificate kept")
        (kept,) = (pki / "rejected").glob("*.der")
        assert run.counters("grip")["opcua_certificates_rejected"] >= 1
        # (the bridge counts the refusal, then logs it: the line may be a moment behind)
        wait_for(lambda: run.log.events("opcua_certificate_rejected"), 5, "the refusal logged")
        rejected = run.log.events("opcua_certificate_rejected")
        assert rejected and rejected[0]["thumbprint"] == kept.stem and rejected[0]["reason"] == "BadCertificateUntrusted"

        # the operator trusts it (no restart)
        listed = CliRunner().invoke(main, ["opcua", "trust", "--pki-dir", str(pki)])
        assert listed.exit_code == 0 and f"rejected  {kept.name}" in listed.output
        moved = CliRunner().invoke(main, ["opcua", "trust", "--pki-dir", str(pki), kept.stem[:12]])
        assert moved.exit_code == 0, moved.output
        assert (pki / "trusted" / kept.name).is_file() and not kept.exists()

        for policy, mode in _MODES:
            peer.ask("connect", url=url, policy=policy, mode=mode, pki=peer_pki, user="op", password="op-secret",
                     timeout_s=60)
            ns = peer.ask("namespace", uri=NAMESPACE_URI)["index"]
            (value,) = peer.ask("read", nodeIds=[f"ns={ns};s=grip.Counters.Scans"])["values"]
            assert value["status"] == "Good", (policy, mode)
            peer.ask("close")

        # refused without credentials, and with a wrong password
        anonymous = peer.try_ask("connect", url=url, policy="Basic256Sha256", mode="SignAndEncrypt", pki=peer_pki,
                                 timeout_s=60)
        assert not anonymous["ok"]
        wrong = peer.try_ask("connect", url=url, policy="Aes128_Sha256_RsaOaep", mode="Sign", pki=peer_pki,
                             user="op", password="guess", timeout_s=60)
        assert not wrong["ok"]
        no_security = peer.try_ask("connect", url=url, user="op", password="op-secret", timeout_s=60)
        assert not no_security["ok"]  # SecurityPolicy None is not offered
        assert run.counters("grip")["opcua_logins_refused"] >= 1

        # a reader reads, and may neither call nor write
        peer.ask("connect", url=url, policy="Basic256Sha256", mode="Sign", pki=peer_pki, user="hmi",
                 password="hmi-secret", timeout_s=60)
        ns = peer.ask("namespace", uri=NAMESPACE_URI)["index"]
        (state,) = peer.ask("read", nodeIds=[f"ns={ns};s=grip.GraspState"])["values"]
        assert state["status"] != "BadUserAccessDenied"
        with pytest.raises(PeerError) as denied:
            peer.ask("call", objectId=f"ns={ns};s=grip", methodId=f"ns={ns};s=grip.AcknowledgeSlip")
        assert denied.value.status == "BadUserAccessDenied"
        write = peer.try_ask("write", nodeId=f"ns={ns};s=grip.Enabled", dataType="Boolean", value=False)
        assert not write["ok"] or write["status"] != "Good"
        peer.ask("close")
        # an operator may
        peer.ask("connect", url=url, policy="Basic256Sha256", mode="Sign", pki=peer_pki, user="op",
                 password="op-secret", timeout_s=60)
        done = peer.ask("call", objectId=f"ns={ns};s=grip", methodId=f"ns={ns};s=grip.AcknowledgeSlip")
        assert done["status"] == "Good"
        counters = run.counters("grip")
    assert counters["opcua_denied"] >= 2 and counters["opcua_commands"] == 1
    denied_events = [e for e in run.log.events("opcua_access_denied")]
    assert denied_events and denied_events[0]["user"] == "hmi"


def test_asyncua_connects_with_each_policy_and_a_user(tmp_path: Path) -> None:
    from asyncua import Client, ua
    from asyncua.crypto import security_policies as sp
    from asyncua.crypto.cert_gen import generate_private_key, generate_self_signed_app_certificate
    from asyncua.crypto.uacrypto import pem_from_key
    from cryptography import x509
    from cryptography.hazmat.primitives import serialization
    from cryptography.x509.oid import ExtendedKeyUsageOID

    config, pki = _secured(tmp_path)
    url = config.outputs["opcua"].endpoint
    uri = "urn:eskin-industrial:tests:asyncua-client"
    key = generate_private_key()
    cert = generate_self_signed_app_certificate(key, "asyncua test client", {}, [x509.UniformResourceIdentifier(uri)],
                                                [ExtendedKeyUsageOID.CLIENT_AUTH])
    cert_path, key_path = tmp_path / "client.der", tmp_path / "client.pem"
    cert_path.write_bytes(cert.public_bytes(serialization.Encoding.DER))
    key_path.write_bytes(pem_from_key(key))
    policies = {"Basic256Sha256": sp.SecurityPolicyBasic256Sha256,
                "Aes128_Sha256_RsaOaep": sp.SecurityPolicyAes128Sha256RsaOaep}

    async def session(policy: str, mode: str, user: str | None, password: str | None) -> object:
        client = Client(url, timeout=15)
        client.application_uri = uri
        if user is not None:
            client.set_user(user)
            client.set_password(password or "")
        await client.set_security(policies[policy], str(cert_path), str(key_path),
                                  mode=getattr(ua.MessageSecurityMode, mode))
        async with client:
            ns = await client.get_namespace_index(NAMESPACE_URI)
            return await client.get_node(f"ns={ns};s=grip.Method").read_value()

    with running_bridge(config):
        (pki / "trusted" / "asyncua-client.der").write_bytes(cert_path.read_bytes())
        for policy, mode in _MODES:
            got = asyncio.run(asyncio.wait_for(session(policy, mode, "op", "op-secret"), 60))
            assert got == "cof-track", (policy, mode)
        with pytest.raises(ua.UaError):  # no credentials: no anonymous token off loopback
            asyncio.run(asyncio.wait_for(session("Basic256Sha256", "SignAndEncrypt", None, None), 60))
        with pytest.raises(ua.UaError):
            asyncio.run(asyncio.wait_for(session("Basic256Sha256", "SignAndEncrypt", "op", "nope"), 60))


def test_check_names_a_certificate_of_another_server(tmp_path: Path) -> None:
    """The certificate in pki_dir must carry this server's application URI; --check and
    the run refuse one that does not, in one line."""
    config, pki = _secured(tmp_path)
    done = CliRunner().invoke(main, ["opcua", "cert", "--pki-dir", str(pki), "--endpoint", "opc.tcp://127.0.0.1:1"])
    assert done.exit_code == 0, done.output
    toml = tmp_path / "bridge.toml"
    opts = config.outputs["opcua"]
    toml.write_text(f"""
[opcua]
endpoint = "{opts.endpoint}"
pki_dir = "{pki}"
application_uri = "urn:another:server"
users_file = "{opts.users_file}"

[[node]]
name = "grip"
profile = "paper-5x5"
source = "scene"
scene = "case2"
""")
    checked = CliRunner().invoke(main, ["bridge", "--config", str(toml), "--check"])
    assert checked.exit_code == 2
    assert "[opcua] pki_dir:" in checked.output and "not 'urn:another:server'" in checked.output
    assert len(checked.output.strip().splitlines()) == 1
