"""A python-can interface that records what it was opened with: a stand-in for a
hardware adapter (PCAN, Kvaser, ...), whose bit rate this machine cannot show.
Registered under the name ``recording`` by :func:`register`; frames pass as on
python-can's virtual bus."""

from __future__ import annotations

from typing import Any

import can
import can.interfaces
import can.util
import pytest
from can.interfaces.virtual import VirtualBus


class RecordingBus(VirtualBus):
    opened: list[dict[str, Any]] = []

    def __init__(self, channel: Any = None, **kwargs: Any) -> None:
        RecordingBus.opened.append({"channel": channel, **kwargs})
        super().__init__(channel=channel, **kwargs)


def register(monkeypatch: pytest.MonkeyPatch) -> list[dict[str, Any]]:
    """Make ``recording`` a valid interface for this test, with python-can's own
    configuration sources cleared (no config file, no CAN_* variables, no can.rc);
    returns the list each opening appends its keyword arguments to."""
    monkeypatch.setitem(can.interfaces.BACKENDS, "recording", (__name__, "RecordingBus"))
    valid = frozenset(can.interfaces.VALID_INTERFACES | {"recording"})
    for module in (can, can.interfaces, can.util):
        monkeypatch.setattr(module, "VALID_INTERFACES", valid)
    monkeypatch.setattr(can, "rc", {})
    for var in ("CAN_INTERFACE", "CAN_CHANNEL", "CAN_BITRATE", "CAN_CONFIG"):
        monkeypatch.delenv(var, raising=False)
    RecordingBus.opened = []
    return RecordingBus.opened
