"""Shared pieces of the tests (no tests and no fixtures here; fixtures live in conftest.py).

- :mod:`tests.helpers.paths`: the checkout's root and its profiles.
- :mod:`tests.helpers.scenes`: synthetic grasps and short scene files.
- :mod:`tests.helpers.modbus`: socat pty pairs, free ports, mbpoll, recordings with a slip.
- :mod:`tests.helpers.bridge`: the bridge run in-process, virtual CAN nodes, a timed PLC.
- :mod:`tests.helpers.fuzz`: reproducible hypothesis settings.
- :mod:`tests.helpers.leaks`: the check that fails a test leaving threads, sockets or
  virtual CAN buses behind.
"""
