"""Every pymodbus call of the package, in one place (pymodbus changes its API between
minor releases; the tested range is pinned in ``pyproject.toml``).

- :class:`RegisterServer` serves a :class:`RegisterHandler` over Modbus TCP or RTU
  from a background thread; the handler answers every read and write itself, so
  it decides which addresses exist and which exception a refused request gets.
  The simulators (the sensor node, the PLC stand-in) use it: a server that someone
  else wrote.  The bridge's server mode has its own (:mod:`.tcp_server`, :mod:`.rtu_server`),
  for answers that follow the specification and an access policy.
- :class:`TcpMaster` / :class:`RtuMaster`: synchronous clients that raise
  :class:`ModbusFault` instead of returning error objects.

Addresses here are 0-based protocol addresses.
"""

from __future__ import annotations

import asyncio
import logging
import socket
import threading
from collections.abc import Sequence

from pymodbus import FramerType
from pymodbus.client import ModbusSerialClient, ModbusTcpClient
from pymodbus.constants import ExcCodes
from pymodbus.datastore import ModbusServerContext
from pymodbus.exceptions import ModbusException, NoSuchIdException
from pymodbus.framer.rtu import FramerRTU
from pymodbus.server import ModbusSerialServer, ModbusTcpServer

from ..errors import EskinError, ModbusFault
from ..netaddr import listen_problem
from .pdu import RegisterHandler, Table
from .serial_line import SerialSettings


_TABLE_OF_FC: dict[int, Table] = {1: "coils", 5: "coils", 15: "coils", 2: "discrete", 3: "holding", 6: "holding",
                                  16: "holding", 22: "holding", 23: "holding", 4: "input"}



def quiet_pymodbus() -> None:
    """For the command line: pymodbus logs refused requests, timeouts and lost peers
    at ERROR (through Python's last-resort handler when nothing is configured); the
    package counts those itself and reports them in one line."""
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)


class _HandlerContext(ModbusServerContext):
    """The server's datastore, answered by a handler (pymodbus' hook for a custom store)."""

    def __init__(self, handler: RegisterHandler, unit_ids: Sequence[int] | None) -> None:  # no super(): no store
        self.handler = handler
        self.unit_ids = None if unit_ids is None else set(unit_ids)
        self.old_simulator = True
        self.simdevices = []

    def _check(self, device_id: int) -> None:
        if self.unit_ids is not None and device_id not in self.unit_ids:
            raise NoSuchIdException(f"unit {device_id}")

    async def async_getValues(self, device_id, func_code, address, count=1):  # noqa: N802 (pymodbus name)
        self._check(device_id)
        table = _TABLE_OF_FC.get(func_code)
        if table is None:
            return ExcCodes.ILLEGAL_FUNCTION
        result = self.handler.read(table, address, count)
        return ExcCodes(result) if isinstance(result, int) else result

    async def async_setValues(self, device_id, func_code, address, values):  # noqa: N802
        self._check(device_id)
        table = _TABLE_OF_FC.get(func_code)
        if table is None:
            return ExcCodes.ILLEGAL_FUNCTION
        if not isinstance(values, list):
            values = [values]
        result = self.handler.write(table, address, values)
        return None if result is None else ExcCodes(result)

    def device_ids(self):
        return sorted(self.unit_ids) if self.unit_ids is not None else [0]


class RegisterServer:
    """A Modbus TCP or RTU server on its own thread; ``start()`` returns once it listens.

    ``unit_ids``: the unit ids answered (RTU: others are ignored, as on a shared line);
    ``None`` answers every id (usual for TCP).
    """

    def __init__(self, handler: RegisterHandler, *, tcp: tuple[str, int] | None = None,
                 serial: SerialSettings | None = None, unit_ids: Sequence[int] | None = None) -> None:
        if (tcp is None) == (serial is None):
            raise ValueError("RegisterServer: give exactly one of tcp= or serial=")
        self.handler = handler
        self.tcp = tcp
        self.serial = serial
        self.unit_ids = unit_ids
        self._loop: asyncio.AbstractEventLoop | None = None
        self._server: ModbusTcpServer | ModbusSerialServer | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None

    @property
    def where(self) -> str:
        if self.tcp is not None:
            return f"tcp {self.tcp[0]}:{self.tcp[1]}"
        assert self.serial is not None
        return f"rtu {self.serial.port} at {self.serial.baudrate} baud"

    def start(self, timeout_s: float = 5.0) -> "RegisterServer":
        self._thread = threading.Thread(target=self._run, name="modbus-server", daemon=True)
        self._thread.start()
        if not self._ready.wait(timeout_s):
            raise EskinError(f"modbus server ({self.where}): did not start within {timeout_s:g} s")
        if self._error is not None:
            # pymodbus says only "please check address": try the bind ourselves for why
            problem = listen_problem(*self.tcp) if self.tcp is not None else None
            if problem:
                raise EskinError(f"modbus server: {problem}")
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
        context = _HandlerContext(self.handler, self.unit_ids)
        if self.tcp is not None:
            self._server = ModbusTcpServer(context, address=self.tcp)
        else:
            s = self.serial
            assert s is not None
            # The server's serial transport opens the port itself; check it first for
            # a clear message (pymodbus only logs a failed open).
            import serial  # pyserial, a pymodbus dependency for RTU

            try:
                serial.Serial(s.port, s.baudrate).close()
            except (serial.SerialException, OSError) as exc:
                raise EskinError(f"cannot open serial port {s.port}: {exc}") from None
            self._server = ModbusSerialServer(
                context, framer=FramerType.RTU, port=s.port, baudrate=s.baudrate, parity=s.parity,
                stopbits=s.stopbits, ignore_missing_devices=True, reconnect_delay=0.5,
            )
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

    def __enter__(self) -> "RegisterServer":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


def _raise_on_error(response, what: str):
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

    @property
    def connected(self) -> bool:
        return self._client.socket is not None

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
        self.settings, self.unit_id = settings, unit_id
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
            kind = "crc" if self._rx and not _valid_frame(bytes(self._rx)) else "timeout"
            if not self._client.connected:
                kind = "connection"
            raise ModbusFault(kind, f"{self.settings.port}: {kind}: {exc}") from None
        return list(_raise_on_error(r, f"{self.settings.port}").registers)

    def write_registers(self, address: int, values: Sequence[int]) -> None:
        try:
            r = self._client.write_registers(address, list(values), device_id=self.unit_id)
        except (ModbusException, OSError) as exc:
            raise ModbusFault("timeout", f"{self.settings.port}: write: {exc}") from None
        _raise_on_error(r, f"{self.settings.port}: write")

    def read_holding(self, address: int, count: int) -> list[int]:
        return self.read(3, address, count)

    @property
    def connected(self) -> bool:
        return bool(self._client.connected)

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


def _valid_frame(data: bytes) -> bool:
    return len(data) >= 4 and FramerRTU.compute_CRC(data[:-2]) == int.from_bytes(data[-2:], "big")

