"""The device identity: ``[identity]`` of the bridge configuration, one section that
every output naming the device reads (the PLC server's device identification,
FC43/14 and FC17; the OPC UA nameplate of each node).

A module of its own, below the outputs: each output reads it without importing
another output.  A profile's ``[modbus.plc.identity]`` of earlier releases still
loads (:mod:`eskin_industrial.profile`, with a deprecation warning) and is used when
the bridge configuration has no ``[identity]``.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class DeviceIdentity:
    """``[identity]``: who made the device, what it is, which revision."""

    vendor_name: str = "eskin-industrial"
    product_code: str = "eskin-bus"
    #: Empty: the package's version.
    revision: str = ""
    vendor_url: str = ""
    product_name: str = "eskin-industrial bridge"
    #: Empty: the node's profile's ``[sensor] name``.
    model_name: str = ""
