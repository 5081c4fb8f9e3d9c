"""What a device's DBIRTH says about the sensor and the deciding method, as Sparkplug
metric properties (a PropertySet of scalar values): the layout, and the method with
the profile keys that set its thresholds, named as in the profile."""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

from . import payload as pb

if TYPE_CHECKING:
    from ...profile import Profile

Property = tuple[str, tuple[int, Any]]

def _typed(value: Any) -> tuple[int, Any] | None:
    if isinstance(value, bool):
        return (pb.BOOLEAN, value)
    if isinstance(value, int):
        return (pb.INT64, value)
    if isinstance(value, float):
        return (pb.DOUBLE, value)
    if isinstance(value, str):
        return (pb.STRING, value)
    if isinstance(value, tuple) and all(isinstance(v, (int, float)) for v in value):
        return (pb.STRING, ",".join(f"{v:g}" for v in value))
    return None  # (nothing else is a threshold)


def layout_properties(profile: Profile) -> tuple[Property, ...]:
    lay = profile.layout
    return (("rows", (pb.INT64, lay.rows)), ("cols", (pb.INT64, lay.cols)), ("pitch_mm", (pb.DOUBLE, lay.pitch_mm)))


def frame_properties(profile: Profile, interval_s: float) -> tuple[Property, ...]:
    """The taxel frame's: its shape (``rows``, ``cols``, row-major), the taxel pitch, and
    the interval it is sent at, at most."""
    return (*layout_properties(profile), ("order", (pb.STRING, "row-major")),
            ("frame_interval_s", (pb.DOUBLE, float(interval_s))))


def score_properties(profile: Profile) -> dict[str, tuple[Property, ...]]:
    """The DBIRTH properties of ``Score A`` and ``Score B``: the deciding method, the
    score's name (as in the updates CSV and ``eskin-bus plc map``) and what it is."""
    from ...methods import get_method

    method = get_method(profile.detector.method)
    return {metric: (("method", (pb.STRING, method.name)), ("score", (pb.STRING, s.name)),
                     ("description", (pb.STRING, s.doc)))
            for metric, s in zip(("Score A", "Score B"), method.scores)}


def method_properties(profile: Profile) -> tuple[Property, ...]:
    """``method`` and the keys that set its decision, as the method declares them, by
    their profile name (``detector.slip_r_coe``, ``detector.cof_track.z``);
    ``detector.contact_threshold_n`` for every method."""
    from ...methods import get_method

    det = profile.detector
    method = get_method(det.method)
    # A method with no settings of its own (the ``none`` baseline) lists the paper's
    # rule, as every DBIRTH has since the keys were first published: a host that reads
    # them finds them still.
    described = method if method.settings is not None else get_method("paper")
    own = described.settings_of(det)
    prefix = f"detector.{described.key}." if described.key else "detector."
    out: list[Property] = [("method", (pb.STRING, det.method))]
    for f in dataclasses.fields(own):
        typed = _typed(getattr(own, f.name))
        if typed is not None:
            out.append((prefix + f.name, typed))
    out.append(("detector.contact_threshold_n", (pb.DOUBLE, float(det.contact_threshold_n))))
    return tuple(out)
