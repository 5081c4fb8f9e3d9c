"""What one screen of the live view shows, as plain values: :class:`Snapshot`.

Pure code, no I/O and no clock.  The glue that reads a running chain
(:mod:`eskin_industrial.view.live`) builds snapshots from the node's snapshot (the
one every output reads) and, when the caller hands one, a table of named registers
(:class:`RegisterTable`: the PLC's, as a PLC reads them; the view decodes no wire
format itself); the renderer (:mod:`eskin_industrial.view.screen`) draws them.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from ..detect.settings import DetectorSettings


@dataclass(frozen=True, slots=True)
class IndicatorScale:
    """How to read the deciding method's two scores (R_coe and R_dw for the paper's methods)."""

    names: tuple[str, str] = ("R_coe", "R_dw")
    #: What the columns hold for this method (shown as a note).
    meaning: str = ""
    #: Slip thresholds; None: the column has none (or is unused).
    slip: tuple[float | None, float | None] = (None, None)
    #: Varying-force thresholds, where the method has them.
    variable: tuple[float | None, float | None] = (None, None)


def indicator_scale(method: str, settings: DetectorSettings, detector: object | None = None) -> IndicatorScale:
    """The thresholds of ``method`` as the profile's detector settings give them.

    The paper's rules compare R_coe and R_dw with ``slip_r_*`` and ``variable_r_*``;
    the gauges show the deciding method's own two scores (``score_a``, ``score_b``;
    ``columns`` on the detector names them), so other methods' thresholds come from
    the method, not from ``slip_r_*``.
    """
    if method.startswith("paper"):
        rule = {"paper-coe": "R_coe alone", "paper-dw": "R_dw alone"}.get(method, "both")
        if settings.varying_force.evidence == "method":  # the paper's own varying-force thresholds
            return IndicatorScale(("R_coe", "R_dw"), f"{method}: slip > | ({rule}), varying > :",
                                  (settings.slip_r_coe, settings.slip_r_dw),
                                  (settings.variable_r_coe, settings.variable_r_dw))
        # (varying force: the total force's own test, not these indicators: detect/vforce.py)
        return IndicatorScale(("R_coe", "R_dw"), f"{method}: slip > | ({rule})",
                              (settings.slip_r_coe, settings.slip_r_dw))
    from ..methods import get_method

    try:
        known = get_method(method)
    except KeyError:  # a detector of no registered method (a test's own)
        known = None
    columns = tuple(s.name for s in known.scores) if known is not None else tuple(
        getattr(detector, "columns", ("score", "unused")))
    if method == "cof-track":
        # Both scores are normalised by the method: 1 is its threshold (detect/cof_track.py).
        return IndicatorScale((columns[0], columns[1]), f"{method} scores: slip > 1", (1.0, 1.0))
    threshold = getattr(detector, "threshold", None)
    slip_a = float(threshold) if isinstance(threshold, (int, float)) else None
    slip_b = None
    return IndicatorScale((columns[0], columns[1]), f"{method} scores", (slip_a, slip_b))


class RegisterTable(NamedTuple):
    """Named register values and the names of the status bits that are set, as an
    output's wire format holds them (handed to the view by whoever decodes it)."""

    values: Mapping[str, int]
    bits: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class Snapshot:
    """Everything one screen shows; built from the newest values of a running chain."""

    #: Taxel forces in N, shape (rows, cols); None before the first scan.
    forces: np.ndarray | None
    #: Names of the rows (the hand's fingers) when the layout has them.
    row_names: tuple[str, ...] | None = None
    r_coe: float | None = None
    r_dw: float | None = None
    scale: IndicatorScale = field(default_factory=IndicatorScale)
    #: State label (``GraspState.label``); None before the first update.
    state: str | None = None
    valid: bool = False
    #: No fresh scan: the state is not a verdict (the image's SENSOR_STALE).
    stale: bool = False
    f_sum: float | None = None
    #: Centre of force in mm.
    cof: tuple[float, float] | None = None
    #: Named registers (STATUS first), as the caller decoded them; None: none (yet).
    registers: Mapping[str, int] | None = None
    #: The STATUS bits that are set, by name, in bit order.
    status_bits: tuple[str, ...] = ()
    #: Where the registers come from ("as the PLC reads them", "as the bridge would publish").
    registers_from: str = ""
    counters: Mapping[str, int] = field(default_factory=dict)
    elapsed_s: float = 0.0
    #: Scans per second lately (None until measured).
    scan_rate_hz: float | None = None
    #: What is watched: profile, method, bus.
    source: str = ""
    #: Title of the screen (the command).
    title: str = "eskin-bus"
    #: Newest state-change lines, oldest first.
    log: tuple[str, ...] = ()
    #: Heat-map colour scale: at least this many N at the top (noise stays dark).
    scale_min_n: float = 0.5
    #: Lines a chain adds under the state (the closed loop: the grip force, the distance slid).
    extra: tuple[str, ...] = ()
