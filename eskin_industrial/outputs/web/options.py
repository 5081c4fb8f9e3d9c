"""``[web]`` of ``bridge.toml``: where the console listens, who may log in, its TLS
certificate, and the capture window kept around each episode.

Open only on loopback: off loopback the console needs TLS (``tls_cert`` and
``tls_key``) and users (``users_file``), else the configuration is refused (``--check``
says so before the run), as the OPC UA output refuses an open endpoint.
"""

from __future__ import annotations

import ipaddress
from dataclasses import dataclass, field

from ...netaddr import parse_endpoint
from ...schema import in_range

DEFAULT_BIND = "127.0.0.1:8080"
DEFAULT_PORT = 8080
#: The heat map's frames at least 25 a second, whatever the sensor's rate.
FRAME_INTERVAL_MAX_S = 0.04


def is_loopback(host: str) -> bool:
    """127.0.0.0/8, ::1 or ``localhost``; ``0.0.0.0`` and ``::`` are every interface."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


@dataclass(frozen=True)
class WebOptions:
    """``[web]``: one server for the whole bridge, one page per node."""

    #: ``HOST:PORT`` the console listens on (``[::1]:8080`` for IPv6).
    bind: str = DEFAULT_BIND
    #: Username/password users with a role (``reader``, ``operator``): the TOML file
    #: ``eskin-bus opcua user add`` writes (one file may serve both outputs).  None:
    #: no login, the console is read-only.
    users_file: str | None = None
    #: The server's certificate and private key (PEM): HTTPS and WSS.
    tls_cert: str | None = None
    tls_key: str | None = None
    #: The raw scans kept before and after an episode's start, for its download.
    capture_pre_s: float = field(default=2.0, metadata=in_range(0, 60))
    capture_post_s: float = field(default=1.0, metadata=in_range(0, 60))
    #: The heat map's frame interval (s): the sink's ``frame_every_s``.
    frame_interval_s: float = field(default=0.03, metadata=in_range(0.005, FRAME_INTERVAL_MAX_S))
    #: No command from anyone, logged in or not.
    read_only: bool = False
    #: A login session lasts this long without a request.
    session_timeout_s: float = field(default=3600.0, metadata=in_range(60, 7 * 86400))
    #: Browser connections at once (each WebSocket); beyond it a new one is refused.
    max_clients: int = field(default=32, metadata=in_range(1, 1000))

    def __post_init__(self) -> None:
        try:
            host, port = parse_endpoint(self.bind, require_port=False, field="bind")
        except ValueError as exc:
            raise ValueError(f"bind: {exc}".replace("bind: bind ", "bind: ")) from None
        if (self.tls_cert is None) != (self.tls_key is None):
            raise ValueError("tls_cert: give tls_cert and tls_key together")
        if not self.loopback:
            missing = [what for what, ok in (("TLS (tls_cert, tls_key)", self.tls), ("users (users_file)",
                                                                                     self.users_file is not None))
                       if not ok]
            if missing:
                raise ValueError(f"bind: on {self.host}, not loopback, the console needs {' and '.join(missing)}")

    @property
    def host(self) -> str:
        return parse_endpoint(self.bind, field="bind")[0] or "127.0.0.1"

    @property
    def port(self) -> int:
        return parse_endpoint(self.bind, field="bind")[1] or DEFAULT_PORT

    @property
    def loopback(self) -> bool:
        return is_loopback(self.host)

    @property
    def tls(self) -> bool:
        return self.tls_cert is not None and self.tls_key is not None

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{'https' if self.tls else 'http'}://{host}:{self.port}/"
