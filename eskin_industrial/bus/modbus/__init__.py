"""Modbus: every pymodbus call (:mod:`.io`), the pure scan register codec and
exception codes (:mod:`.codec`), and the RTU sensor-node source (:mod:`.rtu`)."""
