"""``[opcua]`` of ``bridge.toml``: the server's endpoint, its security, its limits, and
what it publishes.

Security is off only on loopback: SecurityPolicy None and anonymous sessions are
offered by default when the endpoint's host is a loopback address, and elsewhere only
with ``allow_insecure = true`` (the bridge then logs a warning at start, and
``--check`` prints it).  Off loopback the default is the four secure endpoints
(Basic256Sha256 and Aes128_Sha256_RsaOaep, each with Sign and SignAndEncrypt) and
username/password users.  Nothing here reads a file: :mod:`.security` does, at
``--check`` and at open.
"""

from __future__ import annotations

import ipaddress
from dataclasses import dataclass, field
from typing import Literal
from urllib.parse import urlsplit

from ...netaddr import check_host
from ...schema import in_range

DEFAULT_PORT = 4840
FRAME_INTERVAL_MIN_S = 0.05

#: The policies this server offers, by the names of OPC UA (Part 7), with the
#: security mode after the underscore.  Basic128Rsa15 and Basic256 are deprecated by
#: the specification and not offered.
POLICIES: tuple[str, ...] = (
    "None",
    "Basic256Sha256_Sign",
    "Basic256Sha256_SignAndEncrypt",
    "Aes128_Sha256_RsaOaep_Sign",
    "Aes128_Sha256_RsaOaep_SignAndEncrypt",
)
SECURE_POLICIES = POLICIES[1:]


def parse_endpoint_url(url: str) -> tuple[str, int]:
    """``opc.tcp://HOST[:PORT]`` -> (host, port); ValueError, one line, when malformed."""
    parts = urlsplit(url)
    try:
        port = parts.port
    except ValueError:
        port = -1
    if parts.scheme != "opc.tcp" or not parts.hostname or port in (-1, 0) or parts.path not in ("", "/"):
        raise ValueError(f"expected opc.tcp://HOST:PORT, got {url!r}")
    check_host(parts.hostname, "endpoint host")
    return parts.hostname, port or DEFAULT_PORT


def is_loopback(host: str) -> bool:
    """Bound to loopback only: 127.0.0.0/8, ::1 or ``localhost``.  ``0.0.0.0`` and
    ``::`` listen on every interface: not loopback."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _policy_known(name: str) -> bool:
    return name in POLICIES


@dataclass(frozen=True)
class OpcuaOptions:
    """``[opcua]``: one server for the whole bridge, one object per node."""

    #: ``opc.tcp://HOST:PORT``: where the server listens (and the URL it gives out).
    endpoint: str = f"opc.tcp://127.0.0.1:{DEFAULT_PORT}"
    #: The endpoints offered (:data:`POLICIES`); unset: ``None`` on loopback (or with
    #: ``allow_insecure``), and the four secure ones where a ``pki_dir`` is given.
    security_policies: tuple[str, ...] | None = field(default=None, metadata={"check": (
        _policy_known, "one of " + ", ".join(POLICIES))})
    #: The application instance certificate and the trust lists: ``own/``, ``trusted/``,
    #: ``rejected/`` (made on first start; ``eskin-bus opcua cert``).
    pki_dir: str | None = None
    #: SecurityPolicy None and anonymous sessions off loopback (a warning at start).
    allow_insecure: bool = False
    #: What an anonymous session may do where anonymous sessions are allowed;
    #: ``none``: no anonymous session at all.
    anonymous_role: Literal["none", "reader", "operator"] = "operator"
    #: Username/password users: a TOML file (``eskin-bus opcua user``), or an
    #: environment variable of ``NAME:ROLE:PASSWORD`` lines.  Never a command-line value.
    users_file: str | None = None
    users_env: str | None = None
    #: No method call from anyone (the PLC's ``read_only``): every command refused.
    read_only: bool = False
    #: The application's name and URI (the certificate's subject alternative name
    #: carries the URI); unset URI: ``urn:HOSTNAME:eskin-industrial:bridge``.
    application_name: str = "eskin-bus bridge"
    application_uri: str | None = None
    #: Connections at once (each holds at most a session), and how long a client may
    #: take to activate its session after connecting.
    max_sessions: int = field(default=16, metadata=in_range(1, 1000))
    activation_timeout_s: float = field(default=10.0, metadata=in_range(0.5, 600))
    #: Connections at once that have sent their Hello but not activated a session yet
    #: (the next is told BadTcpServerTooBusy), and how long a new socket may take to
    #: send a complete Hello (then BadTimeout): a socket that has not is held apart and
    #: counts against no limit, so that idle sockets cannot keep a client out.
    max_pending: int = field(default=8, metadata=in_range(1, 1000))
    hello_timeout_s: float = field(default=2.0, metadata=in_range(0.1, 60))
    #: The longest session timeout granted (a client that vanishes is dropped after it).
    session_timeout_s: float = field(default=60.0, metadata=in_range(1, 3600))
    max_subscriptions: int = field(default=64, metadata=in_range(1, 10000))
    #: The taxel frame (``Taxels``, a Float matrix) at most this often; 0: never (the
    #: variable is not there).
    frame_interval_s: float = field(default=0.0, metadata={"check": (
        lambda v: v == 0 or FRAME_INTERVAL_MIN_S <= v <= 3600,
        f"0 (off) or a value in [{FRAME_INTERVAL_MIN_S:g}, 3600]")})
    #: A stale sensor's values read UncertainLastUsableValue until its newest scan is
    #: this old, then BadNoCommunication (a silent sensor is not a usable last value).
    bad_after_s: float = field(default=1.0, metadata=in_range(0, 3600))
    #: On shutdown: keep serving the BadOutOfService values this long, so that a
    #: subscribed client is told before the connection goes.
    offline_linger_s: float = field(default=0.5, metadata=in_range(0, 60))
    #: The slip alarm's severity (1..1000; 800 and up: high, as SCADA shows it).
    alarm_severity: int = field(default=800, metadata=in_range(1, 1000))

    def __post_init__(self) -> None:
        try:
            host, _ = parse_endpoint_url(self.endpoint)
        except ValueError as exc:
            text = str(exc)
            raise ValueError(text if text.startswith("endpoint") else f"endpoint: {text}") from None
        if self.users_file is not None and self.users_env is not None:
            raise ValueError("users_file: give users_file or users_env, not both")
        policies = self.policies()
        if not policies and self.security_policies is None:
            raise ValueError(f"pki_dir: on {host}, not loopback, the secure endpoints need a folder for the "
                             f"certificates (pki_dir)")
        if not policies:
            raise ValueError("security_policies: expected at least one policy")
        if len(set(policies)) != len(policies):
            raise ValueError("security_policies: a policy is named twice")
        if any(p != "None" for p in policies) and self.pki_dir is None:
            raise ValueError("pki_dir: a secure policy needs a folder for the certificates (pki_dir)")
        if not self.loopback and not self.allow_insecure:
            if "None" in policies:
                raise ValueError(f"security_policies: 'None' on {host}, not loopback: only with allow_insecure = "
                                 f"true")
            if self.users_file is None and self.users_env is None:
                raise ValueError(f"users_file: on {host}, not loopback, clients log in as users: give users_file "
                                 f"or users_env (anonymous sessions: only with allow_insecure = true)")

        if not self.anonymous and self.users_file is None and self.users_env is None:
            raise ValueError("users_file: no anonymous sessions and no users: no client could log in")

    @property
    def host(self) -> str:
        return parse_endpoint_url(self.endpoint)[0]

    @property
    def port(self) -> int:
        return parse_endpoint_url(self.endpoint)[1]

    @property
    def loopback(self) -> bool:
        return is_loopback(self.host)

    def policies(self) -> tuple[str, ...]:
        """The endpoints offered (the default resolved)."""
        if self.security_policies is not None:
            return self.security_policies
        none = ("None",) if self.loopback or self.allow_insecure else ()
        return none + (SECURE_POLICIES if self.pki_dir is not None else ())

    @property
    def anonymous(self) -> bool:
        """Anonymous sessions are offered: loopback or allow_insecure, and a role."""
        return self.anonymous_role != "none" and (self.loopback or self.allow_insecure)

    def insecure(self) -> list[str]:
        """What is open beyond loopback (the start's warning, ``--check``'s line)."""
        if self.loopback:
            return []
        out = []
        if "None" in self.policies():
            out.append("SecurityPolicy None")
        if self.anonymous:
            out.append(f"anonymous sessions ({self.anonymous_role})")
        return out

