"""Detector output: one :class:`Update` per hop (streaming), or an :class:`UpdateTable`
of the same columns for a whole recording (batch)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

#: Output columns, in file order; the first four are fixed by the CSV contract, and new
#: columns are appended (``score_a`` and ``score_b``: the deciding method's own scores).
COLUMNS: tuple[str, ...] = ("t", "r_coe", "r_dw", "state", "valid", "f_sum", "xc", "yc", "flags",
                            "score_a", "score_b")


class Update(NamedTuple):
    """One detector decision.  A named tuple, not a frozen dataclass: a detector that
    decides every 10 ms builds one per frame at 100 Hz, and a frozen dataclass's
    ``__init__`` calls ``object.__setattr__`` once per field (docs/benchmarks.md)."""

    t: float  #: time of the newest frame the update used (s)
    #: The paper's decorrelation indicator R_coe (0 when stable), whatever method
    #: decides: computed with the paper's settings on the same frames, and held between
    #: the paper's hops when the deciding method's hop is shorter.
    r_coe: float
    r_dw: float  #: the paper's wavelet indicator R_dw, likewise
    state: int  #: :class:`~eskin_industrial.detect.state.GraspState` code
    valid: bool  #: False while the indicators are not defined (warm-up, short window)
    f_sum: float  #: total force of the newest frame (N)
    xc: float  #: centre of force of the newest frame (mm; held while out of contact)
    yc: float
    flags: int  #: OR of the hop's frame flags plus WARMUP / SHORT_WINDOW / RESET
    #: The deciding method's own two scores (what each means: the method's
    #: ``SCORES`` in ``detect/methods.py``); the paper's are its R_coe and R_dw again.
    score_a: float = 0.0
    score_b: float = 0.0


def state_changed(before: Update | None, update: Update) -> bool:
    """The one definition of a state change, for the STATE_CHANGES register and the
    ``state_changes`` counter alike: ``update``'s state code differs from the previous
    update's.  The first update changes nothing, and a change of validity alone (a
    warm-up after a gap) is none: DATA_VALID says that."""
    return before is not None and before.state != update.state


@dataclass(frozen=True)
class UpdateTable:
    """Columns of updates; ``len()`` is the number of updates."""

    t: np.ndarray
    r_coe: np.ndarray
    r_dw: np.ndarray
    state: np.ndarray
    valid: np.ndarray
    f_sum: np.ndarray
    xc: np.ndarray
    yc: np.ndarray
    flags: np.ndarray
    score_a: np.ndarray
    score_b: np.ndarray

    def __len__(self) -> int:
        return len(self.t)

    @classmethod
    def from_updates(cls, updates: list[Update]) -> UpdateTable:
        cols = {}
        for name in Update._fields:
            dtype = np.int64 if name in ("state", "flags") else bool if name == "valid" else np.float64
            cols[name] = np.array([getattr(u, name) for u in updates], dtype=dtype)
        return cls(**cols)
