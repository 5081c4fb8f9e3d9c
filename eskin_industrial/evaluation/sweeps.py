"""The settings each chart point stands for: every method at several settings."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from functools import partial
from typing import Any, Literal

import numpy as np

from ..detect.cof_step import CofStep
from ..detect.cof_track import CofTrack
from ..detect.paper import PaperDetector
from ..detect.scored import CofVelocity, ForceRate, HfEnergy
from ..detect.settings import DetectorSettings
from ..methods import bind, get_method


def _paper(rule: Literal["both", "coe", "dw"], **changes: Any) -> Callable[..., Any]:
    def make(settings: DetectorSettings, x: np.ndarray, y: np.ndarray, rate: float) -> PaperDetector:
        return PaperDetector(replace(settings, slip_rule=rule, **changes), x, y, rate)
    return make


def sweep() -> list[tuple[str, str, Callable[..., Any]]]:
    """(method family, point label, factory) for the accuracy charts."""
    points: list[tuple[str, str, Callable[..., Any]]] = []
    for window, hop in ((0.2, 0.05), (0.4, 0.1), (0.4, 0.05), (0.8, 0.1)):
        for wavelet in ("db2", "db4"):
            for thr in (1.0, 2.5):
                label = f"w{window} h{hop} {wavelet} >{thr}"
                ch = dict(window_s=window, hop_s=hop, lag_s=hop, wavelet=wavelet, slip_r_coe=thr, slip_r_dw=thr,
                          variable_r_coe=min(0.5, thr), variable_r_dw=min(0.5, thr))
                points.append(("paper", label, _paper("both", **ch)))
                if wavelet == "db2":
                    points.append(("paper-coe", label, _paper("coe", **ch)))
                    points.append(("paper-dw", label, _paper("dw", **ch)))
    for thr in (0.5, 1.0, 2.0, 4.0):
        points.append(("force-rate", f">{thr}/s", partial(ForceRate, threshold_per_s=thr)))
    for thr in (2.0, 6.0, 20.0):
        points.append(("hf-energy", f">{thr}x", partial(HfEnergy, threshold=thr)))
    for thr in (4.0, 6.0, 10.0):  # the total force's vibration: what cof-track's ripple evidence uses
        points.append(("hf-energy", f"total >{thr}x", partial(HfEnergy, threshold=thr, total=True)))
    for thr in (2.0, 4.0, 8.0, 16.0):
        points.append(("cof-velocity", f">{thr} mm/s", partial(CofVelocity, threshold_mm_s=thr)))
    for thr in (3.5, 4.5, 6.0, 8.0):  # the plain displacement test (4.5: cof-track's false alarms on long holds)
        points.append(("cof-step", f">{thr:g} sd", partial(CofStep, threshold=thr)))
    for z in (4.0, 5.0, 6.0, 8.0):
        for fast in (0.05, 0.1, 0.2):
            points.append(("cof-track", f"z{z} fast {fast}s", partial(CofTrack, z=z, fast_s=fast)))
    for ramp_z in (4.5, 5.0, 6.0, 7.0, 1e9):  # the ramp channel's threshold (1e9: no ramp)
        label = f"ramp z{ramp_z:g}" if ramp_z < 1e9 else "no ramp"
        points.append(("cof-track", label, partial(CofTrack, ramp_z=ramp_z)))
    # the stick-slip evidence: off, and the least the ramp must show by itself
    points.append(("cof-track", "no ripple evidence", partial(CofTrack, ripple_s=0.0)))
    for support in (0.0, 3.0, 4.5):
        points.append(("cof-track", f"ramp support z{support:g}", partial(CofTrack, ramp_support_z=support)))
    # the step channel: off, and its threshold around the default
    points.append(("cof-track", "no step channel", partial(CofTrack, step_s=0.0)))
    for step_z in (5.5, 6.0, 7.5):
        points.append(("cof-track", f"step z{step_z:g}", partial(CofTrack, step_z=step_z)))
    learned = bind(get_method("learned")).stream  # the shipped model: one model, several decision rules
    for p, hops in ((0.5, 1), (0.7, 1), (0.5, 2), (0.7, 2), (0.5, 3), (0.7, 3)):
        points.append(("learned", f"p>{p} x{hops} hops", partial(learned, slip_p=p, confirm_hops=hops)))
    return points


def defaults() -> dict[str, Callable[..., Any]]:
    names = ("paper", "paper-coe", "paper-dw", "force-rate", "hf-energy", "cof-velocity", "cof-step", "cof-track")
    return {n: get_method(n).stream for n in names}
