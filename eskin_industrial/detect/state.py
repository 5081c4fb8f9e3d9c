"""Grasp states, and the one decision every method ends in.

Every detector, the paper's and the per-frame scored ones alike, reduces a hop of
frames to the same four facts: is the array in contact, is the verdict valid, is
there slip evidence, how strong is the varying-force evidence.  :class:`Decision`
turns those into the reported state, with the same rules for all methods (the
policy a PLC program relies on: docs/plc.md):

- out of contact: ``no_contact`` at once;
- in contact but not valid (warm-up after a start or a reset, a window too short for
  the wavelet): the previous state is kept, and ``no_contact`` becomes ``stable``;
  an update that does not know never reports anything confident (its ``valid`` is 0,
  which the PLC sees);
- slip evidence for ``confirm`` consecutive updates: ``slip`` at once, whatever the
  state; left once ``hold_s`` has passed without slip evidence (an off-delay, like a
  PLC's TOF timer: a slide whose evidence comes and goes, near its threshold, stays
  one slip, where a hold counted from the entry let it flicker off and on, each
  entry a new slip for the PLC);
- otherwise ``variable_force`` while the :class:`VaryingLatch` holds, else ``stable``.
  The latch is set at the first update whose varying-force score reaches 1 (or with
  slip evidence not yet confirmed), and cleared once the score has stayed below
  ``exit_fraction`` for ``exit_s`` and ``min_dwell_s`` have passed since it was set:
  one varying-force episode is one entry and one exit.

The score is, by default, the total force's own ramp test (``vforce.py``), the same
for every method; ``[detector.varying_force] evidence = "method"`` takes each
method's own evidence instead (a yes or no: 1 or 0), through the same latch.

Contact has one rule too, :class:`ContactRule`, applied to each frame's total force
by every method (the paper's indicators included, where it decides whether F_dis and
the centre of force are defined): contact begins when the loaded force (the total
minus the sensor's unloaded baseline, learnt out of contact) reaches
``contact_threshold_n`` (and five times the learnt noise), and lasts while it stays
above half of that, each change held for ``contact_dwell_s``.  A plain threshold
would make a first touch that hovers at the threshold, or an idle film whose offset
and noise reach it, toggle the PLC between ``no_contact`` and ``stable`` every few
frames, and restart a detector's warm-up each time.

What counts as slip evidence is each method's own: :class:`StateMachine` is the paper's
(R_coe and R_dw against their thresholds, with hysteresis) in front of a
:class:`Decision`; :class:`~eskin_industrial.detect.scored.ScoredDetector` votes per
frame and hands the hop's votes to its own :class:`Decision`.
"""

from __future__ import annotations

import copy
import enum
import math

import numpy as np

from .settings import DetectorSettings, VaryingForceSettings


class GraspState(enum.IntEnum):
    """State codes as the PLC sees them; ``label`` is the name used in files."""

    NO_CONTACT = 0
    STABLE = 1
    VARIABLE_FORCE = 2
    SLIP = 3

    @property
    def label(self) -> str:
        return self.name.lower()

    @classmethod
    def from_label(cls, label: str) -> GraspState:
        return cls[label.upper()]


LABELS: tuple[str, ...] = tuple(s.label for s in GraspState)

_NO_CONTACT, _STABLE, _VARIABLE, _SLIP = (int(s) for s in GraspState)


class ContactRule:
    """Contact, judged on each frame's total force against the sensor's learnt
    unloaded baseline and noise floor.

    Out of contact the rule learns the unloaded total (the offset of a piezoresistive
    film, its slow drift) as a running mean over ``baseline_s``, and its noise as a
    running RMS about it.  The loaded force is the total minus that baseline.  Contact
    begins once the loaded force has reached ``enter_n`` (and ``noise_k`` noise RMS,
    whichever is higher) for ``dwell_s``, and ends once it has stayed below
    :data:`STAY_FRACTION` of that (and ``noise_k`` / 2 RMS) for ``dwell_s``; a clear
    load (twice the entry level) or a clear release (below half the stay level)
    changes at once; never in contact at a total of zero.  An idle sensor reading 0.15 +- 0.04 N against a 0.2 N threshold
    thus stays out of contact, where a plain threshold made the PLC's CONTACT flap.

    The baseline is bounded so that it can never hide a real load: it learns only out
    of contact and below the stay level, moves at most ``baseline_max_n`` from zero,
    and starts at zero; the noise floor raises the threshold by at most as much.  A load
    of ``enter_n + 2 x baseline_max_n`` (0.7 N by default) is thus always contact,
    however slowly it crept on.  ``baseline_s = 0`` learns nothing (the plain
    hysteresis).

    For its first ``settle_s`` (after a start or a restart) the rule settles before it
    judges: nothing below that always-contact level enters contact, and a total below
    ``enter_n + baseline_max_n`` is learnt as the unloaded baseline and its noise.
    Without it, an idle film whose offset or rectified noise alone reads above the
    threshold from its first frame (0.3 N on a 5 x 5 array: 0.012 N of offset a
    taxel, or 0.03 N of noise, which a taxel reading no tension rectifies) entered
    contact before anything was learnt, and then never left it: ``stable`` with
    DATA_VALID, nothing gripped.  A sensor loaded from its first frame (a bridge
    restarted while a part is held) is in contact once the settling ends, and learns
    nothing.

    :meth:`touching` is the per-frame form (``was``, the previous answer, is kept by
    the rule itself; the argument stays for callers that restart it), :meth:`mask`
    the same rule over a run of frames from a fresh rule, so the batch answer is the
    streaming one by construction."""

    #: Contact, once made, lasts while the loaded force stays above this share of the threshold.
    STAY_FRACTION = 0.5

    __slots__ = ("enter_n", "stay_n", "noise_k", "dwell", "alpha", "max_n", "settle", "baseline", "var", "seen",
                 "on", "run", "age")

    def __init__(self, enter_n: float, *, rate_hz: float = 100.0, baseline_s: float = 0.0, dwell_s: float = 0.0,
                 noise_k: float = 5.0, baseline_max_n: float = 0.0, settle_s: float = 0.0) -> None:
        self.enter_n = enter_n
        self.stay_n = self.STAY_FRACTION * enter_n
        self.noise_k = noise_k
        self.dwell = max(int(round(dwell_s * rate_hz)), 1)  #: frames a change must hold
        self.alpha = 1.0 / (baseline_s * rate_hz) if baseline_s > 0 else 0.0
        self.max_n = baseline_max_n if baseline_s > 0 else 0.0
        #: frames of settling after a start (none without a baseline to learn)
        self.settle = int(round(settle_s * rate_hz)) if self.alpha else 0
        self.reset()

    def reset(self) -> None:
        self.baseline = 0.0
        self.var = 0.0
        self.seen = 0  #: unloaded frames learnt from (the mean's first steps are exact)
        self.on = False
        self.run = 0  #: consecutive frames that ask for the other answer
        self.age = 0  #: frames since the start, counted while it settles

    @classmethod
    def from_settings(cls, settings: DetectorSettings, rate_hz: float = 100.0) -> ContactRule:
        return cls(settings.contact_threshold_n, rate_hz=rate_hz, baseline_s=settings.contact_baseline_s,
                   dwell_s=settings.contact_dwell_s, noise_k=settings.contact_noise_k,
                   baseline_max_n=settings.contact_baseline_max_n, settle_s=settings.contact_settle_s)

    def levels(self) -> tuple[float, float]:
        """The loaded force that enters contact, and the one below which it ends."""
        # the noise floor raises the threshold by at most baseline_max_n, as the
        # baseline moves it: a load of enter_n + 2 x baseline_max_n is always contact
        floor = min(self.noise_k * math.sqrt(self.var), self.enter_n + self.max_n)
        return max(self.enter_n, floor), max(self.stay_n, 0.5 * floor)

    def touching(self, s: float, was: bool = False) -> bool:
        """Contact at total force ``s`` (frames in time order, one call each)."""
        if not s > 0.0:  # zero (or NaN): never in contact, and nothing to learn
            self.on, self.run = False, 0
            if self.age < self.settle:  # (the settling is time: a zero frame counts)
                self.age += 1
            return False
        loaded = s - self.baseline
        if self.age < self.settle:
            if not self.on:
                self.age += 1
                return self._settling(s, loaded)
            self.age = self.settle  # in contact: settled
        enter, stay = self.levels() if self.alpha else (self.enter_n, self.stay_n)
        want = loaded >= stay if self.on else loaded >= enter
        if want == self.on:
            self.run = 0
        else:
            self.run += 1
            # the dwell is for a total about a level; a clear load (twice the entry
            # level) or a clear release (below half the stay level) changes at once
            clear = loaded >= 2.0 * enter if want else loaded < 0.5 * stay
            if self.run >= self.dwell or clear:
                self.on, self.run = want, 0
        if self.alpha and not self.on and self.run == 0 and loaded < stay:
            self._learn(s)
        return self.on

    def _settling(self, s: float, loaded: float) -> bool:
        """A frame of the settling: only a load that is always contact enters (held for
        the dwell, as any change, or at once when twice that); a total that may be the
        film's own is learnt."""
        always = self.enter_n + 2.0 * self.max_n
        if loaded >= always:
            self.run += 1
            # (a clear load, twice that, at once: as after the settling)
            if self.run >= self.dwell or loaded >= 2.0 * always:
                self.on, self.run = True, 0
        else:
            self.run = 0
            if s < self.enter_n + self.max_n:
                self._learn(s)
        return self.on

    def _learn(self, s: float) -> None:
        self.seen += 1
        a = max(self.alpha, 1.0 / self.seen)
        d = s - self.baseline
        b = self.baseline + a * d
        self.baseline = min(max(b, -self.max_n), self.max_n)
        self.var += a * (d * d - self.var)

    def mask(self, s: np.ndarray) -> np.ndarray:
        """:meth:`touching` frame by frame over ``s``, from a fresh rule (out of contact)."""
        if not self.alpha and self.dwell == 1:  # the plain hysteresis: vectorized
            enter = (s > 0.0) & (s >= self.enter_n)
            leave = ~((s > 0.0) & (s >= self.stay_n))  # disjoint from enter: stay_n <= enter_n
            last = np.maximum.accumulate(np.where(enter | leave, np.arange(len(s)), -1))
            return (last >= 0) & enter[np.maximum(last, 0)]
        fresh = copy.copy(self)
        fresh.reset()
        step = fresh.touching
        return np.fromiter((step(v) for v in np.asarray(s, dtype=np.float64).tolist()), dtype=bool, count=len(s))


class VaryingLatch:
    """The ``variable_force`` state's hysteresis: set at a score of 1; cleared once the
    score has stayed below ``exit_level`` for ``exit_s`` and the latch has been set for
    ``min_dwell_s``.  ``update`` is called once per valid update in contact."""

    __slots__ = ("exit_level", "exit_s", "min_dwell_s", "on", "set_t", "calm_t")

    def __init__(self, exit_level: float, exit_s: float, min_dwell_s: float) -> None:
        self.exit_level = exit_level
        self.exit_s = exit_s
        self.min_dwell_s = min_dwell_s
        self.clear()

    @classmethod
    def from_settings(cls, c: VaryingForceSettings) -> VaryingLatch:
        return cls(c.exit_fraction, c.exit_s, c.min_dwell_s)

    def clear(self) -> None:
        self.on = False
        self.set_t = -math.inf
        self.calm_t: float | None = None  #: since when the score has been below the exit level

    def update(self, t: float, score: float) -> bool:
        if score >= 1.0:
            if not self.on:
                self.on, self.set_t = True, t
            self.calm_t = None
        elif self.on:
            if score >= self.exit_level:
                self.calm_t = None
            else:
                if self.calm_t is None:
                    self.calm_t = t
                if t - self.calm_t >= self.exit_s and t - self.set_t >= self.min_dwell_s:
                    self.on = False
                    self.calm_t = None
        return self.on


class Decision:
    """The grasp-state decision of every method (the rules are in the module's doc).

    ``decide`` is called once per update, not per frame; ``state`` and ``entered_t``
    persist across a detector's restarts after long gaps, as the PLC's view does.
    ``varying`` is the update's varying-force score (1 = evidence; a bool is 0 or 1)."""

    __slots__ = ("hold_s", "confirm", "state", "entered_t", "slip_t", "slip_run", "latch", "from_entry")

    def __init__(self, hold_s: float, confirm: int = 1, latch: VaryingLatch | None = None,
                 hold_from: str = "evidence") -> None:
        self.hold_s = hold_s
        self.from_entry = hold_from == "entry"  #: hold_s from the entry, not the last evidence
        self.confirm = confirm
        self.latch = latch if latch is not None else VaryingLatch.from_settings(VaryingForceSettings())
        self.state = _NO_CONTACT
        self.entered_t = -math.inf
        self.slip_t = -math.inf  #: the newest update with confirmed slip evidence
        self.slip_run = 0  #: consecutive valid updates with slip evidence

    @classmethod
    def from_settings(cls, settings: DetectorSettings, confirm: int | None = None) -> Decision:
        return cls(settings.hold_s, settings.slip_confirm_updates if confirm is None else confirm,
                   VaryingLatch.from_settings(settings.varying_force), settings.hold_from)

    def decide(self, t: float, contact: bool, valid: bool, slip: bool, varying: float) -> int:
        cur = self.state
        if not contact:
            self.slip_run = 0
            self.latch.clear()
            if cur != _NO_CONTACT:
                self.state, self.entered_t = _NO_CONTACT, t
            return self.state
        if not valid:
            # unknown: keep what we had (the update's valid bit says it is stale);
            # contact without any verdict yet reads "stable", never "slip"
            self.slip_run = 0
            if cur == _NO_CONTACT:
                self.state, self.entered_t = _STABLE, t
            return self.state
        confirmed = False
        if slip:
            self.slip_run += 1
            confirmed = self.slip_run >= self.confirm or cur == _SLIP
            if not confirmed and varying < 1.0:
                varying = 1.0  # slip evidence not yet confirmed: something is changing
        else:
            self.slip_run = 0
        latch = self.latch  # (a latch that is off stays off below 1: no call then)
        held = _VARIABLE if (varying >= 1.0 or latch.on) and latch.update(t, varying) else _STABLE
        if confirmed:
            if cur != _SLIP:
                self.state, self.entered_t = _SLIP, t  # slip pre-empts everything, at once
            if not self.from_entry or cur != _SLIP:
                self.slip_t = t
        elif cur == _SLIP:
            if t - self.slip_t >= self.hold_s:
                self.state, self.entered_t = held, t
        elif held != cur:
            self.state, self.entered_t = held, t
        return self.state


class StateMachine:
    """The paper's evidence in front of the one :class:`Decision`.

    - slip evidence: both R_coe > ``slip_r_coe`` and R_dw > ``slip_r_dw`` (the paper's
      rule; or one alone, ``slip_rule``), reported after ``slip_confirm_updates``
      consecutive valid updates; while slip holds, its thresholds are lowered to
      threshold x (1 - ``hysteresis``), so that it is left only once the indicators
      have clearly fallen;
    - varying-force evidence: the total force's score ``vf`` (``vforce.py``), or with
      ``[detector.varying_force] evidence = "method"`` the paper's reading, either
      indicator above its ``variable_*`` threshold (lowered the same way while the
      state is ``variable_force`` or ``slip``).

    ``contact`` is the update's newest frame under :class:`ContactRule`.
    """

    def __init__(self, settings: DetectorSettings) -> None:
        self.settings = settings
        self.decision = Decision.from_settings(settings)
        self._rule = settings.slip_rule
        self._keep = 1.0 - settings.hysteresis
        self._own = settings.varying_force.evidence == "method"

    @property
    def state(self) -> int:
        return self.decision.state

    def step(self, t: float, r_coe: float, r_dw: float, contact: bool, valid: bool, vf: float = 0.0) -> int:
        decision = self.decision
        if not (contact and valid):
            return decision.decide(t, contact, valid, False, 0.0)
        cfg = self.settings
        cur = decision.state
        slip_k = self._keep if cur == _SLIP else 1.0
        over_c, over_d = r_coe > cfg.slip_r_coe * slip_k, r_dw > cfg.slip_r_dw * slip_k
        rule = self._rule
        slip = (over_c and over_d) if rule == "both" else over_c if rule == "coe" else over_d
        if self._own:
            var_k = self._keep if cur >= _VARIABLE else 1.0
            vf = 1.0 if (r_coe > cfg.variable_r_coe * var_k or r_dw > cfg.variable_r_dw * var_k) else 0.0
        return decision.decide(t, True, True, slip, vf)
