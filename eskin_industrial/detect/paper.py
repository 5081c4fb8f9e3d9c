"""The paper's method, end to end: indicators, then the state machine.

:class:`PaperDetector` is the streaming form (frames in, updates out);
:func:`paper_batch` the vectorized form over a recording.  They give the same updates.
"""

from __future__ import annotations

import numpy as np

from ..frames import Frame, FrameFlag
from .hygiene import feed
from .indicators import segment_indicators
from .regularize import regularize
from .settings import DetectorSettings
from .state import ContactRule, StateMachine
from .stream import IndicatorStream
from .updates import COLUMNS, Update, UpdateTable
from .vforce import force_variation_batch


class PaperDetector:
    """Streaming detector: :meth:`push` one frame, get the updates it completes."""

    name = "paper"

    def __init__(self, settings: DetectorSettings, x_mm: np.ndarray, y_mm: np.ndarray, rate_hz: float) -> None:
        self.settings = settings
        self.indicators = IndicatorStream(settings, x_mm, y_mm, rate_hz)
        self.machine = StateMachine(settings)

    @property
    def dropped(self) -> int:
        return self.indicators.dropped

    @property
    def time_faults(self) -> dict[str, int]:
        return self.indicators.time_faults

    def push(self, t: float, forces: np.ndarray, flags: int = 0) -> list[Update]:
        raw = self.indicators.push(t, forces, flags)
        if not raw:
            return []
        step = self.machine.step
        return [
            # the paper's own scores are its indicators: the same floats, computed once
            Update(te, rc, rd, step(te, rc, rd, contact, valid, vf), valid, s, xc, yc, fl, rc, rd)
            for te, rc, rd, valid, fl, s, xc, yc, contact, vf in raw
        ]

    def push_frame(self, frame: Frame) -> list[Update]:
        return self.push(frame.t, frame.forces, frame.flags)

    def feed(self, t: np.ndarray, forces: np.ndarray, flags: np.ndarray | None = None) -> list[Update]:
        """Push a chunk of frames in order; returns all updates they complete."""
        return feed(self.push, t, forces, flags)


def paper_batch(
    settings: DetectorSettings, x_mm: np.ndarray, y_mm: np.ndarray, rate_hz: float,
    t: np.ndarray, forces: np.ndarray, flags: np.ndarray | None = None,
) -> UpdateTable:
    """All updates of a recording at once; equal to feeding it to :class:`PaperDetector`."""
    geo = settings.geometry(rate_hz)
    reg = regularize(t, forces, rate_hz, geo.max_fill, flags)
    mat = np.column_stack([np.ones(len(x_mm)), x_mm, y_mm]).astype(np.float64)
    parts: list[dict[str, np.ndarray]] = []
    own = settings.varying_force.evidence == "method"
    for a, b in reg.segments:
        ind, sums, cof = segment_indicators(reg.forces[a:b], reg.flags[a:b], mat, settings, geo)
        end = ind.end
        s = sums[end, 0]
        parts.append({
            "t": reg.t[a:b][end], "r_coe": ind.r_coe, "r_dw": ind.r_dw, "valid": ind.valid,
            "f_sum": s, "xc": cof[end, 0], "yc": cof[end, 1], "flags": ind.flags,
            "contact": ind.contact,
            "vf": np.zeros(len(end)) if own else _hop_vf(sums[:, 0], reg.flags[a:b], end, settings, geo.hop, rate_hz),
        })
    if not parts:
        return UpdateTable(**{c: np.zeros(0, np.int64 if c in ("state", "flags") else bool if c == "valid" else float) for c in COLUMNS})
    cols = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    machine = StateMachine(settings)
    state = np.fromiter(
        (machine.step(te, rc, rd, bool(c), bool(v), vf) for te, rc, rd, c, v, vf in zip(
            cols["t"].tolist(), cols["r_coe"].tolist(), cols["r_dw"].tolist(), cols["contact"].tolist(),
            cols["valid"].tolist(), cols["vf"].tolist())),
        dtype=np.int64, count=len(cols["t"]),
    )
    del cols["contact"], cols["vf"]
    return UpdateTable(state=state, score_a=cols["r_coe"], score_b=cols["r_dw"], **cols)


def _hop_vf(s: np.ndarray, flags: np.ndarray, end: np.ndarray, settings: DetectorSettings, hop: int,
            rate_hz: float) -> np.ndarray:
    """Each update's largest varying-force score over its hop (the frames end - hop + 1 .. end)."""
    contact = ContactRule.from_settings(settings, rate_hz).mask(s)
    score = force_variation_batch(s, contact, (flags & int(FrameFlag.FILLED)) != 0, settings.varying_force, rate_hz)
    return np.array([score[e - hop + 1:e + 1].max() for e in end.tolist()]) if len(end) else np.zeros(0)
