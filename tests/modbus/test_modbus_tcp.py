"""The PLC client's own Modbus TCP framing and its pipelining master, checked against
pymodbus (a server that decodes our requests, a framer that encodes the answers) and
against a PLC that accepts the connection and never answers."""

from __future__ import annotations

import socket
import struct
import threading
import time

import pytest
from hypothesis import given
from hypothesis import strategies as st

from eskin_industrial.errors import DecodeError, ModbusFault
from eskin_industrial.modbus import mbap
from eskin_industrial.modbus.pymodbus_io import RegisterServer
from eskin_industrial.modbus.tcp_master import PipelinedTcpMaster
from eskin_industrial.outputs.plc.client import PlcWriter
from eskin_industrial.outputs.plc.image import STATUS_COUNT, Status
from tests.helpers.modbus import free_port


class Memory:
    """A served register file: what pymodbus decoded from our requests."""

    def __init__(self, size: int = 200) -> None:
        self.regs = [0] * size
        self.writes: list[tuple[int, list[int]]] = []

    def read(self, table, address, count):
        if table != "holding" or address + count > len(self.regs):
            return 2
        return self.regs[address: address + count]

    def write(self, table, address, values):
        if table != "holding" or address + len(values) > len(self.regs):
            return 2
        self.regs[address: address + len(values)] = [int(v) for v in values]
        self.writes.append((address, [int(v) for v in values]))
        return None


@pytest.fixture
def served():
    port = free_port()
    memory = Memory()
    server = RegisterServer(memory, tcp=("127.0.0.1", port)).start()
    try:
        yield memory, port
    finally:
        server.stop()


@given(tid=st.integers(0, 0xFFFF), unit=st.integers(0, 255), address=st.integers(0, 0xFFFF),
       values=st.lists(st.integers(0, 0xFFFF), min_size=1, max_size=mbap.MAX_WRITE))
def test_write_request_layout(tid, unit, address, values):
    frame = mbap.write_request(tid, unit, address, values)
    head = struct.unpack(">HHHBBHHB", frame[:13])
    assert head == (tid, 0, 7 + 2 * len(values), unit, 16, address, len(values), 2 * len(values))
    assert list(struct.unpack(f">{len(values)}H", frame[13:])) == values
    assert mbap.frame_length(frame[:7]) == len(frame)


def test_garbage_headers_and_truncated_frames_are_decode_errors():
    with pytest.raises(DecodeError, match="not a Modbus TCP frame"):
        mbap.frame_length(b"\x00\x01\x00\x07\x00\x05\x01")  # protocol 7
    with pytest.raises(DecodeError, match="not a Modbus TCP frame"):
        mbap.frame_length(b"\x00\x01\x00\x00\x01\x00\x01")  # longer than any PDU
    with pytest.raises(DecodeError, match="truncated"):
        mbap.decode_response(b"\x00\x01\x00\x00\x00\x06\x01\x10\x00")
    with pytest.raises(DecodeError, match="unexpected function code"):
        mbap.decode_response(b"\x00\x01\x00\x00\x00\x02\x01\x05")


def test_pymodbus_decodes_our_requests_and_we_decode_its_answers(served):
    memory, port = served
    master = PipelinedTcpMaster("127.0.0.1", port, timeout_s=2.0)
    master.connect()
    try:
        master.write_registers(10, [1, 2, 0xFFFF])
        assert memory.writes == [(10, [1, 2, 0xFFFF])]
        memory.regs[50:53] = [7, 0x8000, 9]
        assert master.read_holding(50, 3) == [7, 0x8000, 9]
        with pytest.raises(ModbusFault) as err:  # past the served file: ILLEGAL DATA ADDRESS
            master.write_registers(199, [1, 2])
        assert err.value.kind == "exception" and err.value.code == 2
        # three writes sent before any answer is read; answers matched by id.  (Spaced
        # out: a pymodbus server answers only the first of requests that share one TCP
        # segment; the PLC client never has more than one request outstanding.)
        tids = []
        for i in range(3):
            tids.append(master.send_write(20 + i, [i]))
            time.sleep(0.05)
        for tid in tids:
            assert master.await_response(tid).registers == (20 + tids.index(tid), 1)
        assert memory.regs[20:23] == [0, 1, 2]
    finally:
        master.close()


def test_an_answer_given_up_on_is_counted_and_skipped(served):
    memory, port = served
    master = PipelinedTcpMaster("127.0.0.1", port, timeout_s=2.0)
    master.connect()
    try:
        first = master.send_write(1, [5])
        time.sleep(0.05)  # its answer waits in the socket, unread
        second = master.send_write(2, [6])
        assert master.await_response(second).registers == (2, 1)  # the first answer is passed over
        assert master.stale_answers == 1 and first != second
    finally:
        master.close()


class SilentPlc:
    """Accepts connections, reads what comes, never answers (a hung PLC)."""

    def __init__(self) -> None:
        self.sock = socket.create_server(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.received = 0
        self._stop = threading.Event()
        self._conns: list[socket.socket] = []
        self._thread = threading.Thread(target=self._run, name="silent-plc", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        self.sock.settimeout(0.05)
        while not self._stop.is_set():
            try:
                conn, _ = self.sock.accept()
                conn.settimeout(0.05)
                self._conns.append(conn)
            except TimeoutError:
                pass
            for c in list(self._conns):
                try:
                    data = c.recv(4096)
                    self.received += len(data)
                except TimeoutError:
                    pass
                except OSError:
                    self._conns.remove(c)

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(5)
        for c in self._conns:
            c.close()
        self.sock.close()


def test_an_urgent_image_is_sent_by_the_offering_thread_and_a_hung_plc_never_blocks_it(paper_profile):
    plc = SilentPlc()
    writer = PlcWriter(paper_profile.modbus.plc, "127.0.0.1", plc.port, timeout_s=0.3, poll_commands=False).start()
    try:
        deadline = time.monotonic() + 5
        while not writer.connected:
            assert time.monotonic() < deadline
            time.sleep(0.005)
        image = [int(Status.SLIP)] + [0] * (STATUS_COUNT - 1)
        took = []
        for _ in range(50):  # far more than one answer could come for
            t0 = time.perf_counter()
            writer.offer(image, urgent=True)
            took.append(time.perf_counter() - t0)
        assert max(took) < 0.05  # no offer waits for the PLC
        assert writer.stats.sent_inline >= 1  # the first went straight out, on this thread
        deadline = time.monotonic() + 5
        while writer.stats.failures == 0:  # the writer gave up on the answer
            assert time.monotonic() < deadline
            time.sleep(0.01)
        assert plc.received >= len(mbap.write_request(0, 1, 0, image))
        assert writer.stats.writes == 0 and "no answer" in writer.stats.last_error
    finally:
        writer.stop(flush_s=0.2)
        plc.stop()
