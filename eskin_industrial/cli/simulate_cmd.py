"""``eskin-bus simulate``: render a scene to a recording CSV and a labels CSV."""

from __future__ import annotations

import click

from ..recording import write_recording
from ..scenes import list_scenes, render
from .common import open_profile
from .console import PROGRESS_DELAY_S, Ticker


@click.command()
@click.argument("scene", required=False)
@click.option("-o", "--output", default="-", type=click.Path(dir_okay=False, allow_dash=True), show_default=True,
              help="Recording CSV (t,f0,...) in newtons ('-' for stdout).")
@click.option("--labels", "labels_path", type=click.Path(dir_okay=False), default=None,
              help="Also write the ground truth, one row per frame: t,label.")
@click.option("--rate", "rate_hz", type=click.FloatRange(min=1.0, max=100_000.0), default=100.0, show_default=True)
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--raw", "raw_profile", type=click.Path(dir_okay=False), default=None, metavar="PROFILE",
              help="Write the node's raw unit (t,raw0,...) through this profile's calibration instead of newtons.")
@click.option("--list", "list_only", is_flag=True, help="List the built-in scenes and exit.")
def simulate(scene: str | None, output: str, labels_path: str | None, rate_hz: float, seed: int,
             raw_profile: str | None, list_only: bool) -> None:
    """Render SCENE (a built-in name or a scene .toml file) at any rate with a seed."""
    if list_only:
        for name, description in list_scenes().items():
            click.echo(f"{name:12s} {description}")
        return
    if scene is None:
        raise click.UsageError("give a SCENE (see --list)")
    with Ticker(delay_s=PROGRESS_DELAY_S, stdout_data=output == "-") as ticker:
        _simulate(scene, output, labels_path, rate_hz, seed, raw_profile, ticker)


def _simulate(scene: str, output: str, labels_path: str | None, rate_hz: float, seed: int, raw_profile: str | None,
              ticker: Ticker) -> None:
    rec = render(scene, rate_hz, seed)
    if raw_profile is not None:
        from ..calibration import Calibrator

        prof = open_profile(raw_profile)
        if prof.taxels != rec.forces.shape[1]:
            raise click.UsageError(f"scene {rec.name} has {rec.forces.shape[1]} taxels, profile {prof.name} has {prof.taxels}")
        raw = Calibrator.from_section(prof.calibration, prof.taxels).to_raw(rec.forces)
        write_recording(output, rec.t, raw.round(), unit="raw", progress=ticker)
    else:
        write_recording(output, rec.t, rec.forces, progress=ticker)
    if labels_path is not None:
        with open(labels_path, "w", encoding="utf-8") as f:
            f.write("t,label\n")
            f.writelines(f"{t:.6f},{label}\n" for t, label in zip(rec.t.tolist(), rec.labels.tolist()))
