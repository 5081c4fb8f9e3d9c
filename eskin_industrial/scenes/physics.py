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


def force_drop_factor(t: np.ndarray, events: tuple[Event, ...], rng: np.random.Generator) -> np.ndarray:
    """The normal force's drop at each slide's onset (``force_drop``): a factor (K,)
    falling by the drawn fraction over ``force_drop_s`` and staying there.  A scene
    with no drop draws nothing (its other draws stay as they were)."""
    factor = np.ones_like(t)
    for e in events:
        if e.kind == "slide" and e.force_drop:
            drop = drawn(e.force_drop, rng)
            factor *= 1.0 - drop * smooth_ramp((t - e.t_s) / e.force_drop_s)
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
        if e.kind == "slide" and e.step_hz:
            moved, ripple = stepped_slide(t, e, rng)
            jitter += moved
            factor *= ripple
            continue
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


def cof_jitter(t: np.ndarray, amplitude_mm: float, band_hz: float, rng: np.random.Generator) -> np.ndarray:
    """A held contact's wander (K, 2) mm: white noise per axis kept below ``band_hz``
    (a Gaussian roll-off, so it has no ringing edge), scaled so that its largest
    excursion on each axis is ``amplitude_mm`` (the scene's jitter reaches its bound
    once, whatever its length).  No amplitude: zeros, and nothing drawn."""
    out = np.zeros((t.size, 2))
    if amplitude_mm <= 0 or t.size < 2:
        return out
    dt = float(np.median(np.diff(t)))
    freq = np.fft.rfftfreq(t.size, dt)
    gain = np.exp(-0.5 * (freq / band_hz) ** 2)
    for axis in range(2):
        wander = np.fft.irfft(np.fft.rfft(rng.standard_normal(t.size)) * gain, n=t.size)
        wander -= wander.mean()
        peak = float(np.abs(wander).max())
        out[:, axis] = amplitude_mm * wander / peak if peak > 0 else 0.0
    return out


def drawn(values: tuple[float, ...], rng: np.random.Generator) -> float:
    """One value, or a draw from the range ``[low, high]``."""
    return float(values[0]) if len(values) == 1 else float(rng.uniform(values[0], values[1]))


def stepped_slide(t: np.ndarray, e: Event, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A slide that moves in jumps with rests between them (``step_hz``, ``step_rest``):
    its offset from the constant-speed path of :func:`slide_offset` (K, 2) and a force
    factor (K,).

    Each period (``1 / step_hz``, wandering by 20 %; the periods are scaled to fill the
    slide exactly) starts with a jump, a smooth move over ``1 - step_rest`` of it that
    covers the period's share of the distance, and rests for the remainder: the slide
    starts with its first jump (its label's onset) and ends on the spot it would reach.
    The normal force ripples as the sawtooth of :func:`stick_slip` does, in step with
    the jumps: it drops at each jump and builds up again while the contact sticks."""
    hz, rest = drawn(e.step_hz, rng), drawn(e.step_rest, rng)
    duration = e.end_s - e.t_s
    count = int(np.ceil(duration * hz * 2.0)) + 2  # enough, however short the periods drawn
    periods = (1.0 + 0.2 * rng.standard_normal(count)).clip(0.5, 1.5) / hz
    ends = np.cumsum(periods)
    n = int(np.searchsorted(ends, duration)) + 1  # periods that reach the slide's end
    periods = periods[:n] * (duration / ends[n - 1])
    starts = e.t_s + np.concatenate(([0.0], np.cumsum(periods)[:-1]))
    active = (t >= e.t_s) & (t < e.end_s)
    idx = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, n - 1)
    within = (t - starts[idx]) / periods[idx]  # 0 .. 1 through its period
    moved = (starts[idx] - e.t_s + periods[idx] * smooth_ramp(within / (1.0 - rest))) / duration
    linear = np.clip((t - e.t_s) / duration, 0.0, 1.0)
    offset = np.where(active, moved - linear, 0.0)[:, None] * np.asarray(e.distance_mm)[None, :]
    saw = 2.0 * within - 1.0
    ripple = np.where(active, 1.0 + e.stick_slip_force * (saw + 0.3 * rng.standard_normal(t.size)), 1.0)
    return offset, ripple


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


def rotation_deg(t: np.ndarray, events: tuple[Event, ...], start_deg: float = 0.0) -> np.ndarray:
    """Footprint orientation about the normal (K,) in degrees: each ``rotate`` turns it
    at constant angular speed about its own centre (torsional slip)."""
    angle = np.full(t.size, float(start_deg))
    for e in events:
        if e.kind == "rotate":
            duration = max(e.end_s - e.t_s, 1e-9)
            angle += np.clip((t - e.t_s) / duration, 0.0, 1.0) * e.angle_deg
    return angle


def lift_off_gradient(t: np.ndarray, events: tuple[Event, ...]) -> np.ndarray:
    """Extra pressure gradient (K, 2) per mm while slides with ``lift_off_per_mm`` run:
    the object tips towards where it slides, ramped in over the slide's first
    ``lift_off_s`` and out over as long after it ends."""
    grad = np.zeros((t.size, 2))
    for e in events:
        if e.kind != "slide" or e.lift_off_per_mm == 0:
            continue
        span = e.lift_off_s
        envelope = np.minimum(smooth_ramp((t - e.t_s) / span), smooth_ramp((e.end_s + span - t) / span))
        direction = np.asarray(e.distance_mm) / max(np.hypot(e.distance_mm[0], e.distance_mm[1]), 1e-9)
        grad += e.lift_off_per_mm * envelope[:, None] * direction[None, :]
    return grad


def needs_sampling(foot: Footprint, events: tuple[Event, ...]) -> bool:
    """Whether the scene needs :func:`sampled_forces` (the exact rectangle model is
    kept for every scene it can describe, so that their figures do not move)."""
    return (foot.shape != "rectangle" or foot.angle_deg != 0.0
            or any(e.kind == "rotate" or e.lift_off_per_mm > 0 for e in events))


def shape_weights(shape: str, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Relative pressure at footprint points (u, v in [-0.5, 0.5] of its size), summing to 1."""
    if shape == "cylinder":  # a line contact along v: Hertzian across u
        w = np.sqrt(np.clip(1.0 - (2 * u) ** 2, 0.0, None))
    elif shape == "sphere":  # a point contact: Hertzian over a disc (an ellipse if sizes differ)
        w = np.sqrt(np.clip(1.0 - (2 * u) ** 2 - (2 * v) ** 2, 0.0, None))
    else:
        w = np.ones_like(u)
    return w / w.sum()


def _cells(pos: np.ndarray, h: np.ndarray, pitch: float) -> tuple[np.ndarray, np.ndarray]:
    """Each sample point is a little box of side ``h``: the first cell it overlaps
    along one axis and the share of it in that cell (the rest is in the next one)."""
    lo = pos - h / 2
    first = np.floor((lo + pitch / 2) / pitch)
    share = np.clip(((first + 0.5) * pitch - lo) / h, 0.0, 1.0)
    return first.astype(np.int64), share


def sampled_forces(array: ArraySpec, foot: Footprint, centre: np.ndarray, angle_deg: np.ndarray,
                   gradient: np.ndarray, force: np.ndarray, n: int = 48) -> np.ndarray:
    """Forces (K, rows*cols) of any footprint shape, turned by ``angle_deg`` about its
    centre, with a per-frame pressure gradient (K, 2) in the array's frame: the
    footprint is n x n small boxes, each spread over the cells it overlaps, so the
    forces change continuously as it moves.  Where the gradient would make pressure
    negative the footprint lifts off; the normal force stays ``force``."""
    px, py = array.pitch_mm, array.row_pitch_mm or array.pitch_mm
    u = (np.arange(n) + 0.5) / n - 0.5
    uu, vv = (a.ravel() for a in np.meshgrid(u, u))
    base = shape_weights(foot.shape, uu, vv)
    on = base > 0
    uu, vv, base = uu[on], vv[on], base[on]
    grow = (np.maximum(force, 1e-9) / foot.reference_force_n) ** foot.size_exponent
    taxels = array.rows * array.cols
    out = np.zeros((force.size, taxels))
    chunk = max(1, 2_000_000 // uu.size)
    for a in range(0, force.size, chunk):
        s = slice(a, a + chunk)
        sx, sy = foot.size_mm[0] * grow[s, None], foot.size_mm[1] * grow[s, None]
        th = np.radians(angle_deg[s])[:, None]
        lx, ly = uu[None, :] * sx, vv[None, :] * sy
        dx, dy = lx * np.cos(th) - ly * np.sin(th), lx * np.sin(th) + ly * np.cos(th)
        w = base[None, :] * np.clip(1.0 + gradient[s, 0:1] * dx + gradient[s, 1:2] * dy, 0.0, None)
        w *= force[s, None] / np.maximum(w.sum(axis=1, keepdims=True), 1e-300)
        ix, fx = _cells(centre[s, 0:1] + dx, sx / n, px)
        iy, fy = _cells(centre[s, 1:2] + dy, sy / n, py)
        frame = np.arange(w.shape[0])[:, None] * taxels
        acc = np.zeros(w.shape[0] * taxels)
        for cx, wx in ((ix, fx), (ix + 1, 1.0 - fx)):
            for cy, wy in ((iy, fy), (iy + 1, 1.0 - fy)):
                ok = (cx >= 0) & (cx < array.cols) & (cy >= 0) & (cy < array.rows)
                acc += np.bincount((frame + cy * array.cols + cx)[ok], (w * wx * wy)[ok], minlength=acc.size)
        out[s] = acc.reshape(-1, taxels)
    return out
