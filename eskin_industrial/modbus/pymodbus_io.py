"""Every pymodbus call of the package, in one place (pymodbus changes its API between
minor releases; the tested range is pinned in ``pyproject.toml``).

- :class:`RtuMaster`: the synchronous RTU client of the RTU source and of the PLC
  client over RTU; it raises :class:`ModbusFault` instead of returning error objects
  and tells timeouts, garbled frames and exception responses apart.
- :class:`RegisterServer` and :class:`TcpMaster`: a Modbus TCP server and client that
  someone else wrote, for what stands on the other side of the bridge's own TCP code.
  The PLC stand-in (``plc-sim``, the demo, the tests' PLCs) serves through
  :class:`RegisterServer`, so that the PLC client's own master (:mod:`.tcp_master`,
  :mod:`.mbap`) is checked against a third-party decoder, not against our framing
  on both ends; the tests and benchmarks read the bridge's own server
  (:mod:`.tcp_server`) with :class:`TcpMaster`.  The product serves with its own
  servers only (:mod:`.tcp_server`, :mod:`.rtu_server`).

Addresses here are 0-based protocol addresses.
"""

from __future__ import annotations

import asyncio
import logging
import socket
import threading
from collections.abc import Sequence
from typing import Any

from pymodbus import FramerType
from pymodbus.client import ModbusSerialClient, ModbusTcpClient
from pymodbus.constants import ExcCodes
from pymodbus.datastore import ModbusServerContext
from pymodbus.exceptions import ModbusException
from pymodbus.pdu import ModbusPDU
from pymodbus.server import ModbusTcpServer

from ..errors import EskinError, ListenError, ModbusFault
from ..netaddr import listen_problem
from .pdu import RegisterHandler, Table
from .rtu_frame import intact
from .serial_line import SerialSettings

_TABLE_OF_FC: dict[int, Table] = {1: "coils", 5: "coils", 15: "coils", 2: "discrete", 3: "holding", 6: "holding",
                                  16: "holding", 22: "holding", 23: "holding", 4: "input"}


def quiet_pymodbus() -> None:
    """For the command line: pymodbus logs refused requests, timeouts and lost peers
    at ERROR (through Python's last-resort handler when nothing is configured); the
    package counts those itself and reports them in one line."""
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)


class _HandlerContext(ModbusServerContext):
    """The server's datastore, answered by a handler (pymodbus' hook for a custom
    store); every unit id is answered, as usual over TCP."""

    def __init__(self, handler: RegisterHandler) -> None:  # no super(): no store
        self.handler = handler
        # The two attributes pymodbus' server reads, which only its __init__ sets
        # (pinned by tests/test_private_apis.py).
        self.old_simulator = True
        self.simdevices = []

    async def async_getValues(self, device_id: int, func_code: int, address: int,
                              count: int = 1) -> list[int] | list[bool] | ExcCodes:
        table = _TABLE_OF_FC.get(func_code)
        if table is None:
            return ExcCodes.ILLEGAL_FUNCTION
        result = self.handler.read(table, address, count)
        return ExcCodes(result) if isinstance(result, int) else result

    async def async_setValues(self, device_id: int, func_code: int, address: int,
                              values: Sequence[int] | Sequence[bool]) -> ExcCodes | None:
        table = _TABLE_OF_FC.get(func_code)
        if table is None:
            return ExcCodes.ILLEGAL_FUNCTION
        listed: Any = values if isinstance(values, list) else [values]  # a list from pymodbus 3.16
        result = self.handler.write(table, address, listed)
        return None if result is None else ExcCodes(result)

    def device_ids(self) -> list[int]:
        return [0]


class RegisterServer:
    """A pymodbus Modbus TCP server on its own thread, every read and write answered
    by ``handler`` (which decides which addresses exist and which exception a refused
    request gets); ``start()`` returns once it listens."""

    def __init__(self, handler: RegisterHandler, *, tcp: tuple[str, int]) -> None:
        self.handler = handler
        self.tcp = tcp
        self._loop: asyncio.AbstractEventLoop | None = None
        self._server: ModbusTcpServer | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None

    @property
    def where(self) -> str:
        return f"tcp {self.tcp[0]}:{self.tcp[1]}"

    def start(self, timeout_s: float = 5.0) -> RegisterServer:
        self._thread = threading.Thread(target=self._run, name="modbus-server", daemon=True)
        self._thread.start()
        if not self._ready.wait(timeout_s):
            raise EskinError(f"modbus server ({self.where}): did not start within {timeout_s:g} s")
        if self._error is not None:
            # pymodbus says only "please check address": try the bind ourselves for why
            problem = listen_problem(*self.tcp)
            if problem:  # a port in use: a setting to change, exit 2 (as the bridge's server)
                raise ListenError(f"modbus server: {problem}")
            raise EskinError(f"modbus server ({self.where}): cannot listen: {self._error}")
        return self

    def _run(self) -> None:
        try:
            asyncio.run(self._main())
        except BaseException as exc:  # noqa: BLE001 - reported to start()
            self._error = exc
            self._ready.set()

    async def _main(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._server = ModbusTcpServer(_HandlerContext(self.handler), address=self.tcp)
        try:
            await self._server.serve_forever(background=True)
        except RuntimeError as exc:
            raise EskinError(str(exc)) from None
        self._ready.set()
        await self._server.serving

    def stop(self) -> None:
        """Stop serving; safe to call twice."""
        loop, server = self._loop, self._server
        if loop is not None and server is not None and not loop.is_closed():
            try:
                asyncio.run_coroutine_threadsafe(server.shutdown(), loop).result(timeout=5)
            except (RuntimeError, TimeoutError, ConnectionError):
                pass
        if self._thread is not None:
            self._thread.join(timeout=5)
        self._server = None

    def __enter__(self) -> RegisterServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


def _raise_on_error(response: ModbusPDU, what: str) -> ModbusPDU:
    if response.isError():
        code = int(getattr(response, "exception_code", 0) or 0)
        raise ModbusFault("exception", f"{what}: exception response, code {code}", code)
    return response


class TcpMaster:
    """A synchronous Modbus TCP client with TCP_NODELAY; connect errors raise."""

    def __init__(self, host: str, port: int, unit_id: int = 1, timeout_s: float = 1.0) -> None:
        self.host, self.port, self.unit_id = host, port, unit_id
        self._client = ModbusTcpClient(host, port=port, timeout=timeout_s, retries=0,
                                       reconnect_delay=0, reconnect_delay_max=0)

    def connect(self) -> None:
        try:
            ok = self._client.connect()
            if ok:  # connected: pymodbus has set the socket (AttributeError is caught all the same)
                self._client.socket.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)  # type: ignore[union-attr]
        except (ModbusException, OSError, AttributeError) as exc:
            self.close()
            raise ModbusFault("connection", f"cannot connect to {self.host}:{self.port}: {exc}") from None
        if not ok:
            raise ModbusFault("connection", f"cannot connect to {self.host}:{self.port}")

    def write_registers(self, address: int, values: Sequence[int]) -> None:
        try:
            r = self._client.write_registers(address, list(values), device_id=self.unit_id)
        except (ModbusException, OSError) as exc:
            self.close()
            raise ModbusFault("connection", f"write to {self.host}:{self.port}: {exc}") from None
        _raise_on_error(r, f"write to {self.host}:{self.port}")

    def read_holding(self, address: int, count: int) -> list[int]:
        try:
            r = self._client.read_holding_registers(address, count=count, device_id=self.unit_id)
        except (ModbusException, OSError) as exc:
            self.close()
            raise ModbusFault("connection", f"read from {self.host}:{self.port}: {exc}") from None
        return list(_raise_on_error(r, f"read from {self.host}:{self.port}").registers)

    def close(self) -> None:
        self._client.close()


class RtuMaster:
    """A synchronous Modbus RTU client that tells timeouts, garbled frames (bad CRC or
    framing) and exception responses apart."""

    def __init__(self, settings: SerialSettings, unit_id: int, timeout_s: float) -> None:
        self.settings, self.unit_id, self.timeout_s = settings, unit_id, timeout_s
        self._rx = bytearray()
        self._client = ModbusSerialClient(
            settings.port, framer=FramerType.RTU, baudrate=settings.baudrate, parity=settings.parity,
            stopbits=settings.stopbits, timeout=timeout_s, retries=0, reconnect_delay=0,
            reconnect_delay_max=0, trace_packet=self._trace,
        )

    def _trace(self, sending: bool, data: bytes) -> bytes:
        if sending:
            self._rx.clear()
        else:
            self._rx += data
        return data

    def connect(self) -> None:
        if not self._client.connect():
            raise ModbusFault("connection", f"cannot open serial port {self.settings.port}")

    def read(self, function: int, address: int, count: int) -> list[int]:
        call = self._client.read_input_registers if function == 4 else self._client.read_holding_registers
        try:
            r = call(address, count=count, device_id=self.unit_id)
        except (ModbusException, OSError) as exc:
            raise self._fault(exc) from None
        return list(_raise_on_error(r, f"{self.settings.port}").registers)

    def _fault(self, exc: BaseException) -> ModbusFault:
        """What went wrong, from the bytes that came back, in our words: pymodbus says
        "No response received" of an answer from another unit and of a garbled one
        alike (and "CLOSING CONNECTION" of a serial line that stays open)."""
        port, rx = self.settings.port, bytes(self._rx)
        if not self._client.connected:
            return ModbusFault("connection", f"{port}: connection: {exc}")
        if rx and intact(rx) and rx[0] != self.unit_id:
            return ModbusFault("unit", f"{port}: unit: the answer came from unit {rx[0]}, unit {self.unit_id} was "
                                       "asked ([modbus.node] unit_id, or a bridge node's unit_id)")
        if rx:
            what = "not a whole frame" if len(rx) < 4 else "bad CRC" if not intact(rx) else "not the answer asked for"
            return ModbusFault("crc", f"{port}: crc: a garbled answer ({len(rx)} bytes, {what}), dropped")
        return ModbusFault("timeout", f"{port}: timeout: no answer from unit {self.unit_id} within {self.timeout_s:g} s")

    def write_registers(self, address: int, values: Sequence[int]) -> None:
        try:
            r = self._client.write_registers(address, list(values), device_id=self.unit_id)
        except (ModbusException, OSError) as exc:
            raise ModbusFault("timeout", f"{self.settings.port}: write: {exc}") from None
        _raise_on_error(r, f"{self.settings.port}: write")

    def read_holding(self, address: int, count: int) -> list[int]:
        return self.read(3, address, count)

    def reset_input(self) -> None:
        """Drop whatever is pending on the line (after garbage)."""
        sock = getattr(self._client, "socket", None)
        if sock is not None:
            try:
                sock.reset_input_buffer()
            except (OSError, AttributeError):
                pass

    def close(self) -> None:
        self._client.close()
