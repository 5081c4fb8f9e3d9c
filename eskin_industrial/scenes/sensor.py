"""What the sensor does to the true forces: each imperfection one small function."""

from __future__ import annotations

import numpy as np

from .spec import SensorEffects


def gain_mismatch(forces: np.ndarray, spread: float, rng: np.random.Generator) -> np.ndarray:
    return forces * (1.0 + spread * rng.standard_normal(int(forces.shape[1])))[None, :]


def machine_vibration(forces: np.ndarray, t: np.ndarray, amplitude_n: float, freq_hz: float,
                      start_s: float = 0.0) -> np.ndarray:
    """The machine shakes the gripper (from ``start_s`` on): the loaded taxels share a
    total-force oscillation."""
    total = forces.sum(axis=1, keepdims=True)
    share = np.divide(forces, total, out=np.zeros_like(forces), where=total > 1e-9)
    shake = np.where(t >= start_s, np.sin(2 * np.pi * freq_hz * (t - start_s)), 0.0)
    return forces + amplitude_n * shake[:, None] * share


def film_creep(forces: np.ndarray, t: np.ndarray, fraction: float, tau_s: float, recovery_s: float) -> np.ndarray:
    """Piezoresistive creep with hysteresis: each taxel reads its force plus ``fraction``
    of a first-order lag of it, which follows a rising load with ``tau_s`` and a falling
    one with ``recovery_s`` (a longer recovery: the film lags on unloading)."""
    lag = np.zeros(forces.shape[1])
    out = np.empty_like(forces)
    dt = np.diff(t, prepend=t[0])
    up, down = -np.expm1(-dt / tau_s), -np.expm1(-dt / recovery_s)
    for k in range(forces.shape[0]):  # a per-sample recursion: only scenes that ask for it pay
        f = forces[k]
        lag += (f - lag) * np.where(f > lag, up[k], down[k])
        out[k] = f + fraction * lag
    return out


def crosstalk(forces: np.ndarray, rows: int, cols: int, fraction: float) -> np.ndarray:
    """Each taxel also reads ``fraction`` of each row and column neighbour's force."""
    grid = forces.reshape(-1, rows, cols)
    spill = np.zeros_like(grid)
    spill[:, 1:, :] += grid[:, :-1, :]
    spill[:, :-1, :] += grid[:, 1:, :]
    spill[:, :, 1:] += grid[:, :, :-1]
    spill[:, :, :-1] += grid[:, :, 1:]
    return (grid + fraction * spill).reshape(forces.shape)


def baseline_drift(forces: np.ndarray, t: np.ndarray, rate_n_per_s: float, spread: float,
                   rng: np.random.Generator) -> np.ndarray:
    """Temperature drift: every taxel's offset moves linearly in time, each at the
    common rate times its own gain 1 + spread x N(0, 1)."""
    gain = 1.0 + spread * rng.standard_normal(int(forces.shape[1]))
    return forces + rate_n_per_s * (t - t[0])[:, None] * gain[None, :]


def offset(forces: np.ndarray, total_n: float) -> np.ndarray:
    """Every taxel reads its share of an unloaded offset of ``total_n`` in total."""
    return forces + total_n / forces.shape[1]


def noise(forces: np.ndarray, sigma_n: float, rng: np.random.Generator) -> np.ndarray:
    return forces + sigma_n * rng.standard_normal(forces.shape)


def quantize(forces: np.ndarray, step_n: float) -> np.ndarray:
    return np.round(forces / step_n) * step_n if step_n > 0 else forces


def saturate(forces: np.ndarray, full_scale_n: float | None) -> np.ndarray:
    return np.clip(forces, None, full_scale_n) if full_scale_n is not None else forces


def dead_and_stuck(forces: np.ndarray, dead: tuple[int, ...], stuck: tuple[int, ...], stuck_value: float) -> np.ndarray:
    out = forces.copy()
    out[:, list(dead)] = 0.0
    out[:, list(stuck)] = stuck_value
    return out


def drop_frames(n: int, rate: float, rng: np.random.Generator) -> np.ndarray:
    """Indices of the frames that reach the host (each lost with probability ``rate``)."""
    return np.flatnonzero(rng.random(n) >= rate)


def apply(forces: np.ndarray, t: np.ndarray, fx: SensorEffects, rng: np.random.Generator,
          shape: tuple[int, int] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """All effects in the order a real chain applies them; returns (kept indices, forces).
    ``shape`` (rows, cols) is the array's, for crosstalk."""
    out = film_creep(forces, t, fx.creep_fraction, fx.creep_s, fx.creep_recovery_s) if fx.creep_fraction else forces
    if fx.crosstalk and shape is not None:
        out = crosstalk(out, shape[0], shape[1], fx.crosstalk)
    out = gain_mismatch(out, fx.gain_mismatch, rng) if fx.gain_mismatch else out
    if fx.machine_vibration_n:
        out = machine_vibration(out, t, fx.machine_vibration_n, fx.machine_vibration_hz, fx.machine_vibration_start_s)
    out = baseline_drift(out, t, fx.drift_n_per_s, fx.drift_spread, rng) if fx.drift_n_per_s else out
    out = offset(out, fx.offset_n) if fx.offset_n else out
    out = noise(out, fx.noise_n, rng) if fx.noise_n else out
    out = np.maximum(out, 0.0)  # a piezoresistive taxel reads no tension
    out = dead_and_stuck(out, fx.dead_taxels, fx.stuck_taxels, fx.stuck_value_n)
    out = saturate(quantize(out, fx.quantization_n), fx.saturation_n)
    keep = drop_frames(len(t), fx.drop_rate, rng) if fx.drop_rate else np.arange(len(t))
    return keep, out[keep]
