"""``eskin-bus demo``: the whole chain on the embedded default, nothing to start."""

from __future__ import annotations

import sys
from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING, Any, TextIO, TypeVar

import click
import numpy as np

from ..methods import method_names
from .common import complete_profile, open_profile
from .completion import complete_scene
from .outputs import kind_options, outputs_from_cli

if TYPE_CHECKING:
    from ..profile import Profile
    from ..scenes import Rendered
    from ..sim.cell.realtime import CellParts, CellRun
    from ..sim.cell.virtual import ChainSpec
    from ..sim.demo import DemoResult
    from ..view.terminal import LiveScreen


T = TypeVar("T")


@click.command()
@click.option("--scene", default="hand", show_default=True, shell_complete=complete_scene, help="Scene the node plays (see `simulate --list`).")
@click.option("-p", "--profile", "profile_path", type=click.Path(dir_okay=False), default=None, shell_complete=complete_profile,
              help="Profile: a file or a built-in name (default: the scene's built-in profile).")
@click.option("--rate", "rate_hz", type=click.FloatRange(min=10.0, max=2000.0), default=100.0, show_default=True)
@click.option("--seed", type=int, default=7, show_default=True)
@click.option("--plain", is_flag=True,
              help="One line per state change instead of the live view (the default when stdout is not a terminal).")
@click.option("--plc-log", is_flag=True, help="Also print the PLC stand-in's register changes and gripper actions.")
@click.option("--closed-loop", is_flag=True,
              help="The closed loop instead of a scene: the gripper reacts and the object is held or dropped "
                   "(docs/cell.md).")
@click.option("-m", "--method", type=click.Choice(method_names()), default=None,
              help="The bridge's detection method (default: the profile's; 'none' never reports slip: the fixed "
                   "light grip).")
@click.option("--object", "objects", multiple=True, metavar="NAME",
              help="With --closed-loop: the object (repeatable, one episode each, in turn; default: glass, the "
                   "hand's glass; glass, part, box, egg, cup).")
@click.option("--plc-cycle", "plc_cycle_ms", type=click.IntRange(min=1, max=100), default=10, show_default=True,
              help="With --closed-loop: the PLC's scan cycle (ms).")
@kind_options("web")
def demo(scene: str, profile_path: str | None, rate_hz: float, seed: int, plain: bool, plc_log: bool,
         closed_loop: bool, method: str | None, objects: tuple[str, ...], plc_cycle_ms: int,
         **output_values: object) -> None:
    """Play a scene as a CAN sensor node on python-can's virtual bus, run the bridge
    (decode, detect) and write the registers over Modbus TCP on loopback into a PLC
    stand-in.  In a terminal: a live view (taxel heat map, scores against their
    thresholds, state, the PLC's registers), then the state changes and a summary;
    piped or with --plain: each state change as it comes, then the summary.

    With --closed-loop the node renders what happens in a virtual cell (docs/cell.md):
    the PLC stand-in runs a grip policy and commands a gripper over Modbus TCP, whose
    force decides whether the object sticks or slides; the summary says held,
    dropped or crushed for each object.

    With --web HOST:PORT the web console shows the chain too (docs/web.md)."""
    ctx = click.get_current_context()
    outputs = outputs_from_cli(dict(output_values), ("web",))
    if closed_loop and outputs:
        raise click.UsageError("--web shows a scene's chain; the closed loop has none yet")
    if closed_loop:
        if ctx.get_parameter_source("scene") != click.core.ParameterSource.DEFAULT:
            raise click.UsageError("--scene plays an open-loop scene; with --closed-loop choose --object")
        _closed_loop(objects, profile_path, rate_hz, seed, plain, plc_log, method, plc_cycle_ms / 1000.0)
        return
    if objects or ctx.get_parameter_source("plc_cycle_ms") != click.core.ParameterSource.DEFAULT:
        raise click.UsageError("--object and --plc-cycle belong to the closed loop: give --closed-loop too")
    from ..scenes import render
    from ..sim.demo import run_demo

    rec = render(scene, rate_hz, seed)
    prof = open_profile(profile_path or rec.profile_name)
    if method is not None:
        prof = replace(prof, detector=replace(prof.detector, method=method))
    say = click.echo
    say(f"demo: scene {rec.name} ({rec.spec.scene.description}), {len(rec.t)} scans at {rate_hz:g} Hz on a "
        f"virtual CAN bus -> bridge ({prof.detector.method}) -> Modbus TCP -> PLC stand-in; "
        f"about {rec.t[-1]:.0f} s in real time")
    web_line = f"demo: the web console at {outputs['web'].url}node/0" if "web" in outputs else None
    stdout = sys.stdout
    if plain or not stdout.isatty():
        # the address once the console listens: a script or a browser sent there at once finds it up
        res = run_demo(prof, rec, say, (lambda line: say(f"    PLC {line}")) if plc_log else None, outputs=outputs,
                       ready=(lambda: say(web_line)) if web_line else None)
    else:
        if web_line:
            say(web_line)  # (before the live view takes the screen; the console is up within a second)
        res = _run_live(prof, rec, plc_log, stdout, outputs)
    s, c = res.score, res.counters
    say("summary:")
    if s is not None:
        delays = ", ".join(f"{d * 1000:.0f} ms" for d in s.delays_s) or "-"
        say(f"  slip events {s.events}, found {s.found}, false alarms {s.false_alarms}; detection delay {delays}")
    if res.latencies_s:
        lat = np.asarray(res.latencies_s) * 1000
        say(f"  decision -> acknowledged PLC write: p50 {np.percentile(lat, 50):.2f} ms, "
            f"p99 {np.percentile(lat, 99):.2f} ms over {lat.size} urgent writes")
    say(f"  scans {c.get('scans', 0)}, lost {c.get('lost_scans', 0)}, torn {c.get('torn_scans', 0)}, "
        f"malformed {c.get('malformed_frames', 0)}, rx queue drops {c.get('rx_queue_drops', 0)}; "
        f"PLC status changes {res.plc_status_changes}, grip force raised {res.grip_raises} times")


def _run_live(prof: Profile, rec: Rendered, plc_log: bool, stdout: TextIO, outputs: dict[str, Any]) -> DemoResult:
    """The demo under the live view; the lines it would have printed are kept and
    printed once the view has left the screen."""
    from ..outputs.plc.image import STATUS_COUNT, TAIL_AT, TAIL_COUNT, read_back, status_names
    from ..sim.demo import DemoParts, run_demo
    from ..view.live import Watch, live_screen
    from ..view.snapshot import RegisterTable
    from ..view.terminal import color_wanted

    kept: list[str] = []
    watches: list[Watch] = []

    def say(line: str) -> None:  # the bridge loop: an append or two
        kept.append(line)
        if watches:
            watches[0].note(line)

    def view(parts: DemoParts) -> LiveScreen:
        loop, plc = parts.loop, parts.plc
        word_order = parts.profile.modbus.plc.word_order

        def registers() -> RegisterTable:  # what the PLC stand-in holds, as it reads it
            regs = plc.memory.regs
            values = read_back(regs[:STATUS_COUNT], regs[TAIL_AT:TAIL_AT + TAIL_COUNT], word_order)
            return RegisterTable(values, status_names(values["STATUS"]))

        watch = Watch(parts.profile, loop.pipeline, method=parts.profile.detector.method,
                      snapshot=lambda: loop.snapshot, registers=registers, registers_from="as the PLC reads them",
                      counters=loop.counters, title="eskin-bus demo",
                      source=f"{rec.name} | {parts.profile.name} | {parts.profile.detector.method}",
                      started=parts.started)
        watches.append(watch)
        return live_screen(watch, stdout, color_wanted())

    return _then_echo(kept, lambda: run_demo(prof, rec, say, (lambda line: kept.append(f"    PLC {line}"))
                                             if plc_log else None, live=view, outputs=outputs))


def _closed_loop(objects: tuple[str, ...], profile_path: str | None, rate_hz: float, seed: int, plain: bool,
                 plc_log: bool, method: str | None, plc_cycle_s: float) -> None:
    """``demo --closed-loop``: each object's episode through the real chain."""
    from ..sim.cell.demo import DEFAULT_OBJECTS, chain_line, run_objects, summary_line
    from ..sim.cell.objects import OBJECT
    from ..sim.cell.virtual import ChainSpec

    unknown = [o for o in objects if o not in OBJECT]
    if unknown:
        raise click.BadParameter(f"unknown object {unknown[0]!r}; known: {', '.join(OBJECT)}", param_hint="--object")
    objects = objects or DEFAULT_OBJECTS
    given = open_profile(profile_path) if profile_path else None
    profiles: dict[str, Profile] = {}

    def profile_for(name: str) -> Profile:
        prof = profiles.get(name)
        if prof is None:
            prof = given if given is not None else open_profile(name)
            if prof.taxels != open_profile(name).taxels:
                raise click.BadParameter(f"{prof.name} has {prof.taxels} taxels; the object lies on a {name} array",
                                         param_hint="--profile")
            profiles[name] = prof
        return prof

    chain = ChainSpec(rate_hz=rate_hz, plc_cycle_s=plc_cycle_s)
    chosen = method or profile_for(OBJECT[objects[0]].profile).detector.method
    say = click.echo
    say(f"demo --closed-loop: {', '.join(objects)} (seed {seed}); {chain_line(chosen, chain)}")
    echo = (lambda line: say(f"    PLC {line}")) if plc_log else None
    if plain or not sys.stdout.isatty():
        runs = run_objects(objects, seed, chosen, chain, profile_for, say, echo)
    else:
        runs = _cell_live(objects, seed, chosen, chain, profile_for, plc_log, sys.stdout)
    say("summary:")
    for run in runs:
        c = run.counters
        say(f"  {summary_line(run.result)}")
        say(f"    scans {c.get('scans', 0)}, lost {c.get('lost_scans', 0)}, rx queue drops {c.get('rx_queue_drops', 0)}; "
            f"PLC writes {c.get('plc_writes', 0)}")


def _cell_live(objects: tuple[str, ...], seed: int, method: str, chain: ChainSpec,
               profile_for: Callable[[str], Profile], plc_log: bool, stdout: TextIO) -> list[CellRun]:
    """The closed loop under the live view, with the cell's lines (grip force, distance
    slid); the lines it would have printed are printed once the view has gone."""
    from ..outputs.plc.image import STATUS_COUNT, TAIL_AT, TAIL_COUNT, read_back, status_names
    from ..sim.cell.demo import cell_lines, run_objects
    from ..view.live import Watch, live_screen
    from ..view.snapshot import RegisterTable
    from ..view.terminal import color_wanted

    kept: list[str] = []
    watches: list[Watch] = []

    def say(line: str) -> None:
        kept.append(line)
        if watches:
            watches[-1].note(line)

    def view(parts: CellParts) -> LiveScreen:
        loop, memory = parts.loop, parts.program.memory
        word_order = parts.profile.modbus.plc.word_order

        def registers() -> RegisterTable:  # what the PLC stand-in holds, as its program reads it
            regs = memory.regs
            values = read_back(regs[:STATUS_COUNT], regs[TAIL_AT:TAIL_AT + TAIL_COUNT], word_order)
            return RegisterTable(values, status_names(values["STATUS"]))

        watch = Watch(parts.profile, loop.pipeline, method=method, snapshot=lambda: loop.snapshot,
                      registers=registers, registers_from="as the PLC reads them", counters=loop.counters,
                      title="eskin-bus demo --closed-loop",
                      source=f"{parts.episode.kind.name} | {parts.profile.name} | {method}", started=parts.started,
                      extra=lambda: cell_lines(parts))
        watches.append(watch)
        return live_screen(watch, stdout, color_wanted())

    return _then_echo(kept, lambda: run_objects(objects, seed, method, chain, profile_for, say,
                                                (lambda line: kept.append(f"    PLC {line}")) if plc_log else None,
                                                live=view))


def _then_echo(kept: list[str], run: Callable[[], T]) -> T:
    """``run()``, then the lines it kept (printed once the live view has left the
    screen), also when Ctrl-C ends it (then exit 130)."""
    try:
        out = run()
    except KeyboardInterrupt:  # the view has restored the terminal: say what was seen
        for line in kept:
            click.echo(line)
        click.echo("demo: interrupted", err=True)
        sys.exit(130)
    for line in kept:
        click.echo(line)
    return out
