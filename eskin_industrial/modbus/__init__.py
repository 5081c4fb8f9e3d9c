"""The Modbus protocol, shared by the RTU source (``bus/modbus``), the PLC sink
(``plc``) and the simulators; it imports nothing of the package above its bottom
modules (``errors``, ``netaddr``).

Pure, bytes or numbers in and out, no threads and no sockets: :mod:`.pdu` (a
server's answers), :mod:`.mbap` (TCP framing), :mod:`.rtu_frame` (RTU framing),
:mod:`.exception_codes`, :mod:`.words` (a 32-bit value in two registers),
:mod:`.serial_line` (a line's settings and timing).

Moving the bytes: our servers, :mod:`.tcp_server` (with an access policy) and
:mod:`.rtu_server`, sharing :mod:`.serving`; our TCP master :mod:`.tcp_master` (the
PLC client's, pipelined); and every pymodbus call, :mod:`.pymodbus_io` (the RTU
master, and a third-party TCP server and client for the stand-ins and the tests).
"""
