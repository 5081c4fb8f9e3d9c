"""``eskin-bus receive``: decode a sensor node's scans from a live CAN bus and detect."""

from __future__ import annotations

import json
import sys

import click

from ..detect.updates import UpdateTable
from ..recording import write_updates
from .can_common import bus_options
from .common import open_profile, profile_option


@click.command()
@profile_option()
@bus_options
@click.option("-o", "--output", default=None, type=click.Path(dir_okay=False, allow_dash=True),
              help="Write the detector updates here (CSV, '-' for stdout) when receiving ends.")
@click.option("--log", "log_path", default=None, type=click.Path(dir_okay=False),
              help="Record the raw traffic (python-can writer by suffix: .log candump, .blf, .asc, ...).")
@click.option("--rate", "rate_hz", type=float, default=None, help="The node's scan rate in Hz (default: the profile's).")
@click.option("--duration", "duration_s", type=float, default=None, help="Stop after this many seconds.")
@click.option("--idle-exit", "idle_s", type=float, default=None,
              help="Stop once no frame came for this many seconds (after the first).")
@click.option("--scans", "max_scans", type=int, default=None, help="Stop after this many scans.")
@click.option("--queue-frames", type=int, default=200_000, show_default=True,
              help="Frames the reader may queue ahead of the detector before dropping.")
@click.option("-q", "--quiet", is_flag=True, help="Nothing on stderr (no start line, no counters).")
def receive(profile_path, interface, channel, bitrate, fd, data_bitrate, output, log_path, rate_hz, duration_s,
            idle_s, max_scans, queue_frames, quiet) -> None:
    """Receive scans from a CAN bus until stopped (Ctrl-C, --duration, --idle-exit,
    --scans), run the detector, and report the transport counters as JSON on stderr."""
    import can

    from ..bus.can.layout import CanLayout, ScanAssembler
    from ..bus.can.reader import READER_SWITCH_INTERVAL_S, BusReader, CanSource, bus_kwargs, open_bus
    from ..pipeline import Pipeline

    sys.setswitchinterval(READER_SWITCH_INTERVAL_S)
    prof = open_profile(profile_path)
    kw = bus_kwargs(prof, interface, channel, bitrate, fd, data_bitrate)
    layout = CanLayout.from_profile(prof, fd=kw["fd"])
    rate = rate_hz or prof.sensor.rate_hz
    pipeline = Pipeline(prof, rate_hz=rate)
    reader = BusReader(lambda: open_bus(**kw), queue_frames=queue_frames)
    log = can.Logger(log_path) if log_path else None
    source = CanSource(reader.start(), ScanAssembler(layout, rate), pipeline, log, keep_updates=output is not None)
    if not quiet:
        bus = reader.bus
        click.echo(f"eskin-bus: receiving {prof.name} on {getattr(bus, 'channel_info', '?')} "
                   f"({layout.segments} frame{'s' if layout.segments > 1 else ''} per scan)", err=True)
    try:
        source.run(duration_s=duration_s, idle_timeout_s=idle_s, max_scans=max_scans)
    finally:
        if log is not None:
            log.stop()
    if output is not None:
        write_updates(output, UpdateTable.from_updates(source.updates))
    if not quiet:
        c = pipeline.counters
        summary = {k: v for k, v in vars(c).items() if k != "extra"} | source.counters()
        if source.assembler.status is not None:
            summary["node_rate_hz"] = source.assembler.status.rate_hz
        click.echo(json.dumps(summary), err=True)
