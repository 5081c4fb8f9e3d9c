"""The PLC side: the pure register image (:mod:`.image`), and the two Modbus sinks
that move it, writing into the PLC (:mod:`.client`) or serving it (:mod:`.server`)."""
