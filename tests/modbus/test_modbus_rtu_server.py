"""Server mode over RTU: our serial-line server, spoken to over a socat pty pair with
hand-built frames whose CRC is computed by pymodbus (a framer we did not write), and
read by mbpoll in tests/outputs/plc/test_plc_server.py.  The framing itself, pure, is
tests/modbus/test_modbus_rtu_frame.py."""

from __future__ import annotations

import struct
import time

import pytest
from pymodbus.framer.rtu import FramerRTU

from eskin_industrial.modbus import rtu_frame
from eskin_industrial.modbus.serial_line import SerialSettings
from eskin_industrial.modbus.tcp_server import Policy
from eskin_industrial.outputs.plc.image import COIL, REG
from eskin_industrial.outputs.plc.server import PlcServer
from tests.helpers.modbus import pty_pair

UNIT = 1


def rtu(unit: int, pdu: bytes) -> bytes:
    body = bytes((unit,)) + pdu
    return body + FramerRTU.compute_CRC(body).to_bytes(2, "big")


class Line:
    """The master's end of the pty pair: raw bytes, no Modbus library."""

    def __init__(self, path: str) -> None:
        import serial

        self.port = serial.Serial(path, 115200, timeout=0.1)

    def ask(self, frame: bytes, expect: int | None = None) -> bytes:
        """The answer: ``expect`` bytes, or (None) what comes until a silence; b"" when
        nothing comes within 0.3 s."""
        self.port.reset_input_buffer()
        self.port.write(frame)
        out = b""
        deadline = time.monotonic() + (2.0 if expect is not None else 0.3)
        while time.monotonic() < deadline and (expect is None or len(out) < expect):
            chunk = self.port.read(256 if expect is None else expect - len(out))
            if not chunk and expect is None and out:
                break
            out += chunk
        return out

    def close(self) -> None:
        self.port.close()


@pytest.fixture
def line(tmp_path, paper_profile, request):
    policy = getattr(request, "param", None)
    with pty_pair(tmp_path) as (a, b):
        server = PlcServer(paper_profile.modbus.plc, serial=SerialSettings(a, 115200), policy=policy).start()
        master = Line(b)
        try:
            yield server, master
        finally:
            master.close()
            server.stop()


def test_rtu_answers_are_the_specifications(line):
    server, m = line
    req = rtu(UNIT, struct.pack(">BHH", 5, COIL["ENABLE"].offset, 0xFF00))
    assert m.ask(req, len(req)) == req  # FC5: the echo, CRC included
    req = rtu(UNIT, struct.pack(">BHHBH", 16, REG["ENABLE"].offset, 1, 2, 1))
    assert m.ask(req, 8) == rtu(UNIT, req[1:6])
    resp = m.ask(rtu(UNIT, bytes((17,))))
    assert rtu_frame.intact(resp) and b"eskin-industrial" in resp and resp[3:5] == bytes((UNIT, 0xFF))
    resp = m.ask(rtu(UNIT, bytes((43, 14, 1, 0))))
    assert rtu_frame.intact(resp) and resp[1:3] == bytes((43, 14)) and resp[7] == 3  # three basic objects
    # A function not served, framed by the silence that follows: ILLEGAL FUNCTION.
    assert m.ask(rtu(UNIT, bytes((8, 0, 0, 0, 0))), 5) == rtu(UNIT, bytes((0x88, 1)))
    assert [c.name for c in server.take_commands()] == ["enable", "enable"]


def test_rtu_garbage_bad_crc_other_units_and_broadcast(line):
    server, m = line
    read = rtu(UNIT, struct.pack(">BHH", 3, 0, 2))
    # Noise, then a request, in one write: the request is found behind the noise.
    assert m.ask(b"\x00\xff\x13" + read, 9)[:3] == bytes((UNIT, 3, 4))
    bad = bytearray(read)
    bad[3] ^= 0x01
    assert m.ask(bytes(bad)) == b""  # a garbled request: no answer
    assert m.ask(rtu(7, struct.pack(">BHH", 3, 0, 2))) == b""  # another device's
    req = struct.pack(">BHH", 5, COIL["ENABLE"].offset, 0x0000)
    assert m.ask(rtu(0, req)) == b""  # broadcast: acted on, not answered
    time.sleep(0.05)
    assert [c.name for c in server.take_commands()] == ["disable"]
    c = server.counters()
    assert c["modbus_crc_errors"] >= 1 and c["modbus_other_units"] == 1 and c["modbus_dropped_bytes"] >= 3


@pytest.mark.parametrize("line", [Policy(read_only=True)], indirect=True)
def test_rtu_read_only(line):
    server, m = line
    req = rtu(UNIT, struct.pack(">BHH", 6, REG["ENABLE"].offset, 0))
    assert m.ask(req, 5) == rtu(UNIT, bytes((0x86, 1)))
    assert m.ask(rtu(UNIT, struct.pack(">BHH", 3, 0, 1)), 7)[:2] == bytes((UNIT, 3))
    assert server.counters()["modbus_denied_writes"] == 1 and not server.take_commands()


def test_rtu_tare_refused_before_anything_is_known(line):
    server, m = line
    req = rtu(UNIT, struct.pack(">BHH", 5, COIL["TARE"].offset, 0xFF00))
    assert m.ask(req, 5) == rtu(UNIT, bytes((0x85, 4)))
    assert server.handler.tares_refused == 1


def test_a_serial_line_that_goes_away_is_counted_and_logged_once(tmp_path, paper_profile, caplog):
    import logging

    from tests.helpers.bridge import wait_for

    with caplog.at_level(logging.ERROR, logger="eskin_industrial"):
        with pty_pair(tmp_path) as (a, _b):
            server = PlcServer(paper_profile.modbus.plc, serial=SerialSettings(a, 115200)).start()
        try:  # socat has gone: the port fails, and cannot be opened again
            wait_for(lambda: server.counters()["modbus_serial_errors"] >= 2, 5, "the failures")
        finally:
            t0 = time.monotonic()
            server.stop()
            assert time.monotonic() - t0 < 2.0
    errors = [r for r in caplog.records if r.getMessage() == "modbus_serial_error"]
    assert len(errors) == 1 and a in errors[0].fields["port"]  # type: ignore[attr-defined]
