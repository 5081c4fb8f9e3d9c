"""Transports: each source turns CAN, Modbus RTU or a recorded log into raw scans and
counts what it lost; sinks publish the register image to a PLC."""
