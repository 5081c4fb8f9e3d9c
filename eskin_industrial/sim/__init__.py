"""Simulators beside the real parts: sensor nodes that send what a real node sends
(CAN, Modbus RTU), a PLC stand-in with example gripper logic, and the demo that wires
them to the real bridge.  No real source or sink imports this package."""
