"""What every stream detector is to the code that runs it: the pipeline, the offline
path and the evaluation rely on this and nothing more, whichever method decides (a
built-in one or a plug-in's)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Protocol

import numpy as np

from .updates import Update


class Detector(Protocol):
    """A streaming detector: frames in, in time order; updates out, one per hop."""

    @property
    def dropped(self) -> int:
        """Frames refused for their time (repeated, backward, or no time at all)."""
        ...

    @property
    def time_faults(self) -> Mapping[str, int]:
        """Those frames by kind (``hygiene.TIME_FAULTS``' names; they sum to :attr:`dropped`)."""
        ...

    def push(self, t: float, forces: np.ndarray, flags: int = 0) -> list[Update]:
        """One frame (``t`` in s, ``forces`` in N, row-major); the updates it completes."""
        ...

    def feed(self, t: np.ndarray, forces: np.ndarray, flags: np.ndarray | None = None) -> list[Update]:
        """Many frames at once: the updates :meth:`push` would give, frame by frame."""
        ...
