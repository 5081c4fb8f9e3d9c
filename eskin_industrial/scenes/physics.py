"""Minimal contact physics: each effect is one small function of time, composed per
scene from the events it lists.  Everything is vectorized over the sample times."""

from __future__ import annotations

import numpy as np

from .spec import ArraySpec, Event, Footprint


def smooth_ramp(u: np.ndarray) -> np.ndarray:
    """0 -> 1 over u in [0, 1] with zero slope at both ends (a motor's soft start)."""
    u = np.clip(u, 0.0, 1.0)
    return u * u * (3.0 - 2.0 * u)


def force_profile(t: np.ndarray, events: tuple[Event, ...]) -> np.ndarray:
    """Total normal force over time: press, force ramps, release, and slides that
    change the force; each ramp starts from the level the previous one reached."""
    force = np.zeros_like(t)
    level = 0.0
    for e in events:
        target = {"press": e.force_n, "force": e.force_n, "release": 0.0}.get(e.kind, e.force_n)
        if target is None or e.kind == "oscillate":
            continue
        duration = e.end_s - e.t_s
        u = (t - e.t_s) / duration if duration > 0 else (t >= e.t_s).astype(float)
        force = np.where(t >= e.t_s, level + (target - level) * smooth_ramp(u), force)
        level = target
    return force


def oscillation_factor(t: np.ndarray, events: tuple[Event, ...]) -> np.ndarray:
    """Inertial force oscillation (a glass moved back and forth): a multiplicative factor."""
    factor = np.ones_like(t)
    for e in events:
        if e.kind == "oscillate":
            active = (t >= e.t_s) & (t < e.end_s)
            factor = np.where(active, factor * (1.0 + e.amplitude * np.sin(2 * np.pi * e.freq_hz * (t - e.t_s))), factor)
    return factor


def slide_offset(t: np.ndarray, events: tuple[Event, ...]) -> np.ndarray:
    """Footprint displacement (K, 2) in mm: each slide moves it at constant speed."""
    offset = np.zeros((t.size, 2))
    for e in events:
        if e.kind != "slide":
            continue
        duration = max(e.end_s - e.t_s, 1e-9)
        frac = np.clip((t - e.t_s) / duration, 0.0, 1.0)
        offset += frac[:, None] * np.asarray(e.distance_mm)[None, :]
    return offset


def stick_slip(t: np.ndarray, events: tuple[Event, ...], rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Micro-motion while sliding: position jitter (K, 2) mm and a force factor (K,).

    Stick-slip is a relaxation oscillation: a sawtooth at ``stick_slip_hz`` whose
    period wanders, plus white jitter; it is what excites the high-frequency band.
    """
    jitter = np.zeros((t.size, 2))
    factor = np.ones_like(t)
    for e in events:
        if e.kind != "slide" or (e.stick_slip_mm == 0 and e.stick_slip_force == 0):
            continue
        active = (t >= e.t_s) & (t < e.end_s)
        if not active.any():
            continue
        n = int(active.sum())
        freq = e.stick_slip_hz * (1.0 + 0.2 * rng.standard_normal(n)).clip(0.3)
        phase = np.cumsum(freq * np.gradient(t[active])) if n > 1 else np.zeros(n)
        saw = 2.0 * (phase - np.floor(phase)) - 1.0
        direction = np.asarray(e.distance_mm) / max(np.hypot(e.distance_mm[0], e.distance_mm[1]), 1e-9)
        wobble = e.stick_slip_mm * (saw + 0.3 * rng.standard_normal(n))
        jitter[active] += wobble[:, None] * direction[None, :]
        factor[active] *= 1.0 + e.stick_slip_force * (saw + 0.3 * rng.standard_normal(n))
    return jitter, factor


def taxel_centres(array: ArraySpec) -> tuple[np.ndarray, np.ndarray]:
    row_pitch = array.row_pitch_mm or array.pitch_mm
    return np.arange(array.cols) * array.pitch_mm, np.arange(array.rows) * row_pitch


def footprint_forces(array: ArraySpec, foot: Footprint, centre: np.ndarray, force: np.ndarray) -> np.ndarray:
    """Forces (K, rows*cols) of a rectangular footprint of uniform (tilted) pressure.

    Each taxel owns the cell around it (pitch x row pitch, the film is continuous) and
    takes pressure x overlap area; force applied off the array is not measured.
    """
    xs, ys = taxel_centres(array)
    px, py = array.pitch_mm, array.row_pitch_mm or array.pitch_mm
    grow = (np.maximum(force, 1e-9) / foot.reference_force_n) ** foot.size_exponent
    sx, sy = foot.size_mm[0] * grow[:, None], foot.size_mm[1] * grow[:, None]
    cx, cy = centre[:, 0:1], centre[:, 1:2]
    ox = np.clip(np.minimum(cx + sx / 2, xs + px / 2) - np.maximum(cx - sx / 2, xs - px / 2), 0.0, None)
    oy = np.clip(np.minimum(cy + sy / 2, ys + py / 2) - np.maximum(cy - sy / 2, ys - py / 2), 0.0, None)
    area = oy[:, :, None] * ox[:, None, :]  # (K, rows, cols)
    gx, gy = foot.gradient_per_mm
    tilt = 1.0 + gx * (xs[None, None, :] - cx[:, :, None]) + gy * (ys[None, :, None] - cy[:, :, None])
    pressure = force[:, None, None] / (sx * sy)[:, :, None]
    return (pressure * area * np.clip(tilt, 0.0, None)).reshape(force.size, -1)
