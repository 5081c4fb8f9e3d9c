"""matplotlib for the evaluation's charts: an extra, imported only when a chart is drawn."""

from __future__ import annotations

from typing import Any


def pyplot() -> Any:
    """``matplotlib.pyplot`` on the Agg backend (files, no display), or a one-line
    error naming the extra to install."""
    try:
        import matplotlib
    except ImportError:
        from ..errors import MissingExtra

        raise MissingExtra.of("the evaluation charts", "matplotlib", "plot") from None

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt
