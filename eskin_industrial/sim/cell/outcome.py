"""What one episode came to: held, dropped or crushed, how far the object slid, how hard
and how often the cell squeezed.  Built the same way from a real-time run and a
virtual-time one."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from .policy import Raise
from .world import CellWorld

#: A raise with no slide in this long before it is a needless squeeze: longer than the
#: default method's slowest detections (p90 120 ms held out) and the chain's latency.
NEEDLESS_WINDOW_S = 0.5

Outcome = Literal["held", "dropped", "crushed"]


@dataclass(frozen=True)
class EpisodeResult:
    control: str  #: the method, or a baseline (fixed, oracle)
    object: str
    seed: int
    fragile: bool
    outcome: Outcome
    slid_mm: float  #: the path slid over the episode
    slides: int  #: slides that began
    holding_s: float  #: time the fingers carried it, intact
    grip_ns: float  #: the grip force integrated over that time
    fixed_n: float  #: the fixed grip for this object (the reference)
    peak_n: float
    raises: int  #: raises of the force request on a slip (or a slip that lasts)
    needless: int  #: of them, with no slide in ``NEEDLESS_WINDOW_S`` before
    fallbacks: int  #: raises to the fallback for want of a verdict
    #: onset of each slide -> the PLC's first raise after it (s); None: no raise before it ended + 0.5 s
    reactions_s: tuple[float | None, ...] = ()

    @property
    def held(self) -> bool:
        return self.outcome == "held"

    @property
    def mean_grip_n(self) -> float:
        return self.grip_ns / self.holding_s if self.holding_s > 0 else 0.0


def needless(raises: list[Raise], slides: list[tuple[float, float | None]], window_s: float = NEEDLESS_WINDOW_S) -> int:
    """Raises on a slip with no slide under way in the ``window_s`` before them."""
    count = 0
    for r in raises:
        if r.why == "no verdict":
            continue
        if not any(start <= r.t and (end is None or end >= r.t - window_s) for start, end in slides):
            count += 1
    return count


def reactions(raises: list[Raise], slides: list[tuple[float, float | None]]) -> tuple[float | None, ...]:
    out: list[float | None] = []
    for start, end in slides:
        stop = float("inf") if end is None else end + NEEDLESS_WINDOW_S
        first = next((r.t for r in raises if r.why != "no verdict" and start <= r.t <= stop), None)
        out.append(None if first is None else first - start)
    return tuple(out)


def result_of(control: str, world: CellWorld, raises: list[Raise], fixed_n: float) -> EpisodeResult:
    c = world.contact
    outcome: Outcome = "crushed" if c.crushed_at is not None else "dropped" if c.dropped_at is not None else "held"
    spec = world.episode.specimen
    slip_raises = [r for r in raises if r.why != "no verdict"]
    return EpisodeResult(control, spec.kind.name, world.episode.seed, spec.fragile, outcome, c.slid_mm, len(c.slides),
                         world.holding_s, world.grip_ns, fixed_n, world.peak_n, len(slip_raises),
                         needless(raises, c.slides), len(raises) - len(slip_raises), reactions(raises, c.slides))
