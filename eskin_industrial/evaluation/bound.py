"""Where the slip delay's bound lies: an oracle that knows the onset and the path.

For each slip event of a rendered scene, the ideal test knows when the slide starts,
how the contact will move (the centre of force of the same scene rendered without
sensor noise: its ramp, its jumps and rests, its stick-slip) and where it was; all
it does not know is the noise.  Its statistic after ``k`` frames of the slide is the
matched filter's signal-to-noise ratio,

    SNR_k^2 = sum_{j = onset .. k} ((c_x(j) - c_x(onset - 1)) / sigma_x)^2 + (the same in y)

with ``sigma`` each axis's noise, measured as the spread of the noisy CoF over the
half-second before the onset (the contact still there).  Its delay is the time from
the onset to the first frame with SNR >= z.  At the threshold ``z`` a detector needs
to keep still holds quiet, no test that does not know the onset, the path and the
starting level can be faster: the oracle's delay is the bound, and a detector's
excess over it is what it pays for not knowing them (plus its hop and its
smoothing).  docs/evaluation.md, *The physics of the delay*, measures the methods
against it for ramps (the paper's slides) and for steps (the step-slip family).

The centre of force is what a slide moves; a turn about the normal leaves it in place.
The same matched filter on the whole normalised distribution ``p = f / S`` (each
taxel's share of the total, its noise measured per taxel the same way) watches
everything a test of the pressure image could watch, turns included: a second oracle,
at or below the first on every slide (a centre is one projection of ``p``).  Its
per-taxel noise leaves out what the shares have in common through ``S``; on the
torsion family, whose total does not change, the raw forces (noise independent by
taxel) give the same delays.

No I/O; numpy only.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..progress import NO_PROGRESS, Progress
from ..scenes import SceneSpec, load_scene, render
from .conditions import Hook
from .corpus import coordinates
from .metrics import SceneScore, spans

#: the spread of the CoF before an onset is measured over this long
NOISE_S = 0.5


def cof_path(forces: np.ndarray, x_mm: np.ndarray, y_mm: np.ndarray) -> np.ndarray:
    """(K, 2) centre of force of each frame (NaN where the total is not positive)."""
    total = forces.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        c = np.column_stack([forces @ x_mm, forces @ y_mm]) / total[:, None]
    c[~(total > 0)] = np.nan
    return c


def distribution_path(forces: np.ndarray) -> np.ndarray:
    """(K, taxels) each taxel's share of the frame's total (NaN where the total is not
    positive): the pressure image with the grip's level taken out."""
    total = forces.sum(axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        p = forces / total
    p[~(total[:, 0] > 0)] = np.nan
    return p


def oracle_delays(true_cof: np.ndarray, noisy_cof: np.ndarray, t: np.ndarray, labels: np.ndarray, z: float,
                  noise_s: float = NOISE_S) -> list[float | None]:
    """The oracle's delay (s) for each slip event (a run of ``slip`` labels), or None
    where its SNR never reaches ``z`` before the event ends.  ``true_cof`` and
    ``noisy_cof`` are (K, D) paths, each column with a noise of its own: the centre of
    force (D = 2) or the distribution (``distribution_path``)."""
    rate = 1.0 / float(np.median(np.diff(t)))
    before = max(2, round(noise_s * rate))
    out: list[float | None] = []
    for a, b in spans(np.asarray(labels) == "slip"):
        if a < before + 1:
            out.append(None)
            continue
        sigma = np.nanstd(noisy_cof[a - before:a], axis=0, ddof=1)
        sigma = np.maximum(sigma, 1e-6)  # (an axis that does not move at all, a strip's y; a taxel never loaded)
        signal = (true_cof[a:b] - true_cof[a - 1]) / sigma
        snr = np.sqrt(np.nancumsum((signal * signal).sum(axis=1)))
        hit = np.flatnonzero(snr >= z)
        out.append(float(t[a + hit[0]] - t[a]) if hit.size else None)
    return out


#: What each oracle watches: the centre of force, or the whole distribution.
PATHS: tuple[str, ...] = ("cof", "distribution")

Bound = tuple[SceneScore, dict[str, SceneScore]]


def oracle_score(scenes: tuple[str, ...], seeds: tuple[int, ...], z: float, rate_hz: float = 100.0,
                 spec_hook: Hook | None = None, stream: int | None = None,
                 progress: Progress = NO_PROGRESS) -> dict[str, Bound]:
    """Both oracles (``PATHS``) over scenes and seeds, from the same renders: for each,
    a score (events, found, delays; nothing else applies to it) and per scene."""
    out: dict[str, Bound] = {path: (SceneScore(), {}) for path in PATHS}
    for scene in scenes:
        spec: SceneSpec = load_scene(scene)
        if spec_hook is not None:
            spec = spec_hook(spec)
        quiet = replace(spec, sensor=replace(spec.sensor, noise_n=0.0))
        for seed in seeds:
            noisy = render(spec, rate_hz, seed, stream)
            clean = render(quiet, rate_hz, seed, stream)
            x, y = coordinates(noisy)
            # (the noiseless render draws the same motion; it keeps every frame the noisy
            # one keeps unless frames are dropped, which the oracle does not model)
            keep = np.isin(clean.t, noisy.t)
            paths = {"cof": (cof_path(clean.forces[keep], x, y), cof_path(noisy.forces, x, y)),
                     "distribution": (distribution_path(clean.forces[keep]), distribution_path(noisy.forces))}
            for path, (true, measured) in paths.items():
                delays = oracle_delays(true, measured, noisy.t, noisy.labels, z)
                s = SceneScore(events=len(delays), found=sum(d is not None for d in delays),
                               delays_s=[d for d in delays if d is not None])
                total, per_scene = out[path]
                total += s
                per_scene.setdefault(scene, SceneScore())
                per_scene[scene] += s
            progress.advance(1, f"oracle, {scene}")
    return out
