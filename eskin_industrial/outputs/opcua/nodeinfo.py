"""What the model says about one node: made on the bridge's side, handed to the
server's process (no asyncua here: the bridge's process does not import it)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class NodeInfo:
    """What the model says about one node, from its configuration and profile."""

    name: str
    score_names: tuple[str, str]
    score_docs: tuple[str, str]
    identification: dict[str, str]
    force_range: tuple[float, float]
    x_range: tuple[float, float]
    y_range: tuple[float, float]
    #: rows x cols of the taxel frame, when it is published
    frame_shape: tuple[int, int] | None = None
    frame_range: tuple[float, float] = (0.0, 0.0)
