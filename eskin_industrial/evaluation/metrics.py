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
  ``variable_force`` span (the paper's central claim is that there are none);
- a found event's *slip episodes*: the flag episodes that have an update in its
  [onset, end + tolerance_s]; one slide read as one slip makes 1, a slip that
  flickers off and on during it more (each entry a new SLIP_EVENTS count for the PLC);
- a missed event is *flagged unseen* when every update in contact from its onset to
  its end carried TURN_UNSEEN: the detector said a turn there would read ``stable``
  (for a turn, the defined degraded behaviour; the bit says nothing of slides, so a
  slide missed on such a contact counts too); the *unseen share* is the share of
  holding time in which the newest update carried TURN_UNSEEN.

Stability of the reported state (what a PLC acts on); the state "in effect" at a
frame is that of the newest update at or before it, and a *state change* is an
update whose state differs from the update before it:
- a varying-force *episode* is a maximal run of frames labelled ``variable_force``;
  it is *found* when an update inside it reads ``variable_force``;
- its *coverage* is the share of its time after the first ``VF_GRACE_S`` in which
  ``variable_force`` is in effect (pooled over episodes, and per episode);
- its *changes* are the state changes from its onset to ``EXIT_ALLOWANCE_S`` after
  its end (the exit belongs to the episode), cut at the next span not labelled
  ``stable``: one entry and one exit make 2;
- changes per minute *inside varying-force spans*: changes at updates inside
  ``variable_force`` labels, per minute of such labels;
- changes per minute *while holding*: changes at updates labelled ``stable`` or
  ``variable_force``, per minute of holding time (the charts' measure);
- changes per minute *in still holds*: changes at updates inside *still* time, per
  minute of it: frames labelled ``stable`` at least ``EXIT_ALLOWANCE_S`` after the
  last frame labelled anything else (the state may take that long to come back
  after a grab, a slide or a varying force);
- how fast the states come and go: a varying-force episode is *entered* at its first
  update reading ``variable_force`` from its onset on (before ``EXIT_ALLOWANCE_S``
  after its end), and *left* at the first update from its end on that reads
  anything else (before the next span not labelled ``stable``); a found slip event
  is left at the first update after its end not reading ``slip``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..detect.state import GraspState
from ..detect.updates import UpdateTable
from ..frames import FrameFlag

_SLIP = int(GraspState.SLIP)
_VARIABLE = int(GraspState.VARIABLE_FORCE)
_UNSEEN = int(FrameFlag.TURN_UNSEEN)

#: The first this long of a varying-force episode is not counted in its coverage (the
#: force has hardly changed yet).
VF_GRACE_S = 0.15
#: A state change this long after a span not labelled ``stable`` ends is that span's
#: exit, not a change in a still hold.
EXIT_ALLOWANCE_S = 1.0


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
    # -- stability of the reported state (the module's doc) --
    vf_episodes: int = 0
    vf_found: int = 0
    vf_coverages: list[float] = field(default_factory=list)  #: per episode (after the grace time)
    vf_counted_s: float = 0.0  #: episode time after the grace time
    vf_covered_s: float = 0.0  #: ... in which variable_force was in effect
    vf_episode_changes: list[int] = field(default_factory=list)  #: per episode
    vf_span_s: float = 0.0
    vf_span_changes: int = 0
    still_s: float = 0.0
    still_changes: int = 0
    holding_changes: int = 0  #: changes at updates labelled stable or variable_force
    vf_entry_s: list[float] = field(default_factory=list)  #: episode onset -> variable_force
    vf_exit_s: list[float] = field(default_factory=list)  #: episode end -> any other state
    slip_exit_s: list[float] = field(default_factory=list)  #: slip event end -> any other state
    slip_episodes: list[int] = field(default_factory=list)  #: flag episodes per found event
    missed_unseen: int = 0  #: missed events flagged unseen (the module's doc)
    unseen_s: float = 0.0  #: holding time with TURN_UNSEEN in effect

    def __iadd__(self, other: SceneScore) -> SceneScore:
        self.events += other.events
        self.found += other.found
        self.false_alarms += other.false_alarms
        self.vf_as_slip += other.vf_as_slip
        self.holding_s += other.holding_s
        self.delays_s += other.delays_s
        self.vf_episodes += other.vf_episodes
        self.vf_found += other.vf_found
        self.vf_coverages += other.vf_coverages
        self.vf_counted_s += other.vf_counted_s
        self.vf_covered_s += other.vf_covered_s
        self.vf_episode_changes += other.vf_episode_changes
        self.vf_span_s += other.vf_span_s
        self.vf_span_changes += other.vf_span_changes
        self.still_s += other.still_s
        self.still_changes += other.still_changes
        self.holding_changes += other.holding_changes
        self.vf_entry_s += other.vf_entry_s
        self.vf_exit_s += other.vf_exit_s
        self.slip_exit_s += other.slip_exit_s
        self.slip_episodes += other.slip_episodes
        self.missed_unseen += other.missed_unseen
        self.unseen_s += other.unseen_s
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

    @staticmethod
    def percentile(values: list[float], q: float) -> float:
        return float(np.percentile(values, q)) if values else float("nan")

    @property
    def vf_recall(self) -> float:
        return self.vf_found / self.vf_episodes if self.vf_episodes else float("nan")

    @property
    def vf_coverage(self) -> float:
        """Pooled: covered time over counted time of all episodes."""
        return self.vf_covered_s / self.vf_counted_s if self.vf_counted_s else float("nan")

    def vf_covered_share(self, at_least: float = 0.9) -> float:
        """Share of episodes with at least ``at_least`` of their time covered."""
        c = self.vf_coverages
        return sum(1 for v in c if v >= at_least) / len(c) if c else float("nan")

    @property
    def vf_changes_per_min(self) -> float:
        return self.vf_span_changes / (self.vf_span_s / 60.0) if self.vf_span_s else float("nan")

    @property
    def holding_changes_per_min(self) -> float:
        """Every state change while holding (labelled stable or variable_force), per minute of it."""
        return self.holding_changes / (self.holding_s / 60.0) if self.holding_s else float("nan")

    @property
    def unseen_share(self) -> float:
        return self.unseen_s / self.holding_s if self.holding_s else float("nan")

    @property
    def still_changes_per_min(self) -> float:
        return self.still_changes / (self.still_s / 60.0) if self.still_s else float("nan")


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
    # each update's flag episode (its count from 1; 0 when not flagged)
    episode = np.where(flagged, np.cumsum(flagged & ~np.concatenate(([False], flagged[:-1]))), 0)
    unseen = (np.asarray(updates.flags) & _UNSEEN) != 0
    eff = np.searchsorted(updates.t, t, side="right") - 1  # the newest update at each frame
    out.unseen_s = float(dt[holding & (eff >= 0) & unseen[np.maximum(eff, 0)]].sum()) if len(updates) else 0.0
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
            out.slip_episodes.append(int(np.unique(episode[hits]).size))
            stop = t[b - 1] + dt[b - 1]
            after = np.flatnonzero((updates.t >= stop) & ~flagged)
            if after.size:
                out.slip_exit_s.append(float(updates.t[after[0]] - stop))
        else:
            touching = (updates.t >= onset) & (updates.t <= t[b - 1]) & (updates.state != 0)
            out.missed_unseen += int(touching.any() and unseen[touching].all())
    for a, b in spans(flagged):
        if credited[a:b].any() or (up_label[a:b] == "transition").all():
            continue
        out.false_alarms += 1
        if up_label[a] == "variable_force":
            out.vf_as_slip += 1
    _score_stability(out, updates, t, dt, labels, idx)
    return out


def _score_stability(out: SceneScore, updates: UpdateTable, t: np.ndarray, dt: np.ndarray, labels: np.ndarray,
                     up_idx: np.ndarray) -> None:
    """The stability figures (the module's doc) into ``out``."""
    state = np.asarray(updates.state)
    # the state in effect at each frame: the newest update at or before it (-1 before any)
    eff = np.searchsorted(updates.t, t, side="right") - 1
    in_effect = np.where(eff >= 0, state[np.maximum(eff, 0)], -1)
    changed = np.zeros(len(state), bool)
    changed[1:] = state[1:] != state[:-1]
    change_t = np.asarray(updates.t)[changed]
    change_label = labels[up_idx][changed]
    vf = labels == "variable_force"
    stable = labels == "stable"
    other = ~stable
    # end of the newest frame labelled other than stable, at each frame
    other_end = np.maximum.accumulate(np.where(other, t + dt, -np.inf))
    still = stable & (t - other_end >= EXIT_ALLOWANCE_S - 1e-9)
    out.still_s += float(dt[still].sum())
    out.still_changes += int(still[up_idx][changed].sum())
    out.vf_span_s += float(dt[vf].sum())
    out.vf_span_changes += int((change_label == "variable_force").sum())
    out.holding_changes += int(((change_label == "variable_force") | (change_label == "stable")).sum())
    for a, b in spans(vf):
        out.vf_episodes += 1
        onset, end = t[a], t[b - 1] + dt[b - 1]
        inside_up = (updates.t >= onset) & (updates.t < end)
        out.vf_found += int((state[inside_up] == _VARIABLE).any())
        counted = (np.arange(len(t)) >= a) & (np.arange(len(t)) < b) & (t >= onset + VF_GRACE_S - 1e-9)
        span_s = float(dt[counted].sum())
        covered_s = float(dt[counted & (in_effect == _VARIABLE)].sum())
        out.vf_counted_s += span_s
        out.vf_covered_s += covered_s
        out.vf_coverages.append(covered_s / span_s if span_s > 0 else 1.0)
        nxt = np.flatnonzero(other[b:])
        next_t = t[b + nxt[0]] if nxt.size else np.inf
        limit = min(end + EXIT_ALLOWANCE_S, next_t)
        out.vf_episode_changes.append(int(((change_t >= onset) & (change_t < limit)).sum()))
        up_t = np.asarray(updates.t)
        entered = np.flatnonzero((up_t >= onset) & (up_t < limit) & (state == _VARIABLE))
        if entered.size:
            out.vf_entry_s.append(float(up_t[entered[0]] - onset))
            left = np.flatnonzero((up_t >= end) & (up_t < next_t) & (state != _VARIABLE))
            if left.size:
                out.vf_exit_s.append(float(up_t[left[0]] - end))
