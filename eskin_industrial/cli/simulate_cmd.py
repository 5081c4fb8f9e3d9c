"""``eskin-bus simulate``: render a scene to a recording CSV and a labels CSV."""

from __future__ import annotations

import click

from ..recording import write_recording
from ..scenes import Rendered, list_scenes, render
from .common import check_output, complete_profile, open_profile, writing
from .completion import complete_scene
from .console import PROGRESS_DELAY_S, Ticker


@click.command()
@click.argument("scene", required=False, shell_complete=complete_scene)
@click.option("-o", "--output", default=None, type=click.Path(dir_okay=False, allow_dash=True),
              help="Recording CSV (t,f0,...) in newtons ('-' for stdout, the default without --can-log).")
@click.option("--labels", "labels_path", type=click.Path(dir_okay=False), default=None,
              help="Also write the ground truth, one row per frame: t,label.")
@click.option("--rate", "rate_hz", type=click.FloatRange(min=1.0, max=100_000.0), default=100.0, show_default=True)
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--raw", "raw_profile", type=click.Path(dir_okay=False), default=None, metavar="PROFILE",
              help="Write the node's raw unit (t,raw0,...) through this profile's calibration instead of newtons.")
@click.option("--can-log", "can_log", default=None, type=click.Path(dir_okay=False, allow_dash=True), metavar="FILE",
              help="Write the scene as the profile's CAN node sends it (-p) to a CAN log, stamped from 0 at the scene's "
                   "rate (python-can's writer by suffix: .asc, .blf, .csv, .log candump, .trc; '-': candump -L on stdout).")
@click.option("-p", "--profile", "profile_path", type=click.Path(dir_okay=False), default=None, shell_complete=complete_profile,
              help="With --can-log: the node's profile (default: the scene's own, e.g. paper-5x5).")
@click.option("--list", "list_only", is_flag=True, help="List the built-in scenes and exit.")
def simulate(scene: str | None, output: str | None, labels_path: str | None, rate_hz: float, seed: int,
             raw_profile: str | None, can_log: str | None, profile_path: str | None, list_only: bool) -> None:
    """Render SCENE (a built-in name or a scene .toml file) at any rate with a seed: a
    recording CSV, and with --can-log the CAN log its node would give (no bus needed:
    detect --can-log reads it)."""
    if list_only:
        for name, description in list_scenes().items():
            click.echo(f"{name:12s} {description}")
        return
    if scene is None:
        raise click.UsageError("give a SCENE (see --list)")
    if profile_path is not None and can_log is None:
        raise click.UsageError("-p/--profile is the CAN node's profile: give it with --can-log")
    if can_log == "-" and output == "-":
        raise click.UsageError("--can-log - and -o - both write to stdout: give one of them a file")
    if can_log is not None:
        from ..bus.can.logbus import check_log_path

        try:
            check_log_path(can_log)
        except ValueError as exc:
            raise click.BadParameter(str(exc), param_hint="--can-log") from None
    if output is None:
        output = "-" if can_log is None else None
    check_output(output, "-o")  # before the scene is rendered
    check_output(labels_path, "--labels")
    with Ticker(delay_s=PROGRESS_DELAY_S, stdout_data="-" in (output, can_log)) as ticker:
        rec = render(scene, rate_hz, seed)
        if can_log is not None:
            _can_log(rec, can_log, profile_path or rec.profile_name, rate_hz, seed)
        if output is not None:
            _simulate(rec, output, raw_profile, ticker)
    if labels_path is not None:
        with writing(labels_path, "--labels"), open(labels_path, "w", encoding="utf-8") as f:
            f.write("t,label\n")
            f.writelines(f"{t:.6f},{label}\n" for t, label in zip(rec.t.tolist(), rec.labels.tolist()))


def _can_log(rec: Rendered, path: str, profile_path: str, rate_hz: float, seed: int) -> None:
    """The scene's scans as the profile's node sends them, written to a CAN log: the
    node simulator's frames and heartbeat, the scene's time from 0."""
    from ..bus.can.layout import CanLayout
    from ..calibration import Calibrator
    from ..sim.can_node import CanNode, Faults
    from .can_common import log_bus

    prof = open_profile(profile_path)
    if prof.taxels != rec.forces.shape[1]:
        raise click.UsageError(f"scene {rec.name} has {rec.forces.shape[1]} taxels, profile {prof.name} has {prof.taxels}")
    raw = Calibrator.from_section(prof.calibration, prof.taxels).to_raw(rec.forces)
    bus = log_bus(path)
    try:
        CanNode(CanLayout.from_profile(prof), bus, raw, rate_hz, prof.can.heartbeat_s, Faults(seed=seed), burst=True,
                t0=0.0).run()
    finally:
        bus.shutdown()


def _simulate(rec: Rendered, output: str, raw_profile: str | None, ticker: Ticker) -> None:
    if raw_profile is not None:
        from ..calibration import Calibrator

        prof = open_profile(raw_profile)
        if prof.taxels != rec.forces.shape[1]:
            raise click.UsageError(f"scene {rec.name} has {rec.forces.shape[1]} taxels, profile {prof.name} has {prof.taxels}")
        raw = Calibrator.from_section(prof.calibration, prof.taxels).to_raw(rec.forces)
        with writing(output, "-o"):
            write_recording(output, rec.t, raw.round(), unit="raw", progress=ticker)
    else:
        with writing(output, "-o"):
            write_recording(output, rec.t, rec.forces, progress=ticker)
