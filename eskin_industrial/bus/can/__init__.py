"""CAN and CAN FD: the pure frame layout codec and DBC, the bus reader thread, the
scan source, the shared-bus router and the log reader."""
