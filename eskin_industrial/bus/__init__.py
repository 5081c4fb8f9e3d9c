"""Sources: the input seam.  Each kind turns a transport (CAN, Modbus RTU, a CAN log,
a recording or scene replay) into raw scans and reports its health and counters;
see :mod:`.source` for the contract and the registry of kinds."""
