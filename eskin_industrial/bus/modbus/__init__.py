"""The Modbus RTU sensor-node source (:mod:`.rtu`) and its pure scan register codec
(:mod:`.codec`); the protocol itself is :mod:`eskin_industrial.modbus`."""
