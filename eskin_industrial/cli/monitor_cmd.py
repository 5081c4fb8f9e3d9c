"""``eskin-bus monitor``: the live view on a sensor node's real CAN traffic."""

from __future__ import annotations

import sys
import time
from contextlib import nullcontext
from typing import Any

import click

from ..methods import method_names
from .can_common import bus_options, nothing_received
from .common import profile_option
from .outputs import kind_options, outputs_from_cli


@click.command()
@profile_option()
@bus_options
@click.option("--rate", "rate_hz", type=float, default=None, help="The node's scan rate in Hz (default: the profile's).")
@click.option("-m", "--method", type=click.Choice(sorted(method_names())), default=None,
              help="Detection method (default: the profile's).")
@click.option("--duration", "duration_s", type=float, default=None, help="Stop after this many seconds.")
@click.option("--idle-exit", "idle_s", type=float, default=None,
              help="Stop once no scan came for this many seconds, counted from the start (none at all: exit 6).")
@click.option("--plain", is_flag=True,
              help="One line per state change instead of the live view (the default when stdout is not a terminal).")
@kind_options("web")
def monitor(profile_path: str, interface: str | None, channel: str | None, bitrate: int | None, fd: bool | None, data_bitrate: int | None, bus_extra: dict[str, Any],
            rate_hz: float | None, method: str | None, duration_s: float | None, idle_s: float | None,
            plain: bool, **output_values: Any) -> None:
    """Watch a sensor node on a CAN bus: its scans decoded and detected, shown live
    (taxel heat map, scores against their thresholds, state, the register image the
    bridge would publish, counters) until Ctrl-C, --duration or --idle-exit; then one
    line of counters.  No PLC is contacted.  With --web HOST:PORT the web console shows
    the node too (docs/web.md)."""
    from ..bridge.config import BridgeConfig, NodeConfig, resolve
    from ..bridge.runtime import SingleNode
    from ..detect.updates import Update
    from ..errors import EskinError
    from ..outputs.plc.kept import KeptRegisters
    from ..outputs.web.sink import web_sinks
    from ..view.live import Watch, change_line, live_screen
    from ..view.snapshot import RegisterTable
    from ..view.terminal import color_wanted

    if rate_hz is not None and not rate_hz > 0:
        raise click.BadParameter(f"expected a positive rate, got {rate_hz}", param_hint="--rate")
    node = NodeConfig.of("node", profile_path, "can", rate_hz=rate_hz, interface=interface, channel=channel,
                         bitrate_bps=bitrate, fd=fd, data_bitrate_bps=data_bitrate, **bus_extra)
    cfg = BridgeConfig(node=(node,), outputs=outputs_from_cli(output_values, ("web",)))
    (resolved,) = resolve(cfg)
    prof = resolved.profile
    chosen = method or prof.detector.method
    sink = KeptRegisters(prof.modbus.plc)
    # a bus that cannot be opened: one line, exit 3
    single = SingleNode(cfg, resolved, extra_sinks=[sink], default_output=False, all_frames=True, method=method)
    loop = single.loop
    for web in web_sinks(loop.sinks):  # the register block as the bridge would publish it
        web.set_registers(sink.table)
    where = loop.source.describe_where() if channel is None else channel
    stdout = sys.stdout
    live = not plain and stdout.isatty()

    def registers() -> RegisterTable | None:
        table = sink.table()
        return None if table is None else RegisterTable(*table)

    watch = Watch(prof, loop.pipeline, method=chosen, snapshot=lambda: loop.snapshot, registers=registers,
                  registers_from="as the bridge would publish them", counters=loop.counters,
                  title="eskin-bus monitor", source=f"{prof.name} | {chosen} | {where}", started=time.monotonic())

    last_state: int | None = None

    def observed(u: Update) -> None:  # on the data path: a comparison per update
        nonlocal last_state
        if u.state != last_state:
            last_state = u.state
            line = change_line(u)
            watch.note(line)
            if not live:
                click.echo(line)

    loop.on_update = observed
    if not live:
        click.echo(f"eskin-bus monitor: {prof.name} on {where}, method {chosen}; Ctrl-C ends", err=True)
    start = time.monotonic()
    interrupted, ended = False, ""
    with single:
        try:
            with live_screen(watch, stdout, color_wanted()) if live else nullcontext():
                ended = loop.run(duration_s=duration_s, idle_timeout_s=idle_s)
        except KeyboardInterrupt:
            interrupted = True
    c = loop.counters()
    click.echo(f"monitor: {time.monotonic() - start:.1f} s{' (interrupted)' if interrupted else ''}, "
               f"scans {c.get('scans', 0)}, lost {c.get('lost_scans', 0)}, torn {c.get('torn_scans', 0)}, "
               f"malformed {c.get('malformed_frames', 0)}, rx queue drops {c.get('rx_queue_drops', 0)}, "
               f"bus errors {c.get('bus_errors', 0)}, state changes {c.get('state_changes', 0)}")
    if single.failure:
        raise EskinError(f"monitor stopped: {single.failure}")
    if ended == "silent" and idle_s is not None:
        raise nothing_received(prof, where, idle_s)
