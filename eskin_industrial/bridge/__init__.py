"""The bridge as a long-running process: configuration (``config``), the threads
that run each node (``runtime``, ``can_group``) and its structured logs (``logs``).
The per-node loop itself is :class:`~eskin_industrial.bus.modbus_bridge.ModbusBridge`."""
