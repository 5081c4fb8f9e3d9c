"""The PLC server over TCP, spoken to with plain sockets and hand-built bytes (the
byte layouts of the Modbus Application Protocol Specification V1.1b3 and of Modbus
Messaging on TCP/IP), and read by mbpoll: pipelining, the write answers, report
server id, device identification, the connection cap and idle timeout, the access
policy and the tare rule."""

from __future__ import annotations

import logging
import socket
import struct
import time

import numpy as np
import pytest

from eskin_industrial.bridge.loop import NodeLoop
from eskin_industrial.bus.replay import ReplaySource
from eskin_industrial.calibration import Calibrator
from eskin_industrial.detect.state import GraspState
from eskin_industrial.modbus.tcp_server import Policy, networks
from eskin_industrial.outputs.plc.image import COIL, IMAGE_COUNT, REG, Status
from eskin_industrial.outputs.plc.server import PlcServer, identity_of
from tests.helpers.modbus import free_port, mbpoll, mbpoll_values, slip_recording
from tests.helpers.raw_modbus import adu, ask, closed_by_peer, connect, read_adu, read_registers

TARE = COIL["TARE"].offset


def served(profile, policy: Policy | None = None, **kw) -> PlcServer:
    return PlcServer(profile.modbus.plc, tcp=("127.0.0.1", free_port()), policy=policy, **kw).start()


def bridge_on(profile, server: PlcServer, force_n: float) -> NodeLoop:
    """A loop replaying a still grasp scaled to ``force_n`` in total (0: nothing held)."""
    t, f, _ = slip_recording()
    k = int(1.4 * 100)  # the still part only
    f = f[:k] * (force_n / max(f[:k].sum(axis=1).mean(), 1e-9))
    raw = Calibrator.from_section(profile.calibration, profile.taxels).to_raw(f)
    return NodeLoop(profile, ReplaySource(profile, t[:k], raw, 400.0, loop=True), [server.block(0)])


def settle(loop: NodeLoop, timeout_s: float = 10.0) -> None:
    deadline = time.monotonic() + timeout_s
    while loop.pipeline.last_update is None or not loop.pipeline.last_update.valid:
        assert time.monotonic() < deadline, "no valid verdict"
        loop.step()
    loop.publish_if_due(True)


def port_of(server: PlcServer) -> int:
    return server.server.port  # type: ignore[union-attr]


# -- framing and the answers of the specification ------------------------------------

def test_requests_sent_back_to_back_in_one_segment_are_all_answered_in_order(paper_profile):
    server = served(paper_profile)
    try:
        with connect(port_of(server)) as s:
            requests = [adu(10, 1, struct.pack(">BHH", 3, 0, 4)), adu(11, 1, struct.pack(">BHH", 1, 0, 3)),
                        adu(12, 1, struct.pack(">BHH", 4, 0, 4)), adu(13, 1, struct.pack(">BHH", 3, 500, 1)),
                        adu(14, 1, struct.pack(">BHH", 2, 0, 10))]
            blob = b"".join(requests)
            # one segment: the whole batch, and then a batch cut in the middle of a header
            s.sendall(blob)
            answers = [read_adu(s) for _ in requests]
            s.sendall(blob[:30])
            time.sleep(0.05)
            s.sendall(blob[30:])
            answers_split = [read_adu(s) for _ in requests]
        assert [a[0] for a in answers] == [10, 11, 12, 13, 14]
        assert answers == answers_split
        assert [a[2][0] for a in answers] == [3, 1, 4, 0x83, 2]
        assert answers[3][2] == bytes((0x83, 2))  # past the image: ILLEGAL DATA ADDRESS
        assert answers[0][2][2:] == answers[2][2][2:]  # FC4 mirrors the holding block
    finally:
        server.stop()


def test_write_answers_are_the_specifications(paper_profile):
    server = served(paper_profile)
    try:
        with connect(port_of(server)) as s:
            enable = REG["ENABLE"].offset
            # FC5: the response is the request, byte for byte.
            req = struct.pack(">BHH", 5, COIL["ENABLE"].offset, 0xFF00)
            assert ask(s, req) == req
            req = struct.pack(">BHH", 5, COIL["ENABLE"].offset, 0x0000)
            assert ask(s, req) == req
            assert ask(s, struct.pack(">BHH", 5, COIL["ENABLE"].offset, 0x1234)) == bytes((0x85, 3))
            # ACK_SLIP acts on 1 and reads 0: the answer is still the request, not what it reads.
            req = struct.pack(">BHH", 5, COIL["ACK_SLIP"].offset, 0xFF00)
            assert ask(s, req) == req
            # FC6: the echo too.
            req = struct.pack(">BHH", 6, enable, 1)
            assert ask(s, req) == req
            # FC15: function, starting address, quantity of outputs.
            req = struct.pack(">BHHBB", 15, COIL["ENABLE"].offset, 1, 1, 0x01)
            assert ask(s, req) == req[:5]
            assert ask(s, struct.pack(">BHHBBB", 15, 0, 3, 2, 0, 0)) == bytes((0x8F, 3))  # byte count wrong
            # FC16: function, starting address, quantity of registers.
            req = struct.pack(">BHHBH", 16, enable, 1, 2, 1)
            assert ask(s, req) == req[:5]
            # Read back: ENABLE is 1 (the last write), and the coil says the same.
            assert read_registers(s, enable, 1) == [1]
            assert ask(s, struct.pack(">BHH", 1, COIL["ENABLE"].offset, 1)) == bytes((1, 1, 1))
            assert ask(s, bytes((8, 0, 0, 0, 0))) == bytes((0x88, 1))  # diagnostics: not served
        names = [c.name for c in server.take_commands()]
        assert names == ["enable", "disable", "ack", "enable", "enable", "enable"]
    finally:
        server.stop()


def test_report_server_id_names_this_product(paper_profile):
    server = served(paper_profile)
    try:
        with connect(port_of(server)) as s:
            resp = ask(s, bytes((17,)))
        assert resp[0] == 17 and resp[1] == len(resp) - 2
        assert resp[2] == paper_profile.modbus.plc.unit_id and resp[3] == 0xFF  # server id, run indicator ON
        text = resp[4:].decode("ascii")
        assert "eskin-industrial" in text and "Pymodbus" not in text
    finally:
        server.stop()


def parse_device_id(resp: bytes) -> tuple[int, int, dict[int, str]]:
    assert resp[:2] == bytes((43, 14)), resp.hex()
    code, conformity, more, _next, n = resp[2:7]
    assert more == 0
    objects, at = {}, 7
    for _ in range(n):
        oid, length = resp[at], resp[at + 1]
        objects[oid] = resp[at + 2: at + 2 + length].decode("ascii")
        at += 2 + length
    assert at == len(resp)
    return code, conformity, objects


def test_device_identification_gives_the_mandatory_objects_of_the_identity(paper_profile):
    from eskin_industrial.identity import DeviceIdentity

    ident = DeviceIdentity(vendor_name="Acme Tactile", product_code="AT-5X5", revision="2.3",
                           vendor_url="https://acme.example")
    server = PlcServer(paper_profile.modbus.plc, tcp=("127.0.0.1", free_port()),
                       identity=identity_of(ident, paper_profile.name)).start()
    try:
        with connect(port_of(server)) as s:
            code, conformity, basic = parse_device_id(ask(s, bytes((43, 14, 1, 0))))
            _, _, regular = parse_device_id(ask(s, bytes((43, 14, 2, 0))))
            _, _, one = parse_device_id(ask(s, bytes((43, 14, 4, 5))))
            restart = ask(s, bytes((43, 14, 1, 0x40)))  # an unknown object id: the stream from the start
            missing = ask(s, bytes((43, 14, 4, 6)))  # no user application name
            bad_code = ask(s, bytes((43, 14, 9, 0)))
        assert code == 1 and conformity in (0x02, 0x82)
        assert basic == {0: "Acme Tactile", 1: "AT-5X5", 2: "2.3"}
        assert regular == {**basic, 3: "https://acme.example", 4: "eskin-industrial bridge", 5: paper_profile.name}
        assert one == {5: paper_profile.name}
        assert parse_device_id(restart)[2] == basic
        assert missing == bytes((0xAB, 2)) and bad_code == bytes((0xAB, 3))
    finally:
        server.stop()


def test_a_malformed_header_closes_only_that_connection(paper_profile):
    server = served(paper_profile)
    try:
        with connect(port_of(server)) as good, connect(port_of(server)) as bad:
            bad.sendall(struct.pack(">HHHB", 1, 7, 6, 1) + bytes(5))  # protocol id 7
            assert closed_by_peer(bad)
            assert read_registers(good, 0, 2)
        assert server.counters()["modbus_malformed"] == 1
    finally:
        server.stop()


# -- connections --------------------------------------------------------------------

def test_connection_cap_lets_a_polling_plc_in_by_replacing_an_idle_socket(paper_profile, monkeypatch):
    import eskin_industrial.modbus.tcp_server as mod

    monkeypatch.setattr(mod, "EVICT_IDLE_S", 0.3)  # the rule as it stands, sooner (1 s in service)
    server = served(paper_profile, Policy(max_connections=3, idle_timeout_s=60))
    port = port_of(server)
    idle = [connect(port) for _ in range(3)]
    try:
        for s in idle:  # each asks once (a socket that never asks is replaced at once: test_modbus_rotation.py)
            read_registers(s, 0, 1)
        # The cap is reached by connections that asked just now (none quiet yet): the next is closed.
        with connect(port) as extra:
            assert closed_by_peer(extra)
        assert server.counters()["modbus_over_cap"] == 1
        time.sleep(0.4)  # now the three are idle: a reconnecting PLC takes one's place
        with connect(port) as plc:
            for _ in range(3):
                assert len(read_registers(plc, 0, 4)) == 4
            assert sum(closed_by_peer(s, 0.2) for s in idle) == 1
            # The PLC polls: it is never the one replaced.
            for _ in range(4):
                time.sleep(0.1)
                read_registers(plc, 0, 1)
            with connect(port) as other:
                read_registers(other, 0, 1)
            assert len(read_registers(plc, 0, 4)) == 4
        c = server.counters()
        assert c["modbus_evicted"] == 2 and c["modbus_over_cap"] == 1
    finally:
        for s in idle:
            s.close()
        server.stop()


def test_idle_timeout_closes_a_quiet_connection_not_a_polling_one(paper_profile):
    server = served(paper_profile, Policy(idle_timeout_s=0.4))
    try:
        with connect(port_of(server)) as quiet, connect(port_of(server)) as polling:
            t0 = time.monotonic()
            while time.monotonic() - t0 < 0.9:
                read_registers(polling, 0, 1)
                time.sleep(0.1)
            assert closed_by_peer(quiet, 0.1)
            assert read_registers(polling, 0, 1) is not None
        assert server.counters()["modbus_idle_closed"] == 1
    finally:
        server.stop()


@pytest.mark.slow
def test_hundreds_of_idle_sockets_under_a_low_descriptor_limit_leave_room_for_the_plc(tmp_path):
    """The finding's attack: a bridge with 256 descriptors, 348 idle sockets opened
    at it, then the PLC reconnects.  No traceback, a bounded log, the PLC gets in."""
    import resource
    import subprocess
    import sys

    from tests.helpers.paths import PROFILES

    port = free_port()
    cmd = [sys.executable, "-m", "eskin_industrial", "bridge", "-p", str(PROFILES / "paper-5x5.toml"),
           "--source", "scene:hold", "--plc", f"serve:127.0.0.1:{port}", "--duration", "8"]

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_NOFILE, (256, 256))

    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, preexec_fn=limit)
    socks: list[socket.socket] = []
    try:
        deadline = time.monotonic() + 10
        while True:
            try:
                socks.append(connect(port, timeout_s=0.5))
                break
            except OSError:
                assert time.monotonic() < deadline, "the bridge did not listen"
                time.sleep(0.1)
        for _ in range(347):
            try:
                socks.append(connect(port, timeout_s=0.5))
            except OSError:
                pass
        time.sleep(1.2)
        with connect(port) as plc:
            status = read_registers(plc, 0, 1)[0]
        assert not status & Status.BRIDGE_OFFLINE
    finally:
        for s in socks:
            s.close()
        _, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    assert "Traceback" not in err
    assert len(err.splitlines()) < 40, err[:2000]
    assert "modbus_client_refused" in err or "modbus_client_evicted" in err  # (silent ones make room)


# -- access ---------------------------------------------------------------------------

def test_allow_lists_by_client_address(paper_profile):
    # 127.0.0.2 may write, 127.0.0.3 may only read, 127.0.0.1 (the default source) neither.
    policy = Policy(allow_read=networks(["127.0.0.3"]), allow_write=networks(["127.0.0.2/32"]))
    server = served(paper_profile, policy)
    port = port_of(server)
    enable = struct.pack(">BHH", 6, REG["ENABLE"].offset, 1)
    try:
        with connect(port) as stranger:
            assert closed_by_peer(stranger)
        with connect(port, source="127.0.0.3") as reader:
            assert len(read_registers(reader, 0, 2)) == 2
            assert ask(reader, enable) == bytes((0x86, 1))  # ILLEGAL FUNCTION
        with connect(port, source="127.0.0.2") as writer:
            assert ask(writer, enable) == enable
            assert len(read_registers(writer, 0, 2)) == 2  # a writer may read
        c = server.counters()
        assert c["modbus_refused_connections"] == 1 and c["modbus_denied_writes"] == 1
        assert [cmd.name for cmd in server.take_commands()] == ["enable"]
    finally:
        server.stop()


def test_read_only_mode_refuses_every_write(paper_profile, caplog):
    server = served(paper_profile, Policy(read_only=True))
    try:
        with connect(port_of(server)) as s, caplog.at_level(logging.WARNING, logger="eskin_industrial"):
            writes = (struct.pack(">BHH", 5, TARE, 0xFF00), struct.pack(">BHH", 6, REG["COMMAND"].offset, 1),
                      struct.pack(">BHHBB", 15, 0, 1, 1, 1), struct.pack(">BHHBH", 16, REG["ENABLE"].offset, 1, 2, 0))
            for req in writes:
                assert ask(s, req) == bytes((req[0] | 0x80, 1))
            assert len(read_registers(s, 0, IMAGE_COUNT)) == IMAGE_COUNT
        assert server.counters()["modbus_denied_writes"] == 4 and not server.take_commands()
        assert [r.getMessage() for r in caplog.records] == ["modbus_write_denied"]  # one line, the rest held back
    finally:
        server.stop()


def test_unit_id_policy(paper_profile):
    server = served(paper_profile)  # default: the profile's unit id, 0 and 255
    try:
        with connect(port_of(server)) as s:
            for unit in (paper_profile.modbus.plc.unit_id, 0, 255):
                assert ask(s, struct.pack(">BHH", 3, 0, 1), unit=unit)[0] == 3
            assert ask(s, struct.pack(">BHH", 3, 0, 1), unit=7) == bytes((0x83, 0x0B))
            assert ask(s, struct.pack(">BHH", 5, TARE, 0xFF00), unit=7) == bytes((0x85, 0x0B))
        assert server.counters()["modbus_wrong_unit"] == 2
    finally:
        server.stop()
    server = served(paper_profile, Policy(unit_ids=frozenset({3})))
    try:
        with connect(port_of(server)) as s:
            assert ask(s, struct.pack(">BHH", 3, 0, 1), unit=3)[0] == 3
            assert ask(s, struct.pack(">BHH", 3, 0, 1), unit=1) == bytes((0x83, 0x0B))
    finally:
        server.stop()


# -- the tare rule ---------------------------------------------------------------------

def test_tare_during_contact_is_refused_with_exception_04_and_allowed_once_open(paper_profile, caplog):
    server = served(paper_profile)
    try:
        loop = bridge_on(paper_profile, server, 8.0)
        settle(loop)
        f_before = loop.pipeline.last_update.f_sum
        assert f_before > 4.0 and loop.pipeline.last_update.state != GraspState.NO_CONTACT
        zero = loop.pipeline.calibrator.zero.copy()
        with connect(port_of(server)) as s, caplog.at_level(logging.WARNING, logger="eskin_industrial"):
            # The TARE coil and COMMAND bit 1 (with an acknowledge: refused as a whole).
            assert ask(s, struct.pack(">BHH", 5, TARE, 0xFF00)) == bytes((0x85, 4))
            assert ask(s, struct.pack(">BHH", 6, REG["COMMAND"].offset, 3)) == bytes((0x86, 4))
            for _ in range(20):
                loop.step()
            assert read_registers(s, REG["COMMAND"].offset, 1) == [0]
        assert not server.take_commands() and loop.tares == 0
        assert np.array_equal(loop.pipeline.calibrator.zero, zero)
        assert loop.pipeline.last_update.f_sum > 0.9 * f_before  # the force is still there
        assert server.handler.tares_refused == 2 and loop.counters()["plc_tares_refused"] == 2
        refused = [r for r in caplog.records if r.getMessage() == "plc_tare_refused"]
        assert len(refused) == 1 and refused[0].fields["reason"] == "in_contact"  # type: ignore[attr-defined]
        assert refused[0].fields["peer"].startswith("127.0.0.1:")  # type: ignore[attr-defined]
    finally:
        server.stop()
    server = served(paper_profile)
    try:
        loop = bridge_on(paper_profile, server, 0.0)
        settle(loop)
        assert loop.pipeline.last_update.state == GraspState.NO_CONTACT
        with connect(port_of(server)) as s:
            req = struct.pack(">BHH", 5, TARE, 0xFF00)
            assert ask(s, req) == req
        loop.step()
        assert loop.tares == 1 and server.handler.tares_refused == 0
    finally:
        server.stop()


def test_a_tare_queued_before_contact_is_refused_when_applied(paper_profile):
    server = served(paper_profile)
    try:
        loop = bridge_on(paper_profile, server, 8.0)
        settle(loop)
        from eskin_industrial.node import Command

        server.handler.commands.put(Command("tare"))  # as if written just before the contact
        seen = []
        loop.on_command = seen.append
        loop.step()
        assert loop.tares == 0 and loop.tares_refused == 1 and seen == ["tare_refused"]
    finally:
        server.stop()


def test_mbpoll_reads_the_input_register_mirror(paper_profile):
    server = served(paper_profile)
    port = port_of(server)
    try:
        loop = bridge_on(paper_profile, server, 6.0)
        settle(loop)
        args = ("-m", "tcp", "-p", str(port), "-a", "1", "-r", "1", "-c", str(IMAGE_COUNT), "-1", "127.0.0.1")
        holding = mbpoll(*args)
        mirror = mbpoll("-t", "3", *args)
        assert holding.returncode == 0 and mirror.returncode == 0, holding.stderr + mirror.stderr
        assert mbpoll_values(mirror.stdout) == mbpoll_values(holding.stdout)
        assert Status(mbpoll_values(mirror.stdout)[1]) & Status.DATA_VALID
        # The mirror is read-only: there is no function to write input registers.
        out = mbpoll("-m", "tcp", "-p", str(port), "-a", "1", "-t", "3", "-r", "22", "-1", "127.0.0.1", "0")
        assert out.returncode != 0
    finally:
        server.stop()


# -- configuration ---------------------------------------------------------------------

def profile_with(tmp_path, plc_lines: str) -> str:
    """paper-5x5 with lines added to its [modbus.plc] (keys it does not set; the PLC's
    connection keys there are deprecated, [plc]'s now, and still read)."""
    from tests.helpers.paths import PROFILES

    text = (PROFILES / "paper-5x5.toml").read_text()
    text = text.replace("[modbus.plc]\n", f"[modbus.plc]\n{plc_lines}\n")
    path = tmp_path / "profile.toml"
    path.write_text(text)
    return str(path)


@pytest.mark.slow
def test_modbus_bridge_serve_port_only_listens_on_the_profiles_bind(tmp_path):
    import subprocess
    import sys

    from eskin_industrial.recording import write_recording

    profile = profile_with(tmp_path, 'bind = "127.0.0.2"')
    t, f, _ = slip_recording(still_s=3.0, slip_s=0.0, after_s=0.0)
    write_recording(tmp_path / "still.csv", t, f)
    port = free_port()
    proc = subprocess.Popen([sys.executable, "-m", "eskin_industrial", "modbus-bridge", "-p", profile, "--recording",
                             str(tmp_path / "still.csv"), "--serve", f":{port}", "--duration", "4"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 15
        while True:
            try:
                with connect(port, host="127.0.0.2", timeout_s=0.5) as s:
                    assert len(read_registers(s, 0, 2)) == 2
                break
            except OSError:
                assert time.monotonic() < deadline and proc.poll() is None, "nothing listens on 127.0.0.2"
                time.sleep(0.1)
        with pytest.raises(ConnectionRefusedError):
            connect(port, host="127.0.0.1", timeout_s=0.5)
    finally:
        _, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    assert f"tcp 127.0.0.2:{port}" in err


@pytest.mark.parametrize("key, line, bad", [
    ("allow_read", 'allow_read = ["10.0.0.0/24", "10.0.0.300"]', "'10.0.0.300'"),
    ("allow_write", 'allow_write = ["plc.local"]', "'plc.local'"),
    ("unit_ids", "unit_ids = [1, 256]", "256"),
    ("max_connections", "max_connections = 0", "0"),
])
def test_a_bad_server_setting_is_one_line_at_load(tmp_path, key, line, bad):
    from eskin_industrial import load_profile
    from eskin_industrial.errors import DeprecatedKey, ProfileError

    with pytest.warns(DeprecatedKey, match=rf"\[plc\] {key} in the bridge"), pytest.raises(ProfileError) as err:
        load_profile(profile_with(tmp_path, line))  # a profile's key of earlier releases: checked as before
    msg = str(err.value)
    assert "\n" not in msg and f"[modbus] plc.{key}:" in msg and bad in msg


def test_a_bad_allow_list_in_bridge_toml_is_one_line_and_exit_2(tmp_path):
    import subprocess
    import sys

    from tests.helpers.paths import PROFILES

    cfg = tmp_path / "bridge.toml"
    cfg.write_text(f'[plc]\nmode = "server"\nallow_write = ["192.168.10.20", "192.168.10.x"]\n\n'
                   f'[[node]]\nname = "a"\nprofile = "{PROFILES / "paper-5x5.toml"}"\nsource = "scene"\n'
                   f'scene = "hold"\n')
    r = subprocess.run([sys.executable, "-m", "eskin_industrial", "bridge", "--config", str(cfg), "--check"],
                       capture_output=True, text=True, timeout=30)
    assert r.returncode == 2, r.stdout + r.stderr
    assert r.stderr.strip().count("\n") == 0 and "[plc] allow_write:" in r.stderr and "192.168.10.x" in r.stderr
    assert "Traceback" not in r.stderr


# -- the structured log ------------------------------------------------------------------

@pytest.mark.slow
def test_refusals_and_asyncio_reports_reach_the_bridge_log_rate_limited(capfd):
    from eskin_industrial import load_profile
    from tests.helpers.bridge import can_node, channel, hold_raw, node_thread, running_bridge, server_config, wait_for
    from tests.helpers.paths import PROFILES

    profile = load_profile(PROFILES / "paper-5x5.toml")
    ch = channel()
    cfg = server_config(can_node("left", ch))
    port = cfg.outputs["plc"].port
    with running_bridge(cfg) as run, node_thread(profile, ch, hold_raw(profile, 150)) as node:
        node.start()
        wait_for(lambda: run.block(0)["STATUS"] & Status.DATA_VALID and run.block(0)["STATE"] != 0, 10, "a grasp")
        with connect(port) as s:
            for _ in range(3):
                assert ask(s, struct.pack(">BHH", 5, TARE, 0xFF00)) == bytes((0x85, 4))
        server = run.bridge.server.server
        for _ in range(50):  # what asyncio reports when accept() runs out of descriptors
            server._loop.call_soon_threadsafe(server._loop.call_exception_handler, {
                "message": "socket.accept() out of system resource", "exception": OSError(24, "Too many open files")})
        wait_for(lambda: run.counters("left")["modbus_asyncio_errors"] == 50, 5, "the reports")
        wait_for(lambda: run.log.events("modbus_server_error"), 5, "the log line")
        counters = run.counters("left")
        refused = run.log.events("plc_tare_refused")
        errors = run.log.events("modbus_server_error")
    assert counters["plc_tares_refused"] == 3 and counters["tares"] == 0
    assert len(refused) == 1 and refused[0]["reason"] == "in_contact" and refused[0]["level"] == "warning"
    assert len(errors) == 1 and "Too many open files" in errors[0]["error"]
    assert "Traceback" not in capfd.readouterr().err


def test_requests_before_a_malformed_header_are_answered_then_the_connection_closes(paper_profile):
    server = served(paper_profile)
    try:
        with connect(port_of(server)) as s:
            s.sendall(adu(1, 1, struct.pack(">BHH", 3, 0, 1)) + adu(2, 1, struct.pack(">BHH", 3, 0, 1))
                      + struct.pack(">HHHB", 3, 0, 900, 1))  # a length no frame has
            assert [read_adu(s)[0] for _ in range(2)] == [1, 2]
            assert closed_by_peer(s)
    finally:
        server.stop()


def test_the_servers_events_are_lines_of_the_bridge_log_while_it_is_open():
    import io
    import json

    from eskin_industrial.bridge.logs import EventLog
    from eskin_industrial.modbus.serving import RateLimitedLog
    from eskin_industrial.modbus.tcp_server import LOG

    stream = io.StringIO()
    log = EventLog(stream, "json", "info")
    events = RateLimitedLog(LOG, every_s=60)
    for i in range(5):
        events.event("modbus_write_denied", peer=f"10.0.0.{i}:502", reason="read_only")
    events.event("modbus_client_idle", level=logging.DEBUG, peer="-")  # below the log's level
    quick = RateLimitedLog(LOG, every_s=0.05)
    quick.event("modbus_unit_refused", unit=7)
    quick.event("modbus_unit_refused", unit=8)
    time.sleep(0.06)
    quick.event("modbus_unit_refused", unit=9)
    log.close()
    events.event("modbus_write_denied", peer="after close")
    lines = [json.loads(line) for line in stream.getvalue().splitlines()]
    for line in lines:
        del line["ts"]
    assert lines == [
        {"level": "warning", "event": "modbus_write_denied", "peer": "10.0.0.0:502", "reason": "read_only"},
        {"level": "warning", "event": "modbus_unit_refused", "unit": 7},
        {"level": "warning", "event": "modbus_unit_refused", "unit": 9, "held_back": 1},
    ]


def test_serving_on_every_interface_without_an_allow_list_is_logged(paper_profile, caplog, monkeypatch):
    from eskin_industrial.modbus.tcp_server import TcpServer

    monkeypatch.setattr(TcpServer, "start", lambda self: self)  # the tests listen on loopback only
    with caplog.at_level(logging.WARNING, logger="eskin_industrial"):
        listed = Policy(allow_write=networks(["127.0.0.1"]))
        for host, policy in (("0.0.0.0", None), ("127.0.0.1", None), ("0.0.0.0", listed)):
            PlcServer(paper_profile.modbus.plc, tcp=(host, free_port()), policy=policy).start().stop()
    exposed = [r for r in caplog.records if r.getMessage() == "plc_server_exposed"]
    assert len(exposed) == 1 and exposed[0].fields["bind"] == "0.0.0.0"  # type: ignore[attr-defined]
