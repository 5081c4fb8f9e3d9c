"""``eskin-bus demo``: the whole chain on the embedded default, nothing to start."""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING, TextIO

import click
import numpy as np

from .common import open_profile

if TYPE_CHECKING:
    from ..profile import Profile
    from ..scenes import Rendered
    from ..sim.demo import DemoResult
    from ..view.terminal import LiveScreen


@click.command()
@click.option("--scene", default="hand", show_default=True, help="Scene the node plays (see `simulate --list`).")
@click.option("-p", "--profile", "profile_path", type=click.Path(dir_okay=False), default=None,
              help="Profile: a file or a built-in name (default: the scene's built-in profile).")
@click.option("--rate", "rate_hz", type=click.FloatRange(min=10.0, max=2000.0), default=100.0, show_default=True)
@click.option("--seed", type=int, default=7, show_default=True)
@click.option("--plain", is_flag=True,
              help="One line per state change instead of the live view (the default when stdout is not a terminal).")
@click.option("--plc-log", is_flag=True, help="Also print the PLC stand-in's register changes and gripper actions.")
def demo(scene: str, profile_path: str | None, rate_hz: float, seed: int, plain: bool, plc_log: bool) -> None:
    """Play a scene as a CAN sensor node on python-can's virtual bus, run the bridge
    (decode, detect) and write the registers over Modbus TCP on loopback into a PLC
    stand-in.  In a terminal: a live view (taxel heat map, scores against their
    thresholds, state, the PLC's registers), then the state changes and a summary;
    piped or with --plain: each state change as it comes, then the summary."""
    from ..scenes import render
    from ..sim.demo import run_demo

    rec = render(scene, rate_hz, seed)
    prof = open_profile(profile_path or rec.profile_name)
    say = click.echo
    say(f"demo: scene {rec.name} ({rec.spec.scene.description}), {len(rec.t)} scans at {rate_hz:g} Hz on a "
        f"virtual CAN bus -> bridge ({prof.detector.method}) -> Modbus TCP -> PLC stand-in; "
        f"about {rec.t[-1]:.0f} s in real time")
    stdout = sys.stdout
    if plain or not stdout.isatty():
        res = run_demo(prof, rec, say, (lambda line: say(f"    PLC {line}")) if plc_log else None)
    else:
        res = _run_live(prof, rec, plc_log, stdout)
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


def _run_live(prof: Profile, rec: Rendered, plc_log: bool, stdout: TextIO) -> DemoResult:
    """The demo under the live view; the lines it would have printed are kept and
    printed once the view has left the screen."""
    from ..plc.image import STATUS_COUNT, TAIL_AT, TAIL_COUNT, read_back, status_names
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

    try:
        res = run_demo(prof, rec, say, (lambda line: kept.append(f"    PLC {line}")) if plc_log else None,
                       live=view)
    except KeyboardInterrupt:  # the view has restored the terminal: say what was seen
        for line in kept:
            click.echo(line)
        click.echo("demo: interrupted", err=True)
        sys.exit(130)
    for line in kept:
        click.echo(line)
    return res
