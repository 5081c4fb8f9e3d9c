"""The live terminal view of ``eskin-bus demo`` and ``eskin-bus monitor``.

- :mod:`.snapshot`: what one screen shows, as plain values (pure);
- :mod:`.screen`: the renderer, snapshot in, lines out (pure);
- :mod:`.terminal`: the terminal driver (alternate screen, capped redraw rate);
- :mod:`.live`: snapshots from a running chain's newest values.
"""

from ..plc.image import decode_registers
from .screen import render
from .snapshot import IndicatorScale, Snapshot, indicator_scale, status_names
from .terminal import LiveScreen, color_wanted

__all__ = ["IndicatorScale", "LiveScreen", "Snapshot", "color_wanted", "decode_registers", "indicator_scale",
           "render", "status_names"]
