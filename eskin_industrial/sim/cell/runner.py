"""Every control over every episode, in virtual time: the closed-loop evaluation's
work, in one process or spread over several (each episode is independent and
deterministic, so the figures do not depend on how many)."""

from __future__ import annotations

import concurrent.futures
import multiprocessing
from collections.abc import Sequence
from dataclasses import dataclass, field

from ...profile import Profile, load_profile
from ...progress import NO_PROGRESS, Progress
from .episodes import Batch, episode
from .outcome import EpisodeResult
from .recipes import FIXED_SAFETY, POLICY, PolicyFactors, fixed_grip_n, policy_settings
from .virtual import ChainSpec, run_episode

#: Episodes per task handed to a worker process.
CHUNK = 10


@dataclass(frozen=True)
class Setup:
    """Everything an episode's run depends on but its seed and its control."""

    chain: ChainSpec = field(default_factory=ChainSpec)
    batch: Batch = field(default_factory=Batch)
    factors: PolicyFactors = POLICY
    #: the catalogue's safety factor of the fixed grip (None: the recipes' choice)
    fixed_safety: float | None = None


_PROFILES: dict[str, Profile] = {}


def _profile(name: str) -> Profile:
    prof = _PROFILES.get(name)
    if prof is None:
        prof = _PROFILES[name] = load_profile(name)
    return prof


def run_seed(seed: int, control: str, setup: Setup) -> EpisodeResult:
    ep = episode(seed, setup.batch)
    kind = ep.kind
    drive = setup.chain.actuator
    safety = FIXED_SAFETY if setup.fixed_safety is None else setup.fixed_safety
    fixed = fixed_grip_n(kind, safety, drive)
    settings = policy_settings(kind, setup.factors, safety, drive)
    return run_episode(ep, control, _profile(kind.profile), setup.chain, settings, fixed)


def _chunk(seeds: Sequence[int], controls: Sequence[str], setup: Setup) -> list[EpisodeResult]:
    return [run_seed(s, c, setup) for s in seeds for c in controls]


def run_controls(controls: Sequence[str], seeds: Sequence[int], setup: Setup = Setup(), jobs: int = 1,
                 progress: Progress = NO_PROGRESS) -> dict[str, list[EpisodeResult]]:
    """Each control's results over ``seeds`` (in seed order); ``progress`` advances by
    one per episode and control."""
    out: dict[str, list[EpisodeResult]] = {c: [] for c in controls}
    chunks = [list(seeds[i:i + CHUNK]) for i in range(0, len(seeds), CHUNK)]
    if jobs <= 1:
        for chunk in chunks:
            for s in chunk:
                for c in controls:
                    out[c].append(run_seed(s, c, setup))
                    progress.advance(1, f"{c}, seed {s}")
        return out
    # spawn: a fresh interpreter per worker, whatever threads this process runs
    ctx = multiprocessing.get_context("spawn")
    with concurrent.futures.ProcessPoolExecutor(jobs, mp_context=ctx) as pool:
        futures = {pool.submit(_chunk, chunk, list(controls), setup): i for i, chunk in enumerate(chunks)}
        done: dict[int, list[EpisodeResult]] = {}
        for fut in concurrent.futures.as_completed(futures):
            done[futures[fut]] = fut.result()
            progress.advance(len(done[futures[fut]]), f"{len(done)} of {len(chunks)} chunks")
    for i in range(len(chunks)):
        for r in done[i]:
            out[r.control].append(r)
    return out
