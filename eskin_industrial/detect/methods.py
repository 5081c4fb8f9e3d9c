"""Detection methods by name, so that the CLI, the evaluation and the bridge can run
any of them through one loop (the way python-can finds an interface by name).

Each entry gives a streaming factory ``(settings, x_mm, y_mm, rate_hz) -> detector``
(with ``push(t, forces, flags) -> list[Update]``) and a batch function
``(settings, x_mm, y_mm, rate_hz, t, forces, flags) -> UpdateTable``.

A method with ``needs_model`` (``learned``) must also be handed ``model=``; the
registry does not know where models come from.  :meth:`Method.with_model` binds one;
the layers that build detectors by name do so with the default model
(``eskin_industrial.evaluation.train.ready``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import partial
from typing import Any, Callable

import numpy as np

from .cof_track import CofTrack
from .learned import Learned, Model
from .paper import PaperDetector, paper_batch
from .scored import CofVelocity, ForceRate, HfEnergy
from .updates import UpdateTable


@dataclass(frozen=True)
class Method:
    name: str
    summary: str
    stream: Callable[..., Any]
    batch: Callable[..., Any]
    #: The factories also need ``model=`` (see :meth:`with_model`).
    needs_model: bool = False
    #: ``batch`` is a computation of its own over the whole recording; otherwise it
    #: feeds the stream detector, and feeding it in pieces gives the same updates.
    vectorized: bool = False

    def with_model(self, model: Model) -> "Method":
        """This method with ``model`` bound into both factories."""
        stream = partial(self.stream, model=model)
        return Method(self.name, self.summary, stream, batch_via_stream(stream))


def batch_via_stream(factory: Callable[..., Any]) -> Callable[..., UpdateTable]:
    """A batch function for a method that only streams: feed the whole recording."""

    def batch(settings, x_mm, y_mm, rate_hz, t, forces, flags=None) -> UpdateTable:
        det = factory(settings, x_mm, y_mm, rate_hz)
        return UpdateTable.from_updates(det.feed(np.asarray(t, float), np.asarray(forces, float), flags))

    return batch


def _paper_rule(rule: str) -> Callable[..., Any]:
    def make(settings, x_mm, y_mm, rate_hz):
        return PaperDetector(replace(settings, slip_rule=rule), x_mm, y_mm, rate_hz)

    return make


def _method(name: str, summary: str, stream: Callable[..., Any], needs_model: bool = False) -> Method:
    return Method(name, summary, stream, batch_via_stream(stream), needs_model)


METHODS: dict[str, Method] = {
    "paper": Method("paper", "R_coe and R_dw both above their slip thresholds (the reference paper)", PaperDetector,
                    paper_batch, vectorized=True),
    "paper-coe": _method("paper-coe", "the paper's R_coe alone above its slip threshold", _paper_rule("coe")),
    "paper-dw": _method("paper-dw", "the paper's R_dw alone above its slip threshold", _paper_rule("dw")),
    "force-rate": _method("force-rate", "rival: total-force derivative above a threshold", ForceRate),
    "hf-energy": _method("hf-energy", "rival: high-frequency energy of the taxel signals over its baseline", HfEnergy),
    "cof-velocity": _method("cof-velocity", "rival: centre-of-force speed above a threshold", CofVelocity),
    "cof-track": _method("cof-track", "ours: centre-of-force displacement against its learnt noise", CofTrack),
    "learned": _method("learned", "accuracy ceiling: a small classifier on the other methods' features (extra: learn)", Learned,
                       needs_model=True),
}


def get_method(name: str) -> Method:
    try:
        return METHODS[name]
    except KeyError:
        raise KeyError(f"unknown detection method {name!r}; known: {', '.join(sorted(METHODS))}") from None


def needs_model(factory: Callable[..., Any]) -> bool:
    """Whether ``factory`` is a registered method's stream factory that must be handed a model."""
    return any(m.needs_model and factory is m.stream for m in METHODS.values())
