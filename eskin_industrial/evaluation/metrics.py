"""Scoring detector output against ground-truth labels: pure functions, no I/O.

Definitions (also in docs/evaluation.md):
- a slip *event* is a maximal run of frames labelled ``slip``; it is *found* when some
  update in [onset, end + tolerance_s] reads ``slip``; the delay is the time of the
  first such update minus the onset;
- a *flag episode* is a maximal run of consecutive updates reading ``slip``; an
  episode is a *false alarm* when none of its updates falls in an event's
  [onset, end + tolerance_s] and not all of them fall in ``transition`` spans;
- *holding time* is the time labelled ``stable`` or ``variable_force``;
- *variable force read as slip*: false-alarm episodes that start in a
  ``variable_force`` span (the paper's central claim is that there are none).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..detect.state import GraspState
from ..detect.updates import UpdateTable

_SLIP = int(GraspState.SLIP)


def spans(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) index pairs of the runs of True in ``mask``."""
    m = np.concatenate(([False], np.asarray(mask, bool), [False]))
    edges = np.flatnonzero(m[1:] != m[:-1])
    return list(zip(edges[::2].tolist(), edges[1::2].tolist()))


@dataclass
class SceneScore:
    events: int = 0
    found: int = 0
    false_alarms: int = 0
    vf_as_slip: int = 0
    holding_s: float = 0.0
    delays_s: list[float] = field(default_factory=list)

    def __iadd__(self, other: "SceneScore") -> "SceneScore":
        self.events += other.events
        self.found += other.found
        self.false_alarms += other.false_alarms
        self.vf_as_slip += other.vf_as_slip
        self.holding_s += other.holding_s
        self.delays_s += other.delays_s
        return self

    @property
    def precision(self) -> float:
        flagged = self.found + self.false_alarms
        return self.found / flagged if flagged else 1.0

    @property
    def recall(self) -> float:
        return self.found / self.events if self.events else 1.0

    @property
    def f1(self) -> float:
        p, r = self.precision, self.recall
        return 2 * p * r / (p + r) if p + r else 0.0

    @property
    def false_alarms_per_hour(self) -> float:
        return self.false_alarms / (self.holding_s / 3600.0) if self.holding_s else 0.0

    def delay_percentile(self, q: float) -> float:
        return float(np.percentile(self.delays_s, q)) if self.delays_s else float("nan")


def score_scene(updates: UpdateTable, t: np.ndarray, labels: np.ndarray, tolerance_s: float = 0.5) -> SceneScore:
    """Score one run of a detector on one rendered scene (frame times ``t``, ``labels``)."""
    out = SceneScore()
    labels = np.asarray(labels)
    dt = np.diff(t, append=t[-1] + (t[-1] - t[-2] if len(t) > 1 else 0.0))
    holding = (labels == "stable") | (labels == "variable_force")
    out.holding_s = float(dt[holding].sum())
    # label at each update: that of the newest frame at or before it
    idx = np.clip(np.searchsorted(t, updates.t, side="right") - 1, 0, len(t) - 1)
    up_label = labels[idx]
    flagged = updates.state == _SLIP
    credited = np.zeros(len(updates), bool)
    for a, b in spans(labels == "slip"):
        out.events += 1
        onset, end = t[a], t[b - 1] + tolerance_s
        inside = (updates.t >= onset) & (updates.t <= end)
        hits = np.flatnonzero(inside & flagged)
        credited |= inside
        if hits.size:
            out.found += 1
            out.delays_s.append(float(updates.t[hits[0]] - onset))
    for a, b in spans(flagged):
        if credited[a:b].any() or (up_label[a:b] == "transition").all():
            continue
        out.false_alarms += 1
        if up_label[a] == "variable_force":
            out.vf_as_slip += 1
    return out
