"""The MQTT connection's address and security: ``mqtt://`` or ``mqtts://`` (TLS with a
CA, and a client certificate and key), a username and a password read from a file or
an environment variable (never from the command line: it would show in ``ps`` and in
the shell's history)."""

from __future__ import annotations

import os
import ssl
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from ...netaddr import check_host

DEFAULT_PORTS = {"mqtt": 1883, "mqtts": 8883}


def parse_broker(url: str) -> tuple[str, int, bool]:
    """``mqtt[s]://HOST[:PORT]`` -> (host, port, tls); ValueError, one line, when malformed."""
    parts = urlsplit(url)
    try:
        port = parts.port
    except ValueError:
        port = -1
    if parts.scheme not in DEFAULT_PORTS or not parts.hostname or port in (-1, 0) or parts.path not in ("", "/"):
        raise ValueError(f"expected mqtt://HOST:PORT or mqtts://HOST:PORT, got {url!r}")
    check_host(parts.hostname, "broker host")  # the one host parser (999.1.1.1 is refused here, not retried)
    return parts.hostname, port or DEFAULT_PORTS[parts.scheme], parts.scheme == "mqtts"


def check_security(options: Any) -> None:
    """The security keys against each other (``__post_init__``: no file is read)."""
    _, _, tls = parse_broker(options.broker)
    for key in ("ca_file", "cert_file", "key_file"):
        if getattr(options, key) is not None and not tls:
            raise ValueError(f"{key}: only with an mqtts:// broker, got {options.broker!r}")
    if (options.cert_file is None) != (options.key_file is None):
        raise ValueError("cert_file: give the client certificate and its key_file together")
    if options.password_file is not None and options.password_env is not None:
        raise ValueError("password_file: give password_file or password_env, not both")
    if (options.password_file is not None or options.password_env is not None) and options.username is None:
        raise ValueError("password_file/password_env: a password needs a username")


def check_files(options: Any) -> None:
    """What the connection will read, there and readable (``--check``); ValueError ``key: what``."""
    for key in ("ca_file", "cert_file", "key_file", "password_file"):
        path = getattr(options, key)
        if path is not None and not os.access(path, os.R_OK):
            raise ValueError(f"{key}: {path!r} {'is not readable' if Path(path).exists() else 'does not exist'}")
    if options.password_env is not None and os.environ.get(options.password_env) is None:
        raise ValueError(f"password_env: the environment variable {options.password_env} is not set")
    check_pem(options)


def check_pem(options: Any) -> None:
    """The TLS files are what ``tls_set`` will load: the CA file PEM certificates, the
    client certificate a PEM certificate and the key a PEM private key (without a
    passphrase: nobody is there to type it) that goes with it; ValueError ``key: what``,
    one line, where ssl would end the run with a traceback."""
    ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
    for key in ("ca_file", "cert_file"):
        path = getattr(options, key)
        if path is None:
            continue
        try:
            ctx.load_verify_locations(cafile=path)
        except (ssl.SSLError, ValueError, OSError) as exc:
            raise ValueError(f"{key}: {path!r} is not a PEM certificate ({_reason(exc)})") from None
    if options.cert_file is not None and options.key_file is not None:
        try:
            ctx.load_cert_chain(options.cert_file, options.key_file, password=lambda: b"")
        except (ssl.SSLError, ValueError, OSError) as exc:
            raise ValueError(f"key_file: {options.key_file!r} is not a PEM private key, without a passphrase, "
                             f"of cert_file ({_reason(exc)})") from None


def _reason(exc: Exception) -> str:
    return str(getattr(exc, "reason", None) or exc).lower().replace("_", " ")


def password(options: Any) -> str | None:
    """The password from its file (the first line) or its environment variable."""
    if options.password_file is not None:
        try:
            text = Path(options.password_file).read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise ValueError(f"password_file: {options.password_file!r}: {exc}") from None
        lines = text.splitlines()
        if not lines or not lines[0]:
            raise ValueError(f"password_file: {options.password_file!r} is empty")
        return lines[0]
    if options.password_env is not None:
        value = os.environ.get(options.password_env)
        if value is None:
            raise ValueError(f"password_env: the environment variable {options.password_env} is not set")
        return value
    return None


def configure(client: Any, options: Any) -> None:
    """TLS and credentials on a paho client, before it connects."""
    _, _, tls = parse_broker(options.broker)
    if tls:
        client.tls_set(ca_certs=options.ca_file, certfile=options.cert_file, keyfile=options.key_file)
    if options.username is not None:
        client.username_pw_set(options.username, password(options))
