"""Detection methods by name, so that the CLI, the evaluation and the bridge can run
any of them through one loop (the way python-can finds an interface by name).

Each entry gives a streaming factory ``(settings, x_mm, y_mm, rate_hz) -> detector``
(with ``push(t, forces, flags) -> list[Update]``) and a batch function
``(settings, x_mm, y_mm, rate_hz, t, forces, flags) -> UpdateTable``.

A method declares its own settings: a frozen dataclass (``settings``), read from
``[detector.<key>]`` of a profile (``key``: the name with ``-`` as ``_``, as
``cof-track``'s ``[detector.cof_track]``; the paper's rule from ``[detector]`` itself),
and :meth:`Method.settings_of` finds them in a :class:`DetectorSettings`, a plug-in's
as well as a built-in's.

A method with ``needs_model`` (``learned``) must also be handed ``model=``; the
registry does not know where models come from.  :meth:`Method.with_model` binds one;
every layer that builds detectors by name does so through one function that hands
over the shipped model (``eskin_industrial.methods.bind``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import partial
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from .cof_step import CofStep
from .cof_track import CofTrack
from .learned import Learned, Model
from .paper import PaperDetector, paper_batch
from .protocol import Detector
from .scored import CofVelocity, ForceRate, HfEnergy, NoSlip
from .settings import (
    CofStepSettings,
    CofTrackSettings,
    CofVelocitySettings,
    DetectorSettings,
    ForceRateSettings,
    HfEnergySettings,
    LearnedSettings,
    PaperRuleSettings,
)
from .updates import UpdateTable


@dataclass(frozen=True)
class Score:
    """One of a method's own two scores (an update's ``score_a`` or ``score_b``)."""

    name: str  #: as the detector's ``columns`` name it (CSV, Sparkplug, ``plc map``)
    doc: str  #: what it is, and where its threshold lies


#: The paper's own scores: its indicators again (the same floats, computed once).
PAPER_SCORES = (Score("r_coe", "the paper's R_coe again (slip above slip_r_coe)"),
                Score("r_dw", "the paper's R_dw again (slip above slip_r_dw)"))
UNUSED = Score("unused", "reads 0 (the method has one score)")


@dataclass(frozen=True)
class Threshold:
    """Settings of a method that a teach-in may set from the scores of the user's own
    holds (``eskin-bus profile tune``, docs/profiles.md): which keys, read against
    which of its scores, and how.

    ``relative``: the scores are in units of the threshold (1 = slip), so the keys are
    all multiplied by one factor, the one that puts the holds' scores where the rule
    wants them; else the score is in the key's own unit, and the one key is set to it.
    ``direction``: slip when the score is ``above`` the threshold (or ``below`` it)."""

    keys: tuple[str, ...]
    scores: tuple[str, ...]  #: names of the method's :class:`Score` columns
    relative: bool = False
    direction: Literal["above", "below"] = "above"

    def __post_init__(self) -> None:
        if not self.keys or not self.scores or (not self.relative and len(self.keys) != 1):
            raise ValueError(f"Threshold {self.keys}: expected keys and scores, and one key unless relative")
NO_SCORE = Score("unused", "reads 0 (the method has no score)")


@dataclass(frozen=True)
class Method:
    name: str
    summary: str
    #: ``(settings, x_mm, y_mm, rate_hz) -> Detector`` (and ``model=`` with ``needs_model``)
    stream: Callable[..., Detector]
    #: ``(settings, x_mm, y_mm, rate_hz, t, forces, flags=None) -> UpdateTable``
    batch: Callable[..., UpdateTable]
    #: The factories also need ``model=`` (see :meth:`with_model`).
    needs_model: bool = False
    #: ``batch`` is a computation of its own over the whole recording; otherwise it
    #: feeds the stream detector, and feeding it in pieces gives the same updates.
    vectorized: bool = False
    #: The method's number in the METHOD_ID register and the Sparkplug ``Method`` metric
    #: (fixed: a PLC program compares it; 0 is no method, a bridge that has stopped).
    code: int = 0
    #: What ``score_a`` and ``score_b`` hold.
    scores: tuple[Score, Score] = PAPER_SCORES
    #: The method's own settings: a frozen dataclass whose fields are its profile keys
    #: (types, defaults and bounds as :mod:`eskin_industrial.schema` reads them); None:
    #: none of its own.
    settings: type | None = None
    #: Where they sit in a profile: ``[detector.<section>]``; "" for ``[detector]``
    #: itself (the paper's rule).  Default (None): the name with ``-`` as ``_``.
    section: str | None = None
    #: The thresholds among its settings that a teach-in may set (none: it is not
    #: tuned from holds).
    tunable: tuple[Threshold, ...] = ()

    @property
    def key(self) -> str:
        """The section of the method's settings under ``[detector]`` ("": ``[detector]`` itself)."""
        return self.name.replace("-", "_") if self.section is None else self.section

    def settings_of(self, settings: DetectorSettings) -> Any:
        """The method's own settings out of ``settings`` (None: it has none)."""
        if self.settings is None:
            return None
        if self.key == "":
            return self.settings(**{f.name: getattr(settings, f.name) for f in dataclasses.fields(self.settings)})
        return settings.section(self.key, self.settings)

    def with_model(self, model: Model) -> Method:
        """This method with ``model`` bound into both factories."""
        stream = partial(self.stream, model=model)
        return replace(self, stream=stream, batch=batch_via_stream(stream))


def batch_via_stream(factory: Callable[..., Detector]) -> Callable[..., UpdateTable]:
    """A batch function for a method that only streams: feed the whole recording."""

    def batch(settings: DetectorSettings, x_mm: np.ndarray, y_mm: np.ndarray, rate_hz: float, t: ArrayLike,
              forces: ArrayLike, flags: np.ndarray | None = None) -> UpdateTable:
        det = factory(settings, x_mm, y_mm, rate_hz)
        return UpdateTable.from_updates(det.feed(np.asarray(t, float), np.asarray(forces, float), flags))

    return batch


def _paper_rule(rule: Literal["both", "coe", "dw"]) -> Callable[..., Detector]:
    def make(settings: DetectorSettings, x_mm: np.ndarray, y_mm: np.ndarray, rate_hz: float) -> Detector:
        return PaperDetector(replace(settings, slip_rule=rule), x_mm, y_mm, rate_hz)

    return make


def _method(name: str, summary: str, stream: Callable[..., Any], code: int, scores: tuple[Score, Score],
            needs_model: bool = False, settings: type | None = None, section: str | None = None,
            tunable: tuple[Threshold, ...] = ()) -> Method:
    return Method(name, summary, stream, batch_via_stream(stream), needs_model, code=code, scores=scores,
                  settings=settings, section=section, tunable=tunable)


#: The paper's two slip thresholds, each on its own indicator (the rule "both" asks
#: both to cross: setting each above its own holds' scores is the safe side).
_PAPER_TUNABLE = (Threshold(("slip_r_coe",), ("r_coe",)), Threshold(("slip_r_dw",), ("r_dw",)))
#: Our method's scores are over their thresholds (1 = slip): the displacement's and
#: the ramp's, the step's and the turn's z, and the ramp's own support (else the
#: stick-slip evidence, capped by ramp_z^2 - ramp_support_z^2, would grow with the
#: thresholds and keep the score near 1), all scaled by one factor.
_COF_TRACK_TUNABLE = (Threshold(("z", "ramp_z", "step_z", "torsion_z", "ramp_support_z"),
                                ("onset_score", "slow_score"), relative=True),)


METHODS: dict[str, Method] = {
    "paper": Method("paper", "R_coe and R_dw both above their slip thresholds (the reference paper)", PaperDetector,
                    paper_batch, vectorized=True, code=1, settings=PaperRuleSettings, section="",
                    tunable=_PAPER_TUNABLE),
    # (slip_rule is the variants' own: the profile's is shown, theirs decides)
    "paper-coe": _method("paper-coe", "the paper's R_coe alone above its slip threshold", _paper_rule("coe"), 2,
                         PAPER_SCORES, settings=PaperRuleSettings, section="", tunable=_PAPER_TUNABLE[:1]),
    "paper-dw": _method("paper-dw", "the paper's R_dw alone above its slip threshold", _paper_rule("dw"), 3,
                        PAPER_SCORES, settings=PaperRuleSettings, section="", tunable=_PAPER_TUNABLE[1:]),
    "force-rate": _method("force-rate", "rival: total-force derivative above a threshold", ForceRate, 4, (
        Score("force_rate_per_s", "|dS/dt| / S over lag_s, 1/s (slip above threshold_per_s)"), UNUSED),
        settings=ForceRateSettings, tunable=(Threshold(("threshold_per_s",), ("force_rate_per_s",)),)),
    "hf-energy": _method("hf-energy", "rival: high-frequency energy of the taxel signals over its baseline", HfEnergy, 5, (
        Score("hf_energy_ratio", "high-frequency energy over its baseline (slip above threshold)"), UNUSED),
        settings=HfEnergySettings, tunable=(Threshold(("threshold",), ("hf_energy_ratio",)),)),
    "cof-velocity": _method("cof-velocity", "rival: centre-of-force speed above a threshold", CofVelocity, 6, (
        Score("cof_speed_mm_s", "centre-of-force speed, mm/s (slip above threshold_mm_s)"), UNUSED),
        settings=CofVelocitySettings, tunable=(Threshold(("threshold_mm_s",), ("cof_speed_mm_s",)),)),
    "cof-track": _method("cof-track", "ours: centre-of-force displacement against its learnt noise", CofTrack, 7, (
        Score("onset_score", "onset: the largest of the fast displacement, the ramp and the turn about the "
                             "normal, over their noise thresholds (slip above 1)"),
        Score("slow_score", "the slow displacement still moving onward, over its threshold (slip above 1)")),
        settings=CofTrackSettings, tunable=_COF_TRACK_TUNABLE),
    "cof-step": _method("cof-step", "rival: the newest 20 ms of the centre of force against the mean and spread of "
                        "the half-second that ended 100 ms earlier", CofStep, 10, (
        Score("step_score", "the newest CoF's distance from the base's mean in its standard deviations, over "
                            "threshold (slip above 1)"), UNUSED), settings=CofStepSettings,
        tunable=(Threshold(("threshold",), ("step_score",), relative=True),)),
    "learned": _method("learned", "accuracy ceiling: a small classifier on the other methods' features (extra: learn)", Learned,
                       8, (Score("p_slip", "the model's slip probability (slip above slip_p, confirm_hops in a row)"),
                           Score("p_variable_force", "the model's varying-force probability")), needs_model=True,
                       settings=LearnedSettings, tunable=(Threshold(("slip_p",), ("p_slip",)),)),
    # A baseline, not a detector: the closed loop's fixed grip (no slip sensing), with
    # the state, contact and validity of any other method.
    "none": _method("none", "baseline: never reports slip (no slip sensing; contact and varying force as the others)",
                    NoSlip, 9, (NO_SCORE, NO_SCORE)),
}


def get_method(name: str) -> Method:
    """The built-in method ``name`` (``eskin_industrial.methods.get_method`` also finds
    the plug-ins)."""
    try:
        return METHODS[name]
    except KeyError:
        raise KeyError(f"unknown detection method {name!r}; known: {', '.join(sorted(METHODS))}") from None

