"""The failure map's conditions: each pushes one property of every scene, leaving the
rest as the scene defines it."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

from ..scenes import SceneSpec

Hook = Callable[[SceneSpec], SceneSpec]


def noise(sigma_n: float) -> Hook:
    return lambda s: replace(s, sensor=replace(s.sensor, noise_n=sigma_n))


def contact_size(size_mm: float) -> Hook:
    """A square footprint of this side (the 5 x 5 array is 25 mm wide)."""
    def hook(s: SceneSpec) -> SceneSpec:
        if s.array.rows * s.array.cols != 25:
            return s
        return replace(s, footprint=replace(s.footprint, size_mm=(size_mm, size_mm)))
    return hook


def force_scale(factor: float) -> Hook:
    def hook(s: SceneSpec) -> SceneSpec:
        events = tuple(replace(e, force_n=e.force_n * factor) if e.force_n is not None else e for e in s.events)
        return replace(s, events=events)
    return hook


def slip_speed(speed_mm_s: float) -> Hook:
    def hook(s: SceneSpec) -> SceneSpec:
        return replace(s, events=tuple(replace(e, speed_mm_s=speed_mm_s) if e.kind == "slide" else e for e in s.events))
    return hook


def dead_taxels(count: int) -> Hook:
    def hook(s: SceneSpec) -> SceneSpec:
        n = s.array.rows * s.array.cols
        chosen = tuple(sorted({(7 * i + 3) % n for i in range(count)}))  # spread over the array
        return replace(s, sensor=replace(s.sensor, dead_taxels=chosen))
    return hook


def drop_rate(rate: float) -> Hook:
    return lambda s: replace(s, sensor=replace(s.sensor, drop_rate=rate))


def vibration(amplitude_n: float, freq_hz: float = 37.0, start_s: float = 0.0) -> Hook:
    return lambda s: replace(s, sensor=replace(s.sensor, machine_vibration_n=amplitude_n, machine_vibration_hz=freq_hz,
                                               machine_vibration_start_s=start_s))


def vibration_onset(amplitude_n: float) -> Hook:
    """A machine that starts shaking mid-scene (3 s: the grab has settled, no slide has
    begun): a new ripple in the total force with nothing moving."""
    return vibration(amplitude_n, 37.0, start_s=3.0)


#: name -> (axis label, values, hook factory or None for the sample rate)
CONDITIONS: dict[str, tuple[str, tuple[float, ...], Callable[[float], Hook] | None]] = {
    "noise": ("taxel noise (N rms)", (0.003, 0.01, 0.03, 0.06, 0.1), noise),
    "contact": ("contact size on 5x5 (mm)", (5.0, 8.0, 12.0, 16.0, 20.0), contact_size),
    "force": ("force scale (x scene force)", (0.05, 0.15, 0.3, 0.6, 1.0), force_scale),
    "speed": ("slip speed (mm/s)", (0.3, 1.0, 3.0, 10.0, 30.0), slip_speed),
    "rate": ("sample rate (Hz)", (50.0, 100.0, 250.0, 500.0, 2000.0), None),
    "dead": ("dead taxels", (0, 2, 4, 6, 8), lambda v: dead_taxels(int(v))),
    "drops": ("dropped frames (fraction)", (0.0, 0.02, 0.05, 0.1, 0.2), drop_rate),
    "vibration": ("machine vibration at 37 Hz (N)", (0.0, 0.1, 0.3, 1.0, 2.0), vibration),
    "onset": ("the same, starting mid-hold (N)", (0.0, 0.1, 0.3, 1.0, 2.0), vibration_onset),
}


def slide_ripple(fraction: float) -> Hook:
    """Every slide's stick-slip force ripple (``stick_slip_force``, 4 % in the scenes):
    how strongly the normal force shakes as the contact sticks and slips (for slides in
    jumps, how far it drops at each jump)."""
    return lambda s: replace(s, events=tuple(replace(e, stick_slip_force=fraction) if e.kind == "slide" else e
                                             for e in s.events))


#: Conditions ``evaluate --condition`` can push beyond the failure map's (which draws
#: ``CONDITIONS`` only): name -> (axis label, values, hook factory).
MORE_CONDITIONS: dict[str, tuple[str, tuple[float, ...], Callable[[float], Hook]]] = {
    "ripple": ("slides' force ripple (fraction of the grip)", (0.0, 0.04, 0.08, 0.12), slide_ripple),
}
