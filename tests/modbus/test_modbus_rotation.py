"""Connection rotation at the served block's cap: sockets that never send a byte,
each closed and replaced within 0.5 s (never quiet for a second), hold every slot.
Under the default settings a reconnecting PLC gets in every time (the oldest silent
socket makes room), and the PLC that polls keeps its slot throughout."""

from __future__ import annotations

import collections
import socket
import threading
import time

from pymodbus.client import ModbusTcpClient

from eskin_industrial.outputs.plc.server import PlcServer
from tests.helpers.modbus import free_port
from tests.helpers.raw_modbus import closed_by_peer, connect, read_registers

#: The default cap (plc.md): the attack holds all of it.
SLOTS = 8


class Rotation:
    """``SLOTS`` raw sockets that never send; the oldest closed and a new one opened
    every 0.5 / SLOTS s, so that none lives longer than 0.5 s."""

    def __init__(self, port: int) -> None:
        self.port = port
        self.socks: collections.deque[socket.socket] = collections.deque()
        self.opened = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="rotation", daemon=True)

    def _run(self) -> None:
        for _ in range(SLOTS):
            self._open()
        while not self._stop.wait(0.5 / SLOTS):
            self.socks.popleft().close()
            self._open()

    def _open(self) -> None:
        self.socks.append(connect(self.port))
        self.opened += 1

    def __enter__(self) -> Rotation:
        self._thread.start()
        time.sleep(0.3)
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(5)
        for s in self.socks:
            s.close()


def test_silent_sockets_rotated_at_the_cap_never_keep_a_reconnecting_plc_out(paper_profile):
    server = PlcServer(paper_profile.modbus.plc, tcp=("127.0.0.1", free_port())).start()  # the profile's defaults
    port = server.server.port  # type: ignore[union-attr]
    assert server.server.policy.max_connections == SLOTS  # type: ignore[union-attr]
    served = 0
    try:
        with Rotation(port) as attack, connect(port) as poller:
            for _ in range(18):  # the PLC reconnects, through pymodbus
                client = ModbusTcpClient("127.0.0.1", port=port, timeout=1.0, retries=0)
                try:
                    if client.connect():
                        reply = client.read_holding_registers(0, count=4)
                        served += not reply.isError() and len(reply.registers) == 4
                except Exception:  # noqa: BLE001 - a refused reconnect is what is counted
                    pass
                finally:
                    client.close()
                # the PLC that polls (the longest-established that asks) keeps its slot
                assert len(read_registers(poller, 0, 2)) == 2
                time.sleep(0.1)
            opened = attack.opened
        c = server.counters()
    finally:
        server.stop()
    assert served == 18, f"{served} of 18 reconnects served"
    assert opened > 30 and c["modbus_evicted"] >= 18


def test_a_newcomer_at_a_cap_of_askers_is_refused_and_the_plc_back_from_its_address_gets_in(paper_profile,
                                                                                            monkeypatch):
    """Every slot held by clients that have asked: a newcomer replaces one only when it
    has been quiet (EVICT_IDLE_S), never the longest-established (the PLC's), unless
    the newcomer comes from the PLC's own address (its reconnect, the old connection
    dead)."""
    import eskin_industrial.modbus.tcp_server as mod

    monkeypatch.setattr(mod, "EVICT_IDLE_S", 0.3)
    settings = paper_profile.modbus.plc
    server = PlcServer(settings, tcp=("127.0.0.1", free_port()),
                       policy=mod.Policy(max_connections=2)).start()
    port = server.server.port  # type: ignore[union-attr]
    try:
        with connect(port, source="127.0.0.2") as plc, connect(port) as other:
            read_registers(plc, 0, 1)
            read_registers(other, 0, 1)
            with connect(port, source="127.0.0.3") as newcomer:  # both busy just now
                assert closed_by_peer(newcomer)
            time.sleep(0.4)  # both quiet: the newcomer replaces the other, not the PLC
            with connect(port, source="127.0.0.3") as newcomer:
                assert len(read_registers(newcomer, 0, 1)) == 1
                assert closed_by_peer(other, 0.5) and not closed_by_peer(plc, 0.2)
                time.sleep(0.4)  # the PLC's cable is cut: its connection stays, quiet
                with connect(port, source="127.0.0.2") as back:
                    assert len(read_registers(back, 0, 2)) == 2
                    assert closed_by_peer(plc, 0.5)
    finally:
        server.stop()
