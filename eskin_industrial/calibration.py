"""From the node's raw unit to newtons, vectorized, per taxel; and tare.

The model is the paper's: each taxel's reading is linear in force,

    reading = raw * raw_scale = zero + per_newton * F      =>  F = (reading - zero) / per_newton

(for the reference film: zero = 1400 ohm, per_newton = (495 - 1400) / 5 = -181 ohm/N).
``zero`` and ``per_newton`` hold one value per taxel, so each taxel carries its own
calibration; :meth:`Calibrator.tared` moves ``zero`` to the mean of a recorded
unloaded period.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .frames import FrameFlag
from .profile import CalibrationSection

_NO_FLAGS = np.zeros((), dtype=np.int64)  # the flags of a clean scan (shared: read-only)
_NO_FLAGS.flags.writeable = False
# The reductions themselves: ``a.min()`` goes through a Python wrapper of numpy's
# (``_methods._amin``) on every call, a frame per reduction per scan on the hot path.
_MIN = np.minimum.reduce
_MAX = np.maximum.reduce


def full_scale(forces: np.ndarray, full_scale_n: float) -> tuple[np.ndarray, np.ndarray]:
    """Forces already in newtons (a recording in N) held to the rule a calibrated scan
    follows: at or over ``full_scale_n`` they are kept at full scale and set SATURATED.
    Returns the forces and per-scan flags (shape ``forces.shape[:-1]``)."""
    forces = np.asarray(forces, dtype=np.float64)
    saturated = forces >= full_scale_n  # (False for NaN: the detector flags those INVALID)
    flags = np.where(saturated.any(axis=-1), int(FrameFlag.SATURATED), 0).astype(np.int64)
    return np.minimum(forces, full_scale_n, where=saturated, out=forces.copy()), flags


@dataclass(frozen=True)
class Calibrator:
    zero: np.ndarray  #: reading at 0 N, per taxel, in the raw unit
    per_newton: np.ndarray  #: change of reading per newton, per taxel (non-zero)
    raw_scale: float
    valid_min: float
    valid_max: float
    full_scale_n: float

    @classmethod
    def from_section(cls, cal: CalibrationSection, taxels: int) -> Calibrator:
        zero = np.broadcast_to(np.asarray(cal.zero, dtype=np.float64), (taxels,)).copy()
        per_n = np.broadcast_to(np.asarray(cal.per_newton, dtype=np.float64), (taxels,)).copy()
        for index, override in cal.overrides.items():
            i = int(index)
            if override.zero is not None:
                zero[i] = override.zero
            if override.per_newton is not None:
                per_n[i] = override.per_newton
        return cls(zero, per_n, cal.raw_scale, cal.valid_min, cal.valid_max, cal.full_scale_n)

    @property
    def taxels(self) -> int:
        return self.zero.shape[0]

    def to_newtons(self, raw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Forces in N and per-scan flags for raw scans of shape ``(..., taxels)``.

        Readings outside ``[valid_min, valid_max]`` or not finite become NaN and set
        INVALID (the detector replaces them by the taxel's last good value); forces
        at or over full scale set SATURATED and are kept at full scale.
        """
        reading = np.asarray(raw, dtype=np.float64) * self.raw_scale
        forces = (reading - self.zero) / self.per_newton
        if reading.ndim == 1:
            # One live scan: in range and under full scale is the rule, and three
            # reductions decide it; a bridge at 100 Hz meets each scan with a cold
            # cache, where every numpy call counts (NaN fails both comparisons).
            if _MIN(reading) >= self.valid_min and _MAX(reading) <= self.valid_max:
                if _MAX(forces) < self.full_scale_n:
                    return forces, _NO_FLAGS
        bad = ~((reading >= self.valid_min) & (reading <= self.valid_max))  # NaN -> bad
        saturated = forces >= self.full_scale_n
        forces = np.where(bad, np.nan, np.minimum(forces, self.full_scale_n))
        flags = np.where(bad.any(axis=-1), int(FrameFlag.INVALID), 0) | np.where(
            saturated.any(axis=-1), int(FrameFlag.SATURATED), 0
        )
        return forces, flags.astype(np.int64)

    def to_raw(self, forces: np.ndarray) -> np.ndarray:
        """The inverse model: raw values a node would report for these forces (float;
        a node rounds them to its integer unit)."""
        return (self.zero + self.per_newton * np.asarray(forces, dtype=np.float64)) / self.raw_scale

    def tared(self, unloaded_raw: np.ndarray) -> Calibrator:
        """A copy whose zero is each taxel's mean reading over an unloaded recording.

        ``unloaded_raw`` has shape ``(scans, taxels)``; invalid readings are ignored.
        A taxel with no valid reading keeps its zero.
        """
        reading = np.asarray(unloaded_raw, dtype=np.float64) * self.raw_scale
        if reading.ndim != 2 or reading.shape[1] != self.taxels:
            raise ValueError(f"tare: expected scans of {self.taxels} taxels, got shape {reading.shape}")
        ok = (reading >= self.valid_min) & (reading <= self.valid_max)
        count = ok.sum(axis=0)
        mean = np.where(ok, reading, 0.0).sum(axis=0) / np.maximum(count, 1)
        zero = np.where(count > 0, mean, self.zero)
        return Calibrator(zero, self.per_newton, self.raw_scale, self.valid_min, self.valid_max, self.full_scale_n)
