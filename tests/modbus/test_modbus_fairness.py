"""Fair service in the PLC server over TCP: one client must not starve the others.
Each test plays one attack of the hostile tester's (a client that pipelines and
never reads its answers, sockets that send a frame one byte at a time, the cap
filled while the PLC reconnects) against a real server on loopback, and checks what
the server does about it (closes, throttles, makes room), never how fast: the
latencies are measured by ``benchmarks/bench_fairness.py``."""

from __future__ import annotations

import struct
import threading
import time

from eskin_industrial.modbus.tcp_server import Policy, networks
from eskin_industrial.outputs.plc.server import PlcServer
from tests.helpers.modbus import free_port
from tests.helpers.raw_modbus import adu, closed_by_peer, connect, read_registers


def served(profile, policy: Policy) -> PlcServer:
    return PlcServer(profile.modbus.plc, tcp=("127.0.0.1", free_port()), policy=policy).start()


def port_of(server: PlcServer) -> int:
    return server.server.port  # type: ignore[union-attr]


def test_slow_loris_sockets_are_closed_and_do_not_lock_a_reconnecting_plc_out(paper_profile):
    """Eight sockets fill the cap, each sending one byte of a frame every 0.9 s: a
    frame's bytes are not activity, so after a second they are quiet (a newcomer may
    replace one), and after ``frame_timeout_s`` (2 s) each is closed."""
    server = served(paper_profile, Policy(max_connections=8))
    port = port_of(server)
    frame = adu(1, 1, struct.pack(">BHH", 3, 0, 4))
    loris = [connect(port) for _ in range(8)]
    stop = threading.Event()

    def drip() -> None:
        i = 0
        while not stop.wait(0.9):
            i += 1
            for s in loris:
                try:
                    s.send(frame[i % len(frame):][:1])
                except OSError:
                    pass

    dripper = threading.Thread(target=drip, daemon=True)
    dripper.start()
    try:
        for s in loris:
            s.send(frame[:1])
        time.sleep(1.3)  # past EVICT_IDLE_S, each socket having sent a byte within 0.9 s
        with connect(port) as plc:
            assert len(read_registers(plc, 0, 4)) == 4, "the PLC was refused at the cap"
            deadline = time.monotonic() + 3.0
            while time.monotonic() < deadline and server.counters()["modbus_partial_closed"] < 7:
                read_registers(plc, 0, 1)
                time.sleep(0.1)
            assert len(read_registers(plc, 0, 4)) == 4
        assert sum(closed_by_peer(s, 0.05) for s in loris) == 8
        c = server.counters()
        assert c["modbus_partial_closed"] + c["modbus_evicted"] == 8 and c["modbus_over_cap"] == 0
    finally:
        stop.set()
        dripper.join(2)
        for s in loris:
            s.close()
        server.stop()


def test_the_plc_on_allow_write_gets_in_at_the_cap_filled_by_busy_pollers(paper_profile):
    """Three clients poll without pause and fill the cap; the PLC (127.0.0.2, the
    only address on allow_write) reconnects: it replaces the quietest of them, five
    times out of five, and it is never the one replaced."""
    policy = Policy(max_connections=3, allow_write=networks(["127.0.0.2"]))
    server = served(paper_profile, policy)
    port = port_of(server)
    stop = threading.Event()
    replaced = [0]

    def poll() -> None:
        while not stop.is_set():
            try:
                with connect(port) as s:
                    while not stop.is_set():
                        read_registers(s, 0, 2)
            except (OSError, AssertionError):
                replaced[0] += 1
                time.sleep(0.05)

    pollers = [threading.Thread(target=poll, daemon=True) for _ in range(3)]
    for t in pollers:
        t.start()
    try:
        time.sleep(0.3)
        for _ in range(5):
            with connect(port, source="127.0.0.2") as plc:
                for _ in range(5):
                    assert len(read_registers(plc, 0, 4)) == 4
            time.sleep(0.1)
        assert server.counters()["modbus_evicted"] >= 5
    finally:
        stop.set()
        for t in pollers:
            t.join(3)
        server.stop()


def test_a_client_that_pipelines_and_never_reads_is_cut_off_while_a_poller_is_served(paper_profile):
    """A client sends read requests as fast as TCP takes them and never reads the
    answers: the server stops reading it once ``max_unread_bytes`` are unread, closes it
    after ``unread_timeout_s`` (5 s), and a poller meanwhile gets every answer."""
    server = served(paper_profile, Policy())
    port = port_of(server)
    burst = b"".join(adu(i & 0xFFFF, 1, struct.pack(">BHH", 3, 0, 20)) for i in range(5000))
    hog = connect(port, timeout_s=10.0)
    sent = [0]

    def flood() -> None:
        try:
            while True:
                hog.sendall(burst)
                sent[0] += len(burst)
        except OSError:
            pass  # closed by the server

    flooder = threading.Thread(target=flood, daemon=True)
    flooder.start()
    try:
        with connect(port) as poller:
            t0 = time.monotonic()
            reads = 0
            while flooder.is_alive() and time.monotonic() - t0 < 8.0:
                assert len(read_registers(poller, 0, 4)) == 4
                reads += 1
                time.sleep(0.01)
        flooder.join(1)
        assert not flooder.is_alive(), "the non-reader was never cut off"
        c = server.counters()
        assert c["modbus_unread_closed"] == 1 and c["modbus_deferred"] > 0
        # Throttled: it was answered a few windows' worth, not everything it sent.
        assert c["modbus_requests"] - reads < sent[0] // len(adu(0, 1, b"\x03\x00\x00\x00\x14"))
    finally:
        hog.close()
        server.stop()
