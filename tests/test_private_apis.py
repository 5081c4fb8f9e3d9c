"""The three places the package reaches past a library's public API, pinned: when a
release moves them, this names what moved (docs/architecture.md says why each is
used).  The behaviour behind each is tested elsewhere: the SocketCAN drain in
tests/vcan, the PLC stand-in's pymodbus TCP server (eskin_industrial/modbus/pymodbus_io.py)
wherever the PLC client writes to a stand-in."""

from __future__ import annotations

import inspect

import can
import pymodbus
from pymodbus.datastore import ModbusServerContext


def test_python_cans_socketcan_capture_message() -> None:
    from can.interfaces.socketcan.socketcan import capture_message

    assert list(inspect.signature(capture_message).parameters) == ["sock", "get_channel"]
    assert can.__version__.startswith(("4.4", "4.5", "4.6"))  # pyproject.toml: python-can>=4.4,<4.7


def test_pymodbus_server_context_hooks_of_the_plc_stand_in() -> None:
    from eskin_industrial.modbus.pymodbus_io import _HandlerContext

    # The package's context is the one that leans on these hooks.
    assert issubclass(_HandlerContext, ModbusServerContext)
    for hook in ("async_getValues", "async_setValues", "device_ids"):
        assert hook in vars(_HandlerContext)
    get = inspect.signature(ModbusServerContext.async_getValues).parameters
    put = inspect.signature(ModbusServerContext.async_setValues).parameters
    assert list(get) == ["self", "device_id", "func_code", "address", "count"]
    assert list(put) == ["self", "device_id", "func_code", "address", "values"]
    assert list(inspect.signature(_HandlerContext.async_getValues).parameters) == list(get)
    assert list(inspect.signature(_HandlerContext.async_setValues).parameters) == list(put)
    assert inspect.iscoroutinefunction(ModbusServerContext.async_getValues)
    assert callable(ModbusServerContext.device_ids)
    # The server reads these two attributes, which only __init__ sets (the package's
    # context does not call it: it has no datastore of pymodbus' kind).
    init = inspect.getsource(ModbusServerContext.__init__)
    assert "self.old_simulator" in init and "self.simdevices" in init
    assert pymodbus.__version__.startswith("3.16")  # pyproject.toml: pymodbus>=3.16,<3.17


def test_paho_closes_its_wake_up_socket_pair_on_reset() -> None:
    import paho.mqtt.client as mqtt

    client = mqtt.Client(callback_api_version=mqtt.CallbackAPIVersion.VERSION2)
    client.loop_start()  # opens the pair
    client.loop_stop()
    pair = (client._sockpairR, client._sockpairW)
    assert all(sock is not None and sock.fileno() >= 0 for sock in pair)  # still open after loop_stop
    client._reset_sockets()
    assert all(sock.fileno() == -1 for sock in pair)
