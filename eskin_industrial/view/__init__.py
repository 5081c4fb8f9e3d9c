"""The live terminal view of ``eskin-bus demo`` and ``eskin-bus monitor``.

- :mod:`.snapshot`: what one screen shows, as plain values (pure);
- :mod:`.screen`: the renderer, snapshot in, lines out (pure);
- :mod:`.terminal`: the terminal driver (alternate screen, capped redraw rate);
- :mod:`.live`: snapshots from a running chain's newest values.
"""

from .screen import render
from .snapshot import IndicatorScale, RegisterTable, Snapshot, indicator_scale
from .terminal import LiveScreen, color_wanted

__all__ = ["IndicatorScale", "LiveScreen", "RegisterTable", "Snapshot", "color_wanted", "indicator_scale", "render"]
