"""``eskin-bus node``: play a scene or a recording onto a CAN bus as a sensor node would."""

from __future__ import annotations

import json
import time
from typing import TYPE_CHECKING, Any

import click

if TYPE_CHECKING:
    import can

from .can_common import bus_options, log_bus
from .common import open_profile, profile_option, scene_or_recording
from .completion import complete_scene


@click.command()
@profile_option()
@bus_options
@click.option("--scene", default=None, shell_complete=complete_scene, help="Scene to send (from the scene simulator).")
@click.option("--recording", "recording", type=click.Path(dir_okay=False), default=None,
              help="Recording CSV to send instead (t,f0,... newtons or t,raw0,... raw).")
@click.option("--rate", "rate_hz", type=float, default=None,
              help="Scan rate in Hz (default: the recording's, or the profile's for a scene).")
@click.option("--burst", is_flag=True, help="Send as fast as the bus takes frames (no pacing).")
@click.option("--repeat", type=int, default=1, show_default=True, help="Send the scans this many times.")
@click.option("--duration", "duration_s", type=float, default=None,
              help="Send for this long (node time, seconds), repeating the scans as needed.")
@click.option("--seed", type=int, default=0, show_default=True, help="Seed for scenes and fault injection.")
@click.option("--drop", type=float, default=0.0, help="Fault: probability that a frame is not sent.")
@click.option("--duplicate", type=float, default=0.0, help="Fault: probability that a frame is sent twice.")
@click.option("--reorder", type=float, default=0.0, help="Fault: probability that a frame is held behind the next.")
@click.option("--corrupt", type=float, default=0.0, help="Fault: probability that a frame is sent one byte short.")
@click.option("--silent-at", "silent_at_s", type=float, default=None, help="Fault: fall silent at this node time (s)...")
@click.option("--silent-for", "silent_for_s", type=float, default=0.0, help="...for this long (s).")
@click.option("--modbus-rtu", "modbus_rtu", default=None, metavar="PORT",
              help="Be a Modbus RTU node on this serial port instead of a CAN node (the profile's [modbus.node] map).")
@click.option("--can-log", "can_log", default=None, type=click.Path(dir_okay=False, allow_dash=True), metavar="FILE",
              help="Write the frames to a CAN log instead of a bus (python-can's writer by suffix: .asc, .blf, .csv, "
                   ".log candump, .trc), unpaced, stamped with the node's clock; '-': candump -L lines on stdout, "
                   "paced (unless --burst).")
@click.option("--baud", "baudrate", type=int, default=None, help="With --modbus-rtu: baud rate (default: the profile's).")
@click.option("-q", "--quiet", is_flag=True, help="No summary on stderr.")
def node(profile_path: str, interface: str | None, channel: str | None, bitrate: int | None, fd: bool | None, data_bitrate: int | None, bus_extra: dict[str, Any],
         scene: str | None, recording: str | None, rate_hz: float | None, burst: bool, repeat: int,
         duration_s: float | None, seed: int, drop: float, duplicate: float, reorder: float, corrupt: float,
         silent_at_s: float | None, silent_for_s: float, modbus_rtu: str | None, can_log: str | None,
         baudrate: int | None, quiet: bool) -> None:
    """Send scans as the profile's sensor node: one scan every 1/rate seconds (absolute
    deadlines, no drift), with the node's heartbeat and optional faults; or, with
    --modbus-rtu PORT, serve them as a Modbus RTU slave (the scene loops until
    --duration or Ctrl-C); or, with --can-log FILE, write the frames to a CAN log
    (no hardware, no vcan: detect --can-log reads it)."""
    from ..bus.can.layout import CanLayout
    from ..bus.can.logbus import check_log_path
    from ..bus.can.reader import bus_kwargs, open_bus
    from ..sim.can_node import CanNode, Faults

    if can_log is not None:
        if modbus_rtu is not None or interface is not None or channel is not None:
            raise click.UsageError("--can-log writes a log instead of a bus: give it without -i/-c and --modbus-rtu")
        try:
            check_log_path(can_log)
        except ValueError as exc:
            raise click.BadParameter(str(exc), param_hint="--can-log") from None
    prof = open_profile(profile_path)
    if modbus_rtu is not None:
        from .modbus_cmd import run_rtu_node

        run_rtu_node(prof, modbus_rtu, scene, recording, rate_hz, baudrate, seed, False, duration_s)
        return
    for name, p in (("--drop", drop), ("--duplicate", duplicate), ("--reorder", reorder), ("--corrupt", corrupt)):
        if not 0.0 <= p <= 1.0:
            raise click.BadParameter(f"expected a probability in [0, 1], got {p}", param_hint=name)
    scans = scene_or_recording(prof, scene, recording, rate_hz, seed)
    rate, raw = scans.rate_hz, scans.raw_values(prof)
    kw = bus_kwargs(prof, interface, channel, bitrate, fd, data_bitrate, timing=bus_extra.get("timing"),
                    filters=bus_extra.get("filter", ()), extra=bus_extra.get("bus_kwargs"))
    layout = CanLayout.from_profile(prof, fd=kw["fd"])
    faults = Faults(drop, duplicate, reorder, corrupt, silent_at_s, silent_for_s, seed)
    bus: can.BusABC
    if can_log is not None:
        bus = log_bus(can_log)
        burst = burst or can_log != "-"  # a file is written at once; stdout is paced for a live reader
    else:
        bus = open_bus(**kw)
    try:
        sim = CanNode(layout, bus, raw, rate, prof.can.heartbeat_s, faults, burst, repeat, duration_s)
        start = time.monotonic()
        try:
            stats = sim.run()
        except KeyboardInterrupt:  # Ctrl-C or SIGTERM: a stop as asked, the summary of what was sent
            stats = sim.stats
            stats.elapsed_s = time.monotonic() - start
    finally:
        bus.shutdown()
    if not quiet:
        fps = stats.frames_sent / stats.elapsed_s if stats.elapsed_s > 0 else float("nan")
        click.echo(f"node: {stats.scans} scans, {stats.frames_sent} frames in {stats.elapsed_s:.3f} s "
                   f"({fps:.0f} frames/s); " + json.dumps({k: v for k, v in vars(stats).items()
                                                          if k not in ("scans", "frames_sent", "elapsed_s")}),
                   err=True)
