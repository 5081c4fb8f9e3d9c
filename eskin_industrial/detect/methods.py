"""Detection methods by name, so that the CLI, the evaluation and the bridge can run
any of them through one loop (the way python-can finds an interface by name).

Each entry gives a streaming factory ``(settings, x_mm, y_mm, rate_hz) -> detector``
(with ``push(t, forces, flags) -> list[Update]``) and a batch function
``(settings, x_mm, y_mm, rate_hz, t, forces, flags) -> UpdateTable``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

from .paper import PaperDetector, paper_batch


@dataclass(frozen=True)
class Method:
    name: str
    summary: str
    stream: Callable[..., Any]
    batch: Callable[..., Any]


METHODS: dict[str, Method] = {
    "paper": Method("paper", "R_coe and R_dw both above their slip thresholds (the reference paper)", PaperDetector, paper_batch),
}


def get_method(name: str) -> Method:
    try:
        return METHODS[name]
    except KeyError:
        raise KeyError(f"unknown detection method {name!r}; known: {', '.join(sorted(METHODS))}") from None
