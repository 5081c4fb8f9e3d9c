"""``bridge --check`` finds everything that can be known before the run, and the run
refuses the same things the same way: files there and readable, scenes that exist
and fit the profile, a CAN layout that carries the raw values, hosts that parse,
ports in range and free in server mode, values within their documented bounds.
Each refusal is one line naming where, and exit 2."""

from __future__ import annotations

import os
import re
import socket
from pathlib import Path

import pytest
from click.testing import CliRunner

from eskin_industrial.cli import main
from tests.helpers.modbus import free_port
from tests.helpers.paths import PROFILES, ROOT

PAPER = str(PROFILES / "paper-5x5.toml")
HAND = str(PROFILES / "hand-4x5.toml")


def run(*args: str):
    return CliRunner().invoke(main, list(args))


def refused(res, *expected: str) -> str:
    """Exit 2 and one line naming what is wrong; nothing printed on stdout."""
    lines = [line for line in res.output.splitlines() if line]
    assert res.exit_code == 2, res.output
    assert len(lines) == 1, res.output
    for text in expected:
        assert text in lines[0], res.output
    return lines[0]


def paper_with(tmp_path: Path, old: str, new: str, name: str = "p.toml") -> str:
    text = Path(PAPER).read_text()
    assert old in text, old
    path = tmp_path / name
    path.write_text(text.replace(old, new, 1))
    return str(path)


# -- sources: what the run would refuse, found by --check ------------------------------
def test_a_scene_of_another_taxel_count_is_refused_by_check_and_by_the_run_alike():
    """Before: --check passed scene:hand (20 taxels) with the 25-taxel profile; the run
    then failed with exit 1 after opening the outputs."""
    port = str(free_port())
    check = refused(run("bridge", "-p", PAPER, "--source", "scene:hand", "--plc", f"serve:{port}", "--check"),
                    "[node 'node'] scene: hand has 20 taxels", "profile paper-5x5 has 25")
    res = run("bridge", "-p", PAPER, "--source", "scene:hand", "--plc", f"serve:{port}", "--duration", "5")
    assert refused(res) == check
    assert run("bridge", "-p", HAND, "--source", "scene:hand", "--check").exit_code == 0


def test_a_can_layout_that_cannot_carry_the_raw_values_is_refused_by_check(tmp_path):
    """taxel_bits = 12 with raw values up to 20000: before, --check passed and the run
    exited 2 when it opened the bus."""
    prof = paper_with(tmp_path, "taxel_bits = 16", "taxel_bits = 12")
    for source in (["--source", "can", "-i", "virtual", "-c", "preflight"], ["--source", f"log:{PAPER}"]):
        refused(run("bridge", "-p", prof, *source, "--check"),
                "[node 'node'] profile: ", "[can] taxel_bits: 12 bits carry raw values up to 4095")
    assert run("bridge", "-p", PAPER, "--source", "can", "-i", "virtual", "-c", "preflight", "--check").exit_code == 0


def test_a_log_that_is_not_a_readable_file_is_refused_by_check_and_by_the_run(tmp_path):
    for path, why in ((tmp_path / "missing.log", "no such file"), (tmp_path, "not a file")):
        check = refused(run("bridge", "-p", PAPER, "--source", f"log:{path}", "--check"), f"path: {path}: {why}")
        assert refused(run("bridge", "-p", PAPER, "--source", f"log:{path}", "--duration", "5")) == check
    cfg = tmp_path / "b.toml"
    cfg.write_text(f'[[node]]\nname = "a"\nprofile = "{PAPER}"\nsource = "can-log"\npath = "{tmp_path}/gone.blf"\n')
    refused(run("bridge", "--config", str(cfg), "--check"), f"{cfg}: [node 'a'] path: {tmp_path}/gone.blf: no such file")


def test_a_missing_serial_device_is_refused_by_check(tmp_path):
    refused(run("bridge", "-p", PAPER, "--source", f"rtu:{tmp_path}/ttyUSB9", "--check"),
            f"serial_port: {tmp_path}/ttyUSB9: no such device")
    controller, device = os.openpty()
    try:
        assert run("bridge", "-p", PAPER, "--source", f"rtu:{os.ttyname(device)}", "--check").exit_code == 0
    finally:
        os.close(controller)
        os.close(device)


def test_folders_to_write_into_must_exist(tmp_path):
    refused(run("bridge", "-p", PAPER, "--source", "scene:case2", "--record", f"{tmp_path}/no/{{node}}.csv",
                "--check"), "[recorder] path: ", "no such folder")
    cfg = tmp_path / "b.toml"
    cfg.write_text(f'[[node]]\nname = "a"\nprofile = "{PAPER}"\ninterface = "virtual"\nchannel = "x"\n'
                   f'log = "{tmp_path}/no/traffic.blf"\n')
    refused(run("bridge", "--config", str(cfg), "--check"), "[node 'a'] log: ", "no such folder")


# -- hosts and ports --------------------------------------------------------------------
@pytest.mark.parametrize("spec, host, port", [
    ("serve:15041", "'127.0.0.1'", "15041"),  # the port; the host is the profile's bind
    ("serve::15041", "'127.0.0.1'", "15041"),
    ("serve:127.0.0.2:15041", "'127.0.0.2'", "15041"),
    ("serve:[::1]:15041", "'::1'", "15041"),
    ("tcp:plc-1.cell.example:5020", "'plc-1.cell.example'", "5020"),
])
def test_plc_specs_parse_into_host_and_port(spec, host, port):
    """Before: serve:15041 was read as host "15041" on the profile's port."""
    res = run("bridge", "-p", PAPER, "--source", "scene:case2", "--plc", spec, "--check", "--explain")
    if res.exit_code != 0 and "cannot listen" in res.output:
        pytest.skip(f"this machine cannot listen there: {res.output.strip()}")
    assert res.exit_code == 0, res.output
    got = dict(line.strip().split(" = ", 1) for line in res.output.splitlines() if line.startswith("  plc."))
    assert got["plc.port"].startswith(port + "  ") and got["plc.host"].startswith(host + "  "), res.output


@pytest.mark.parametrize("spec, expected", [
    ("tcp:999.999.1.1:502", "host: expected an IPv4 address (four numbers 0-255), got '999.999.1.1'"),
    ("tcp:1.2.3:502", "host: expected an IPv4 address"),
    ("tcp:plc..cell:502", "host: expected a host name or an IP address"),
    ("tcp:10.0.0.5:99999", "port: expected a port in [1, 65535], got 99999"),
    ("tcp:10.0.0.5:x", "port: expected a port number, got 'x'"),
    ("tcp:::1:99999", "an IPv6 address with a port goes in brackets"),
])
def test_bad_plc_specs_are_usage_errors(spec, expected):
    """Before: found only at run time, where the writer retried for ever."""
    res = run("bridge", "-p", PAPER, "--source", "scene:case2", "--plc", spec, "--check")
    assert res.exit_code == 2 and "--plc" in res.output and expected in res.output, res.output


@pytest.mark.parametrize("line, expected", [
    ('bind = "999.1.1.1"', "[modbus] plc.bind: expected an IPv4 address"),
    ('host = "127.0.0.1:502"',
     "[modbus] plc.host: expected a host without a port, got '127.0.0.1:502' (the port is a key of its own)"),
])
def test_host_fields_of_a_profile_are_parsed_at_load(tmp_path, line, expected):
    """The PLC's hosts are [plc]'s now; a profile of earlier releases that still gives
    them is checked at load as before (besides its deprecation line)."""
    prof = paper_with(tmp_path, "[modbus.plc]\n", f"[modbus.plc]\n{line}\n")
    for res, want in ((run("profile", "check", prof), f"{prof}: {expected}"),
                      (run("bridge", "-p", prof, "--source", "scene:case2", "--check"), expected)):
        lines = [x for x in res.output.splitlines() if x and "is deprecated: write [plc]" not in x]
        assert res.exit_code == 2 and len(lines) == 1 and want in lines[0], res.output


def test_host_of_plc_and_sparkplug_sections_are_parsed(tmp_path):
    cfg = tmp_path / "b.toml"
    node = f'[[node]]\nname = "a"\nprofile = "{PAPER}"\nsource = "scene"\nscene = "case2"\n'
    cfg.write_text('[plc]\nmode = "client"\nhost = "10.0.0.5:502"\n' + node)
    refused(run("bridge", "--config", str(cfg), "--check"), f"{cfg}: [plc] host: expected a host without a port")
    cfg.write_text('[sparkplug]\nbroker = "mqtt://999.1.1.1:1883"\ngroup_id = "g"\nedge_node_id = "e"\n' + node)
    refused(run("bridge", "--config", str(cfg), "--check"), f"{cfg}: [sparkplug] ", "broker host: expected an IPv4")
    cfg.write_text('[sparkplug]\nbroker = "mqtt://broker.cell:0"\ngroup_id = "g"\nedge_node_id = "e"\n' + node)
    refused(run("bridge", "--config", str(cfg), "--check"), "expected mqtt://HOST:PORT or mqtts://HOST:PORT, got 'mqtt://broker.cell:0'")


def test_a_port_in_use_is_named_by_check_and_by_the_run():
    """Before: --check passed, and the run said "Could not start listen, please check
    address"; then the run said it in other words, with exit 1, which the service
    unit restarts in a loop: now the same line and exit 2, which it does not."""
    with socket.socket() as taken:
        taken.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        why = f"cannot listen on 127.0.0.1:{port}: address already in use"
        check = run("bridge", "-p", PAPER, "--source", "scene:case2", "--plc", f"serve:127.0.0.1:{port}", "--check")
        line = refused(check, f"[plc] port: {why}")
        res = run("bridge", "-p", PAPER, "--source", "scene:case2", "--plc", f"serve:{port}", "--duration", "5",
                  "--log-level", "error")
        assert (res.exit_code, res.output.strip()) == (check.exit_code, line), res.output
    unit = (ROOT / "examples" / "deploy" / "eskin-bus-bridge.service").read_text()
    kept = re.search(r"^RestartPreventExitStatus=(.*)$", unit, re.M)
    assert kept and str(check.exit_code) in kept.group(1).split(), "the unit would restart on a port in use"
    res = run("bridge", "-p", PAPER, "--source", "scene:case2", "--plc", f"serve:127.0.0.1:{port}", "--check")
    assert res.exit_code == 0, res.output  # free again; --check let go of it
    with socket.socket() as s:
        s.bind(("127.0.0.1", port))


# -- files and bounds ----------------------------------------------------------------------
def test_a_profile_that_is_not_utf8_is_one_line(tmp_path):
    bad = tmp_path / "latin1.toml"
    bad.write_bytes(Path(PAPER).read_bytes().replace(b'name = "paper-5x5"', 'name = "Gr\u00f6\u00dfe"'.encode("latin-1")))
    line = refused(run("profile", "check", str(bad)), f"{bad}: cannot read profile: not UTF-8 text (byte ")
    assert refused(run("profile", "show", str(bad))) == line
    cfg = tmp_path / "b.toml"
    cfg.write_bytes(b'[log]\nformat = "\xff"\n')
    refused(run("bridge", "--config", str(cfg), "--check"), f"{cfg}: cannot read bridge configuration: not UTF-8")


def test_profile_show_of_a_huge_layout_is_refused_before_anything_is_allocated(tmp_path):
    """Before: rows x cols = 1e9 passed the schema and ``profile show`` died of a
    7.45 GiB MemoryError."""
    prof = paper_with(tmp_path, "rows = 5", "rows = 200000000")
    for cmd in ("check", "show"):
        refused(run("profile", cmd, prof), f"{prof}: [layout] rows: expected rows x cols at most 4096 taxels, "
                                           f"got 200000000 x 5")
    assert run("profile", "check", paper_with(tmp_path, "rows = 5", "rows = 819", "edge.toml")).exit_code == 0  # 4095
    refused(run("profile", "check", paper_with(tmp_path, "rows = 5", "rows = 820", "past.toml")), "got 820 x 5")


@pytest.mark.parametrize("old, new, expected", [
    ("rate_hz = 100.0", "rate_hz = 1e12", "[sensor] rate_hz: expected a value in [1, 100000], got 1000000000000.0"),
    ("retries = 1", "retries = 1000000", "[modbus] node.retries: expected a value in [0, 10], got 1000000"),
    ("r_scale = 100.0", "r_scale = 1e30", "[modbus] plc.r_scale: expected a value in [0.001, 10000], got 1e+30"),
    ("timeout_s = 0.05", "timeout_s = 0.05\npoll_hz = 1e9",
     "[modbus] node.poll_hz: expected a value in [1, 100000]"),
    ("timeout_s = 0.05", "timeout_s = 3600.0", "[modbus] node.timeout_s: expected a value in [0.001, 10], got 3600.0"),
    ("bitrate_bps = 1000000", "bitrate_bps = 10000000",
     "[can] bitrate_bps: expected an integer > 0 and at most 1000000, got 10000000"),
    ("refresh_s = 0.05", "refresh_s = 1e6", "[output] refresh_s: expected a value in [0.001, 60]"),
])
def test_absurd_values_are_refused_naming_file_section_and_key(tmp_path, old, new, expected):
    prof = paper_with(tmp_path, old, new)
    refused(run("profile", "check", prof), f"{prof}: {expected}")


def test_the_bounds_hold_on_the_command_line_and_in_the_bridge_configuration(tmp_path):
    refused(run("bridge", "-p", PAPER, "--source", "scene:case2", "--rate", "1e12", "--check"),
            "<command line>: [node 'node'] rate_hz: expected a number > 0 and at most 100000")
    refused(run("bridge", "-p", PAPER, "-i", "virtual", "-c", "x", "-b", "10000000", "--check"),
            "<command line>: [node 'node'] bitrate_bps: expected an integer > 0 and at most 1000000")
    cfg = tmp_path / "b.toml"
    cfg.write_text(f'queue_frames = 1000000000\n[[node]]\nname = "a"\nprofile = "{PAPER}"\nsource = "scene"\n'
                   f'scene = "case2"\n')
    refused(run("bridge", "--config", str(cfg), "--check"),
            f"{cfg}: [queue_frames]: expected an integer > 0 and at most 2000000")


@pytest.mark.parametrize("command", [["modbus-bridge", "-p", PAPER, "--recording", "x.csv", "--plc-host"],
                                     ["plc-sim", "-p", PAPER, "--host"]])
def test_host_options_of_other_commands_use_the_same_parser(command):
    """Before: modbus-bridge --plc-host 999.1.1.1 reached the writer, which retried it."""
    res = run(*command, "999.1.1.1")
    assert res.exit_code == 2 and "host: expected an IPv4 address (four numbers 0-255), got '999.1.1.1'" in res.output


def test_explain_in_server_mode_shows_the_address_listened_on(tmp_path):
    """A server listens on the profile's ``bind``, not on its PLC ``host``; before,
    --explain showed the PLC's host.  (Both deprecated there, [plc] host now, still read.)"""
    prof = paper_with(tmp_path, "[modbus.plc]\n", '[modbus.plc]\nhost = "192.168.0.10"\nbind = "127.0.0.2"\n')

    def host(*plc: str) -> str:
        res = run("bridge", "-p", prof, "--source", "scene:case2", *plc, "--check", "--explain")
        if res.exit_code != 0 and "cannot listen" in res.output:
            pytest.skip(f"this machine cannot listen there: {res.output.strip()}")
        assert res.exit_code == 0, res.output
        return next(line.strip() for line in res.output.splitlines() if line.startswith("  plc.host = "))

    assert host() == f"plc.host = '127.0.0.2'  (profile {prof})"
    assert host("--plc", "tcp:") == f"plc.host = '192.168.0.10'  (profile {prof})"


def test_a_serial_server_needs_its_device(tmp_path):
    refused(run("bridge", "-p", PAPER, "--source", "scene:case2", "--plc", f"serve-rtu:{tmp_path}/ttyS7", "--check"),
            f"[plc] serial_port: {tmp_path}/ttyS7: no such device")
