"""A detection method by name, ready to build detectors: the one place where the
``learned`` method is handed its model (the one given, or else the default one,
trained on the tuning seeds on first use).

The pipeline (hence the bridge and every live command), the offline path (``detect``,
``plot``) and the evaluation all build their methods here, so that a method name
means the same detector everywhere.

Why this lives in the evaluation package: the pipeline builds ``learned`` by name
with no model given (a bridge's profile may name it), so the binding must sit below
the pipeline; and the default model is trained on the evaluation's scenes, so the
binding needs the training.  The evaluation imports no runtime part (only ``detect``,
``scenes``, ``profile``), hence it sits below the pipeline in the layer contract and
the pipeline's one import of it points downward.  The training itself (scenes,
scikit-learn) is imported only when a method that needs a model is built without one:
a bridge that runs any other method never loads it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from ..detect.learned import Model
from ..detect.methods import Method
from ..detect.settings import DetectorSettings
from ..methods import get_method, method_of_stream

#: A stream factory: (settings, x_mm, y_mm, rate_hz) -> a detector.
Factory = Callable[[DetectorSettings, np.ndarray, np.ndarray, float], Any]


def bind(method: Method, model: Model | None = None) -> Method:
    """``method`` ready to build from (settings, x_mm, y_mm, rate_hz): one that needs
    a model is handed ``model``, or else the default one (trained on first use;
    :class:`~eskin_industrial.errors.MissingExtra` without scikit-learn); any other
    is returned as it is."""
    if not method.needs_model:
        return method
    if model is None:
        from .train import default_model  # only here: see the module's docstring

        model = default_model()
    return method.with_model(model)


def ready_method(name: str | None, settings: DetectorSettings, model: Model | None = None) -> Method:
    """The method ``name`` (None: the settings' own, a profile's ``detector.method``),
    bound by :func:`bind`; an unknown name is a ``KeyError`` naming the known ones."""
    return bind(get_method(name or settings.method), model)


def ready_factory(factory: Factory) -> Factory:
    """A bare stream factory ready to call: a registered method's factory that needs a
    model (``get_method("learned").stream``) is bound by :func:`bind`; any other
    factory (a bound one, one of the sweeps' own) is returned as it is."""
    method = method_of_stream(factory)
    return factory if method is None or not method.needs_model else bind(method).stream


__all__ = ["Factory", "bind", "ready_factory", "ready_method"]
