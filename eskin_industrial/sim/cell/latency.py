"""The chain's latencies as the virtual-time run draws them: distributions measured on
the real chain (``benchmarks/bench_cell_latency.py``, which prints these tables; the
run behind them is in docs/benchmarks.md, *The closed loop's latencies*).

- ``SCAN_TO_PLC``: from the moment the node sends a scan to the moment the PLC's
  memory holds the state the bridge decided on it: the CAN bus and the bridge's reader
  thread, the pipeline and the detector, the register image and the Modbus TCP write
  into the PLC stand-in (loopback);
- ``PLC_TO_GRIPPER``: from the PLC program's write of a force request to the
  gripper's receipt of it (Modbus TCP, loopback).

The PLC's scan cycle and the gripper's dead time are not in them: the virtual run
models those itself (a fixed cycle at a random phase; ``actuator.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Quantiles:
    """An empirical distribution: its quantiles at ``probs`` (0 and 1 included),
    drawn from by inverse transform with linear interpolation."""

    probs: tuple[float, ...]
    values_s: tuple[float, ...]

    def __post_init__(self) -> None:
        if len(self.probs) != len(self.values_s) or self.probs[0] != 0.0 or self.probs[-1] != 1.0:
            raise ValueError("quantiles: expected one value per probability, from 0 to 1")
        if list(self.values_s) != sorted(self.values_s) or list(self.probs) != sorted(self.probs):
            raise ValueError("quantiles: expected rising probabilities and values")

    def draw(self, rng: np.random.Generator) -> float:
        return float(np.interp(rng.random(), self.probs, self.values_s))

    def shifted(self, by_s: float) -> Quantiles:
        return Quantiles(self.probs, tuple(v + by_s for v in self.values_s))

    @property
    def median_s(self) -> float:
        return float(np.interp(0.5, self.probs, self.values_s))

    @classmethod
    def of(cls, samples_s: np.ndarray | list[float], probs: tuple[float, ...] | None = None) -> Quantiles:
        """The quantiles of measured samples."""
        probs = probs or PROBS
        values = np.quantile(np.asarray(samples_s, dtype=np.float64), probs)
        return cls(tuple(probs), tuple(float(v) for v in np.maximum.accumulate(values)))


PROBS: tuple[float, ...] = (0.0, 0.05, 0.1, 0.25, 0.5, 0.75, 0.9, 0.95, 0.99, 1.0)

# benchmarks/bench_cell_latency.py --episodes 30 (146 state changes, 92 force requests;
# docs/benchmarks.md, *The closed loop's latencies*)

SCAN_TO_PLC = Quantiles(PROBS, (0.00065, 0.00069, 0.00073, 0.00078, 0.00099, 0.00304, 0.00673, 0.01033, 0.01670, 0.03469))
PLC_TO_GRIPPER = Quantiles(PROBS, (0.00017, 0.00024, 0.00027, 0.00031, 0.00037, 0.00048, 0.00098, 0.00230, 0.00477, 0.00479))
