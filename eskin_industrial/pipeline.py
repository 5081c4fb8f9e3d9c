"""The seam every live path shares: raw scans in, calibrated frames, detector updates
out, with counters.  Sources (``bus/``) produce :class:`RawScan`; sinks (PLC register
image, views) consume :class:`~eskin_industrial.detect.updates.Update`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .calibration import Calibrator
from .detect.integrity import IntegrityWatch
from .detect.learned import Model
from .detect.protocol import Detector
from .detect.updates import Update, state_changed
from .frames import SENSOR_FAULTS, Frame, FrameFlag, RawScan, new_frame
from .methods import ready_method
from .node.verdict import shown
from .profile import Profile

_INVALID = int(FrameFlag.INVALID)  # plain ints: IntFlag arithmetic costs microseconds per scan
_SATURATED = int(FrameFlag.SATURATED)


@dataclass
class Counters:
    scans: int = 0
    updates: int = 0
    invalid_scans: int = 0
    saturated_scans: int = 0
    lost_scans: int = 0  #: gaps in the sequence numbers
    dropped_by_detector: int = 0  #: duplicate or out-of-order times
    state_changes: int = 0  #: :func:`~.detect.updates.state_changed` (the STATE_CHANGES register's count)
    fault_scans: int = 0  #: scans with a sensor fault (DEAD_TAXELS, FROZEN, RATE, STREAM): no verdict
    sensor_faults: int = 0  #: entries into a sensor fault
    extra: dict[str, int] = field(default_factory=dict)  #: transport-specific counters


class Pipeline:
    """Calibrate and detect, one scan at a time; keeps the newest frame and update."""

    def __init__(self, profile: Profile, rate_hz: float | None = None, method: str | None = None,
                 model: Model | None = None) -> None:
        """``method`` overrides the profile's; a method that needs a model (``learned``)
        gets ``model``, or else the one the package ships (read from package data)."""
        self.profile = profile
        self.calibrator = Calibrator.from_section(profile.calibration, profile.taxels)
        self.rate_hz = rate_hz or profile.sensor.rate_hz
        x, y = profile.coordinates_mm
        self.method = ready_method(method, profile.detector, model)  #: the deciding method (its code, its scores)
        #: Whichever method decides, only :class:`~eskin_industrial.detect.protocol.Detector`'s surface is used.
        self.detector: Detector = self.method.stream(profile.detector, x, y, self.rate_hz)
        self.counters = Counters()
        #: The sensor's faults (:mod:`~.detect.integrity`); ``fault`` holds the newest scan's bits.
        self.integrity = integrity_watch(profile, self.rate_hz)
        self.fault = 0
        self.last_frame: Frame | None = None
        self.last_update: Update | None = None
        self._last_seq: int | None = None

    def time_faults(self) -> dict[str, int]:
        """Frames the detector refused for their time, by kind (``not_a_time``,
        ``repeated_time``, ``backward_time``; they sum to ``dropped_by_detector``)."""
        return dict(self.detector.time_faults)

    def calibrate(self, scan: RawScan) -> Frame:
        forces, flags = self.calibrator.to_newtons(scan.raw)
        return new_frame(scan.seq, scan.t, forces, scan.flags | int(flags))

    def push(self, scan: RawScan) -> list[Update]:
        c = self.counters
        c.scans += 1
        if self._last_seq is not None and scan.seq > self._last_seq + 1:
            c.lost_scans += scan.seq - self._last_seq - 1
        if self._last_seq is None or scan.seq > self._last_seq:
            self._last_seq = scan.seq
        frame = self.calibrate(scan)
        if frame.flags & _INVALID:
            c.invalid_scans += 1
        if frame.flags & _SATURATED:
            c.saturated_scans += 1
        self.last_frame = frame
        # the transport's own verdict (a CAN stream that is not one node's) joins the scans' own
        fault = self.integrity.push(frame.t, frame.forces, scan.raw, bool(frame.flags & _INVALID)) \
            | (scan.flags & SENSOR_FAULTS)
        if fault:
            c.fault_scans += 1
            if not self.fault:
                c.sensor_faults += 1
        self.fault = fault
        before = self.detector.dropped
        # (a fault bit is the moment's, in the snapshot: not one the detector's updates carry on)
        updates = self.detector.push(frame.t, frame.forces, frame.flags & ~SENSOR_FAULTS)
        c.dropped_by_detector += self.detector.dropped - before
        for u in updates:
            if state_changed(self.last_update, u):
                c.state_changes += 1
            self.last_update = u
        c.updates += len(updates)
        return updates

    def shown(self, updates: list[Update]) -> list[Update]:
        """The updates of the newest :meth:`push` as the outputs show them: themselves,
        or, under a sensor fault, no verdict (:func:`~.node.verdict.shown`)."""
        fault = self.fault
        return [shown(u, fault) for u in updates] if fault else updates


def integrity_watch(profile: Profile, rate_hz: float) -> IntegrityWatch:
    """The judge of one node's scans (its ``[output]`` limits, at the detector's rate)."""
    out = profile.output
    return IntegrityWatch(profile.taxels, rate_hz, hold_s=out.hold_s, hold_share=out.hold_share,
                          frozen_s=out.frozen_s, rate_tolerance=out.rate_tolerance)


def frame_faults(profile: Profile, rate_hz: float, t: np.ndarray, forces: np.ndarray, raw: np.ndarray) -> np.ndarray:
    """Each frame's sensor-fault bits, judged as the pipeline judges a node's scans:
    every frame in file order (those whose time the detector refuses too), ``forces``
    in newtons with NaN where a reading is invalid, ``raw`` as read (a recording in
    newtons: the newtons), at the rate the detector runs at."""
    watch = integrity_watch(profile, rate_hz)
    invalid = ~np.isfinite(forces).all(axis=1)
    push = watch.push
    return np.fromiter((push(float(t[i]), forces[i], raw[i], bool(invalid[i])) for i in range(len(t))),
                       dtype=np.int64, count=len(t))
