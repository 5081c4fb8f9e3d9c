"""How long work reports how far it has got, without knowing who shows it.

Reading a large recording or CAN log, writing a long scene, scoring methods over
many scenes and seeds: each takes a :class:`Progress` and tells it what stretch of
work starts (:meth:`Progress.stage`) and how much of it is done
(:meth:`Progress.advance`).  The command line hands in a bar on stderr
(``cli/console.py``, only on a terminal); everything else gets :data:`NO_PROGRESS`,
which does nothing.  The work itself never depends on it: the same steps run, in
the same order, whether anyone watches or not.
"""

from __future__ import annotations

from typing import Protocol


class Progress(Protocol):
    def stage(self, label: str, total: int, percent: bool = False) -> None:
        """A stretch of ``total`` steps starts; ``percent``: show the share done
        rather than the count (bytes of a file, characters of a text)."""

    def advance(self, n: int = 1, label: str | None = None) -> None:
        """``n`` more steps done; ``label``, if given, names the work just done."""


class _NoProgress:
    def stage(self, label: str, total: int, percent: bool = False) -> None:
        pass

    def advance(self, n: int = 1, label: str | None = None) -> None:
        pass


#: Progress nobody watches.
NO_PROGRESS: Progress = _NoProgress()


class Prefixed:
    """Another progress with ``prefix`` before every label (a family's name before
    its scenes')."""

    def __init__(self, inner: Progress, prefix: str) -> None:
        self._inner = inner
        self._prefix = prefix

    def stage(self, label: str, total: int, percent: bool = False) -> None:
        self._inner.stage(self._prefix + label, total, percent)

    def advance(self, n: int = 1, label: str | None = None) -> None:
        self._inner.advance(n, None if label is None else self._prefix + label)
