"""One parser for hosts and ports (``eskin_industrial.netaddr``), used by the profile,
the bridge configuration, ``--plc``, ``--serve`` and the Sparkplug broker."""

from __future__ import annotations

import socket

import pytest

from eskin_industrial.netaddr import check_host, listen_problem, parse_endpoint


@pytest.mark.parametrize("host", ["10.0.0.5", "::1", "fe80::1%eth0", "plc-1", "plc-1.cell.example", "localhost",
                                  "192.168.0.10", "a" * 63 + ".example"])
def test_hosts_that_parse(host):
    assert check_host(host) == host


@pytest.mark.parametrize("host, why", [
    ("999.999.1.1", "expected an IPv4 address"),
    ("999.1.1.1", "expected an IPv4 address"),
    ("1.2.3", "expected an IPv4 address"),
    ("127.0.0.1:502", "expected a host without a port"),
    ("plc.cell:502", "expected a host without a port"),
    ("plc..cell", "expected a host name or an IP address"),
    ("-plc", "expected a host name or an IP address"),
    ("plc_1", "expected a host name or an IP address"),
    ("[::1]", "expected a host name or an IP address"),
    ("", "expected a host name or an IP address"),
    ("a" * 64 + ".example", "expected a host name or an IP address"),
])
def test_hosts_that_do_not_parse_name_the_field(host, why):
    with pytest.raises(ValueError, match=r"^bind: " + why):
        check_host(host, "bind")


@pytest.mark.parametrize("text, expected", [
    ("15041", (None, 15041)),
    (":15041", (None, 15041)),
    ("127.0.0.1:1502", ("127.0.0.1", 1502)),
    ("[::1]:1502", ("::1", 1502)),
    ("[::1]", ("::1", None)),
    ("::1", ("::1", None)),
    ("plc.cell", ("plc.cell", None)),
    ("", (None, None)),
])
def test_endpoints(text, expected):
    assert parse_endpoint(text) == expected


@pytest.mark.parametrize("text, why", [
    ("plc.cell", "address: expected HOST:PORT, :PORT or PORT"),
    ("", "address: expected HOST:PORT, :PORT or PORT"),
    ("host:0", r"port: expected a port in \[1, 65535\], got 0"),
    ("host:65536", r"port: expected a port in \[1, 65535\], got 65536"),
    ("[::1", "address: expected"),
    ("[::1]x", "address: expected"),
    ("::1:99999", r"address: expected .* goes in brackets: \[::1\]:502\)"),
])
def test_endpoints_that_need_a_port(text, why):
    with pytest.raises(ValueError, match=r"^--serve " + why):
        parse_endpoint(text, require_port=True, field="--serve")


def test_listen_problem_names_the_address_and_the_reason():
    with socket.socket() as taken:
        taken.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        assert listen_problem("127.0.0.1", port) == f"cannot listen on 127.0.0.1:{port}: address already in use"
    assert listen_problem("127.0.0.1", port) is None
