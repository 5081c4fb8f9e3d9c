"""``eskin-bus demo --closed-loop``: the cell's episodes through the real chain, one
object after another, with the lines the command prints and the live view shows."""

from __future__ import annotations

from collections.abc import Callable
from contextlib import AbstractContextManager

from ...profile import Profile
from .episodes import Batch, episode
from .objects import get_object
from .outcome import EpisodeResult
from .physics import DROP_MM
from .realtime import CellParts, CellRun, run_cell
from .virtual import ChainSpec
from .world import Episode

#: The demo's object by default: the hand's glass, filled while it is held.
DEFAULT_OBJECTS = ("glass",)


def demo_episode(name: str, seed: int) -> Episode:
    """The episode ``seed`` of one object (whatever the seed's turn in the evaluation)."""
    return episode(seed, Batch(objects=(get_object(name),)))


def chain_line(method: str, chain: ChainSpec) -> str:
    a = chain.actuator
    return (f"CAN node (virtual bus, {chain.rate_hz:g} Hz) -> bridge ({method}) -> Modbus TCP -> PLC (grip policy, "
            f"{chain.plc_cycle_s * 1000:g} ms cycle) -> Modbus TCP -> gripper ({a.rate_n_per_s:g} N/s, "
            f"{a.dead_s * 1000:g} ms dead time) -> the object")


def summary_line(r: EpisodeResult) -> str:
    """``glass: held (...)``: the outcome first, then how it got there."""
    how = f"slid {r.slid_mm:.1f} mm in {r.slides} slide{'s' if r.slides != 1 else ''}"
    if r.holding_s > 0:
        how += (f", mean grip {r.mean_grip_n:.2f} N ({100 * r.mean_grip_n / r.fixed_n:.0f} % of the fixed grip's "
                f"{r.fixed_n:.2f} N), peak {r.peak_n:.2f} N")
    how += f", force raised {r.raises} times ({r.needless} needless)"
    if r.fallbacks:
        how += f", {r.fallbacks} fallback raises (no verdict)"
    return f"{r.object}: {r.outcome} ({how})"


def cell_lines(parts: CellParts) -> list[str]:
    """The live view's lines about the cell (read on the redraw thread: plain reads)."""
    g, world = parts.gripper, parts.node.world
    c = world.contact
    what = ("crushed" if c.crushed_at is not None else "dropped" if c.dropped_at is not None
            else "sliding" if c.sliding else "held" if g.holding else "on the table")
    lines = [f"grip {g.force_n:5.2f} N  request {parts.program.request_n:5.2f} N  fixed {parts.fixed_n:.2f} N",
             f"{parts.episode.kind.name}: {what}, slid {c.slid_mm:4.1f} mm (drops at {DROP_MM:g})"]
    if parts.program.no_verdict:
        lines.append("PLC: no verdict, grip at the fallback")
    return lines


def run_objects(objects: tuple[str, ...], seed: int, method: str, chain: ChainSpec,
                profile_for: Callable[[str], Profile], say: Callable[[str], None],
                plc_echo: Callable[[str], None] | None,
                live: Callable[[CellParts], AbstractContextManager[object]] | None = None) -> list[CellRun]:
    """Each object's episode through the real chain, in turn."""
    runs = []
    for name in objects:
        ep = demo_episode(name, seed)
        say(f"{ep.describe()}: {ep.task.describe()}; about {ep.task.end_s:.0f} s")
        runs.append(run_cell(profile_for(ep.kind.profile), ep, method, chain=chain, say=say, plc_echo=plc_echo,
                             live=live))
    return runs
