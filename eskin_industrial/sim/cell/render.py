"""The taxel frames the node sends, rendered one at a time from the cell's state (the
normal force on the sensed pad, where the contact is), with the scenes' contact model
and sensor effects, so that the detector sees the kind of data the open-loop scenes
give it.

- The contact: the scenes' footprint (``scenes/physics.py``) moved by the object's
  displacement.  A rectangle (the hand's soft fingertips, a block) is computed exactly
  as ``footprint_forces`` does, for one frame; a sphere or a cylinder (rigid) is
  ``sampled_forces`` at unit force on a 0.5 mm grid of displacements, computed where
  first needed and interpolated (within 1 % of the force of a direct rendering, 0.2 %
  for a sphere).
- Nothing of its own while it slides: the stick-slip micro-motion and force ripple,
  and a normal force lost at a slide's onset, are the physics' (``world.py`` hands
  them in as the contact's place and force); a smooth slide renders smooth.
- The sensor: the scenes' effects in their order (``scenes/sensor.py``), per frame,
  with the film's creep as explicit state; the random draws (noise, gains, jitter) are
  made per episode from its seed, one row a frame, so that a frame's noise does not
  depend on when it was rendered (the real-time and virtual-time runs see the same).

No I/O.
"""

from __future__ import annotations

import math

import numpy as np

from ...scenes import sensor
from ...scenes.physics import sampled_forces, taxel_centres
from ...scenes.spec import ArraySpec, Footprint, SensorEffects
from .objects import CellObject

#: Grid step of the sampled shapes' displacement table (mm).
GRID_MM = 0.5


class _Rectangle:
    """``footprint_forces`` for one frame (the same floats): uniform pressure over a
    rectangle, tilted by its gradient, grown with the force on a soft contact."""

    def __init__(self, array: ArraySpec, foot: Footprint) -> None:
        xs, ys = taxel_centres(array)
        px, py = array.pitch_mm, array.row_pitch_mm or array.pitch_mm
        self.xs, self.ys = xs, ys
        self.xlo, self.xhi = xs - px / 2, xs + px / 2
        self.ylo, self.yhi = ys - py / 2, ys + py / 2
        self.foot = foot
        gx, gy = foot.gradient_per_mm
        self.tilted = gx != 0.0 or gy != 0.0

    def forces(self, cx: float, cy: float, force: float) -> np.ndarray:
        foot = self.foot
        grow = (max(force, 1e-9) / foot.reference_force_n) ** foot.size_exponent if foot.size_exponent else 1.0
        sx, sy = foot.size_mm[0] * grow, foot.size_mm[1] * grow
        ox = np.clip(np.minimum(cx + sx / 2, self.xhi) - np.maximum(cx - sx / 2, self.xlo), 0.0, None)
        oy = np.clip(np.minimum(cy + sy / 2, self.yhi) - np.maximum(cy - sy / 2, self.ylo), 0.0, None)
        area = oy[:, None] * ox[None, :]
        if self.tilted:
            gx, gy = foot.gradient_per_mm
            area = area * np.clip(1.0 + gx * (self.xs[None, :] - cx) + gy * (self.ys[:, None] - cy), 0.0, None)
        return (force / (sx * sy) * area).ravel()


class _Sampled:
    """A rigid sphere or cylinder: unit-force frames on a grid of displacements from
    its starting centre, made on first use and kept (shared by every episode of the
    same object in this process), interpolated bilinearly."""

    _tables: dict[tuple[ArraySpec, Footprint], dict[tuple[int, int], np.ndarray]] = {}

    def __init__(self, array: ArraySpec, foot: Footprint) -> None:
        if foot.size_exponent:
            raise ValueError("cell rendering: a soft contact must be a rectangle")
        self.array, self.foot = array, foot
        self.nodes = self._tables.setdefault((array, foot), {})
        self.cx0, self.cy0 = foot.centre_mm

    def _node(self, i: int, j: int) -> np.ndarray:
        w = self.nodes.get((i, j))
        if w is None:
            centre = np.array([[self.cx0 + i * GRID_MM, self.cy0 + j * GRID_MM]])
            w = sampled_forces(self.array, self.foot, centre, np.array([self.foot.angle_deg]), np.zeros((1, 2)),
                               np.ones(1))[0]
            self.nodes[(i, j)] = w
        return w

    def forces(self, cx: float, cy: float, force: float) -> np.ndarray:
        fx, fy = (cx - self.cx0) / GRID_MM, (cy - self.cy0) / GRID_MM
        i, j = math.floor(fx), math.floor(fy)
        u, v = fx - i, fy - j
        w = ((1 - u) * (1 - v)) * self._node(i, j) + (u * (1 - v)) * self._node(i + 1, j)
        if v:
            w = w + ((1 - u) * v) * self._node(i, j + 1) + (u * v) * self._node(i + 1, j + 1)
        return force * w


class FrameRenderer:
    """Frames of one episode: ``frame(k, t, force_n, dx_mm, dy_mm)``.

    ``frames`` bounds the episode (the draws are made for that many frames at once)."""

    def __init__(self, kind: CellObject, rate_hz: float, frames: int, rng: np.random.Generator) -> None:
        self.kind = kind
        foot = kind.footprint
        shaped = foot.shape != "rectangle" or foot.angle_deg != 0.0
        self.shape = _Sampled(kind.array, foot) if shaped else _Rectangle(kind.array, foot)
        self.cx0, self.cy0 = foot.centre_mm
        self.n = kind.array.rows * kind.array.cols
        self.dt = 1.0 / rate_hz
        fx: SensorEffects = kind.sensor
        self.fx = fx
        n = self.n
        # every draw up front, a row a frame (the order is fixed: it is the episode's)
        self.gain = 1.0 + fx.gain_mismatch * rng.standard_normal(n) if fx.gain_mismatch else None
        self.drift_gain = 1.0 + fx.drift_spread * rng.standard_normal(n) if fx.drift_n_per_s else None
        self.noise = fx.noise_n * rng.standard_normal((frames, n)) if fx.noise_n else None
        self.dropped = rng.random(frames) < fx.drop_rate if fx.drop_rate else None
        self._lag = np.zeros(n)  # the film's creep (first-order lag)
        self._t_prev: float | None = None
        self._key: tuple[float, float, float] | None = None
        self._contact = np.zeros(self.n)

    def lost(self, k: int) -> bool:
        """Whether frame ``k`` never reaches the host (the scenes' ``drop_rate``)."""
        return self.dropped is not None and bool(self.dropped[k])

    def frame(self, k: int, t: float, force_n: float, dx_mm: float, dy_mm: float) -> np.ndarray:
        """Frame ``k`` at ``t``: ``force_n`` on the footprint moved by (dx, dy) mm."""
        cx, cy = self.cx0 + dx_mm, self.cy0 + dy_mm
        key = (cx, cy, force_n)
        if key != self._key:  # a still hold renders the same contact frame after frame
            self._key = key
            self._contact = self.shape.forces(cx, cy, force_n) if force_n > 0.0 else np.zeros(self.n)
        return self._sense(k, t, self._contact)

    def _sense(self, k: int, t: float, f: np.ndarray) -> np.ndarray:
        """``scenes.sensor.apply`` for one frame, in its order."""
        fx = self.fx
        if fx.creep_fraction:
            dt = 0.0 if self._t_prev is None else t - self._t_prev
            up, down = -math.expm1(-dt / fx.creep_s), -math.expm1(-dt / fx.creep_recovery_s)
            self._lag += (f - self._lag) * np.where(f > self._lag, up, down)
            f = f + fx.creep_fraction * self._lag
        self._t_prev = t
        if fx.crosstalk:
            f = sensor.crosstalk(f[None, :], self.kind.array.rows, self.kind.array.cols, fx.crosstalk)[0]
        if self.gain is not None:
            f = f * self.gain
        if fx.machine_vibration_n:
            f = sensor.machine_vibration(f[None, :], np.array([t]), fx.machine_vibration_n, fx.machine_vibration_hz,
                                         fx.machine_vibration_start_s)[0]
        if self.drift_gain is not None:
            f = f + fx.drift_n_per_s * t * self.drift_gain
        if self.noise is not None:
            f = f + self.noise[k]
        f = np.maximum(f, 0.0)
        if fx.dead_taxels or fx.stuck_taxels:
            f = sensor.dead_and_stuck(f[None, :], fx.dead_taxels, fx.stuck_taxels, fx.stuck_value_n)[0]
        return sensor.saturate(sensor.quantize(f, fx.quantization_n), fx.saturation_n)
