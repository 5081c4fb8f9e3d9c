"""Sinks: the output seam.  Each kind takes a node's detector updates and register
publications (the PLC, a recorder); see :mod:`.base` for the contract and the registry
of kinds."""
