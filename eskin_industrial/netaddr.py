"""Hosts and ports as a configuration or a command line gives them: one parser for
every place (a profile's ``[modbus.plc] host`` and ``bind``, ``[plc] host``, ``--plc``,
``--serve``, a Sparkplug broker), so that a bad one is refused before the run, with
one line, instead of being retried for ever.

A host is an IPv4 address, an IPv6 address (bare in a host field, in brackets next to
a port: ``[::1]:502``) or a DNS name.  A name whose last label is all digits is meant
as an IPv4 address and must be one (``999.999.1.1`` is refused; no top-level domain
is numeric, RFC 3696).  ``HOST:PORT`` in a host field is refused with the field named:
the port has its own key.
"""

from __future__ import annotations

import ipaddress
import os
import re
import socket

_LABEL = re.compile(r"[A-Za-z0-9](?:[A-Za-z0-9-]{0,61}[A-Za-z0-9])?")


def check_host(text: str, field: str = "host") -> str:
    """``text`` when it is a host (see the module); ValueError ``FIELD: ...`` otherwise."""
    if not isinstance(text, str) or not text:
        raise ValueError(f"{field}: expected a host name or an IP address, got {text!r}")
    try:
        ipaddress.ip_address(text)
        return text
    except ValueError:
        pass
    head, sep, tail = text.rpartition(":")
    if sep and tail.isdigit() and head and ":" not in head.strip("[]"):
        raise ValueError(f"{field}: expected a host without a port, got {text!r} (the port is a key of its own)")
    labels = text[:-1].split(".") if text.endswith(".") else text.split(".")
    if labels[-1].isdigit():
        raise ValueError(f"{field}: expected an IPv4 address (four numbers 0-255), got {text!r}")
    if len(text) > 253 or not all(_LABEL.fullmatch(label) for label in labels):
        raise ValueError(f"{field}: expected a host name or an IP address, got {text!r}")
    return text


def check_port(text: str | int, field: str = "port") -> int:
    """A TCP port, 1 to 65535; ValueError ``FIELD: ...`` otherwise."""
    if isinstance(text, int) and not isinstance(text, bool):
        port = text
    elif isinstance(text, str) and text.isdigit():
        port = int(text)
    else:
        raise ValueError(f"{field}: expected a port number, got {text!r}")
    if not 0 < port < 65536:
        raise ValueError(f"{field}: expected a port in [1, 65535], got {port}")
    return port


def parse_endpoint(text: str, require_port: bool = False, field: str = "") -> tuple[str | None, int | None]:
    """``HOST:PORT``, ``[IPV6]:PORT``, ``:PORT``, ``PORT`` (digits alone are a port),
    ``HOST`` or nothing (when the port is not required): None for what is left out,
    for the caller's default.  ValueError names ``field`` and what is wrong."""
    name = f"{field} " if field else ""
    what = "HOST:PORT, :PORT or PORT" if require_port else "HOST:PORT, HOST, :PORT or PORT"
    host: str | None
    port: str | None
    if text.startswith("["):  # [v6] or [v6]:port
        inside, close, rest = text[1:].partition("]")
        if not close or (rest and not rest.startswith(":")):
            raise ValueError(f"{name}address: expected {what}, got {text!r}")
        host, port = inside, rest[1:] if rest else None
    elif text.isdigit():
        host, port = None, text
    elif text.count(":") > 1:  # a bare IPv6 address: no port can follow it
        host, port = text, None
        try:
            ipaddress.IPv6Address(text)
        except ValueError:
            raise ValueError(f"{name}address: expected {what} (an IPv6 address with a port goes in brackets: "
                             f"[::1]:502), got {text!r}") from None
    else:
        h, sep, p = text.partition(":")
        host, port = h, (p if sep else None)
    if port is None and require_port:
        raise ValueError(f"{name}address: expected {what}, got {text!r}")
    out_port = None if port is None else check_port(port, f"{name}port")
    out_host = check_host(host, f"{name}host") if host else None
    return out_host, out_port


def listen_error(host: str, port: int, exc: OSError) -> str:
    """``cannot listen on HOST:PORT: address already in use`` (the reason in words)."""
    reason = os.strerror(exc.errno).lower() if exc.errno else str(exc)
    where = f"[{host}]:{port}" if ":" in host else f"{host}:{port}"
    return f"cannot listen on {where}: {reason}"


def listen_problem(host: str, port: int) -> str | None:
    """Bind ``host:port`` as a server would (``SO_REUSEADDR``, as asyncio sets it) and
    let go at once: None when it can, else :func:`listen_error`'s line."""
    try:
        infos = socket.getaddrinfo(host or None, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    except socket.gaierror as exc:
        return f"cannot listen on {host}:{port}: {exc.strerror}"
    family, kind, proto, _name, address = infos[0]
    with socket.socket(family, kind, proto) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(address)
        except OSError as exc:
            return listen_error(host, port, exc)
    return None
