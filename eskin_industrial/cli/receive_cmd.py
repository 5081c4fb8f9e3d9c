"""``eskin-bus receive``: decode a sensor node's scans from a live CAN bus and detect."""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, Any, cast

import click

from ..seam import DEFAULT_QUEUE_FRAMES, MAX_QUEUE_FRAMES
from .can_common import bus_options, nothing_received
from .common import profile_option
from .console import signals_ask

if TYPE_CHECKING:
    from ..bus.can.source import CanSource


@click.command()
@profile_option()
@bus_options
@click.option("-o", "--output", default=None, type=click.Path(dir_okay=False, allow_dash=True),
              help="Write the detector updates here as they come (CSV, '-' for stdout; .jsonl: JSON lines).")
@click.option("--log", "log_path", default=None, type=click.Path(dir_okay=False),
              help="Record the raw traffic (python-can writer by suffix: .log candump, .blf, .asc, ...).")
@click.option("--can-log", "can_log", default=None, type=click.Path(dir_okay=False), metavar="FILE",
              help="Replay a CAN log (any format python-can reads) at its own pace instead of a bus, as if received: "
                   "no hardware needed (eskin-bus node --can-log writes one).")
@click.option("--rate", "rate_hz", type=float, default=None, help="The node's scan rate in Hz (default: the profile's).")
@click.option("--duration", "duration_s", type=float, default=None, help="Stop after this many seconds.")
@click.option("--idle-exit", "idle_s", type=float, default=None,
              help="Stop once no scan came for this many seconds, counted from the start (none at all: exit 6).")
@click.option("--scans", "max_scans", type=int, default=None, help="Stop after this many scans.")
@click.option("--queue-frames", type=click.IntRange(min=1, max=MAX_QUEUE_FRAMES), default=DEFAULT_QUEUE_FRAMES, show_default=True,
              help="Frames the reader may queue ahead of the detector before dropping.")
@click.option("-q", "--quiet", is_flag=True, help="Nothing on stderr (no start line, no counters).")
def receive(profile_path: str, interface: str | None, channel: str | None, bitrate: int | None, fd: bool | None, data_bitrate: int | None, bus_extra: dict[str, Any],
            output: str | None, log_path: str | None, can_log: str | None, rate_hz: float | None, duration_s: float | None,
            idle_s: float | None, max_scans: int | None, queue_frames: int, quiet: bool) -> None:
    """Receive scans from a CAN bus until stopped (Ctrl-C, --duration, --idle-exit,
    --scans), run the detector, and report the transport counters as JSON on stderr.
    The same source and loop as ``eskin-bus bridge --source can``."""
    from ..bridge.config import BridgeConfig, NodeConfig, check_sources, resolve
    from ..bridge.runtime import SingleNode
    from ..errors import EskinError
    from ..outputs.recorder.kind import RecorderOptions

    if can_log is None:
        node = NodeConfig.of("node", profile_path, "can", rate_hz=rate_hz, interface=interface, channel=channel,
                             bitrate_bps=bitrate, fd=fd, data_bitrate_bps=data_bitrate, log=log_path, **bus_extra)
    elif interface is not None or channel is not None or log_path is not None or bus_extra:
        raise click.UsageError("--can-log replays a log instead of a bus: give it without -i/-c, --log and the "
                               "bus options")
    else:  # the bridge's can-log source: the same assembler, pipeline and counters, paced by the log
        keys: dict[str, Any] = {"path": can_log} | ({"fd": fd} if fd is not None else {})
        node = NodeConfig.of("node", profile_path, "can-log", rate_hz=rate_hz, **keys)
    outputs = {"recorder": RecorderOptions(path=output)} if output is not None else {}
    cfg = BridgeConfig(node=(node,), outputs=outputs, queue_frames=queue_frames)
    (resolved,) = resolve(cfg)
    check_sources(cfg, [resolved])  # --log's folder, --can-log's file: one line, exit 2, before the bus opens
    single = SingleNode(cfg, resolved, default_output=False, all_frames=True)  # a bus that cannot be opened: one line, exit 3 (5: no SocketCAN)
    loop, source = single.loop, cast("CanSource", single.loop.source)  # the node's source is "can" or "can-log"
    ended, where = "", source.describe_where()
    # from the start line on, Ctrl-C or SIGTERM end the run at the end of a step, with
    # the counters: every update counted is written
    with signals_ask(loop.stop), single:
        if not quiet:
            layout = source.assembler.layout
            click.echo(f"eskin-bus: receiving {resolved.profile.name} on {where} "
                       f"({layout.segments} frame{'s' if layout.segments > 1 else ''} per scan)", err=True)
        ended = loop.run(duration_s=duration_s, idle_timeout_s=idle_s, max_scans=max_scans)
        source.end_reception(loop.step)  # what the reader had queued is still recorded and decoded
    if not quiet:
        c = loop.pipeline.counters
        summary = {k: v for k, v in vars(c).items() if k != "extra"} | source.counters()
        if source.assembler.status is not None:
            summary["node_rate_hz"] = source.assembler.status.rate_hz
        click.echo(json.dumps(summary), err=True)
    if single.failure:
        raise EskinError(f"receive stopped: {single.failure}")
    if ended == "silent" and idle_s is not None:
        raise nothing_received(resolved.profile, where, idle_s)
