"""``eskin-bus bridge``: sensor nodes -> detector -> outputs (the PLC's register
blocks, a recorder, ...), for months.

One node from the command line (``--profile``, ``--source``, the outputs' options),
or several from a configuration file (``--config``).  The source kinds and the output
kinds, and their options, come from their registries.  Every signal but KILL either
stops it cleanly (every output left reading BRIDGE_OFFLINE) or has a use (USR1: the
counters): bridge/signals.py, and the table in docs/operations.md.
"""

from __future__ import annotations

import sys
import warnings
from typing import TYPE_CHECKING, Any, Literal, cast

import click

from ..errors import DeprecatedKey

if TYPE_CHECKING:
    from ..bridge.config import NodeConfig
    from ..bridge.runtime import Bridge
from .can_common import bus_options
from .common import complete_profile
from .completion import complete_source
from .console import verbosity
from .extras import check_extras
from .outputs import given_output_options, node_outputs_from_cli, output_options, outputs_from_cli


def node_from_options(profile_path: str, source: str, bus: dict[str, Any], outputs: dict[str, Any],
                      rate_hz: float | None, name: str) -> NodeConfig:
    """One ``[[node]]`` from ``--source KIND:WHERE`` and python-can's bus options."""
    from ..bridge.config import NodeConfig
    from ..bus.source import source_class, source_kinds
    from ..errors import ProfileError

    kind, _, where = source.partition(":")
    where = where[2:] if where.startswith("//") else where
    try:
        cls = source_class(kind)
    except ProfileError as exc:
        specs = ", ".join(source_class(k).spec for k in source_kinds())
        raise click.BadParameter(f"{exc}; expected {specs}", param_hint="--source") from None
    try:
        keys = cls.options_from_spec(where, bus)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--source") from None
    return NodeConfig.of(name, profile_path, cls.kind, rate_hz=rate_hz, outputs=outputs, **keys)


@click.command()
@click.option("--config", "config_path", type=click.Path(dir_okay=False), default=None,
              help="Bridge configuration (TOML): several nodes, each to its own register block.")
@click.option("-p", "--profile", "profile_path", type=click.Path(dir_okay=False), default=None, shell_complete=complete_profile,
              help="One node: its sensor profile (instead of --config).")
@click.option("--source", default="can", show_default=True, metavar="SPEC", shell_complete=complete_source,
              help="One node's scans: can (python-can bus, -i/-c), log:FILE (replay a CAN log), "
                   "rtu:PORT[@BAUD] (poll a Modbus RTU node), scene:NAME (a built-in scene in real time), "
                   "recording:FILE.csv.")
@bus_options
@output_options
@click.option("--rate", "rate_hz", type=click.FloatRange(min=0.1), default=None,
              help="One node: scan rate in Hz (default: the profile's).")
@click.option("--name", default="node", show_default=True, help="One node: its name in logs.")
@click.option("--log-format", type=click.Choice(["plain", "json"]), default=None,
              help="Log lines (stderr): plain key=value or JSON (default: the configuration's, plain).")
@click.option("--log-level", type=click.Choice(["debug", "info", "warning", "error"]), default=None)
@click.option("--status-every", type=click.FloatRange(min=0.0), default=None,
              help="Log every counter every N seconds (default 60; 0: only at the end).")
@click.option("--duration", "duration_s", type=click.FloatRange(min=0.0), default=None,
              help="Stop after this many seconds (default: until SIGTERM, SIGINT or SIGHUP).")
@click.option("--check", is_flag=True, help="Validate the configuration and profiles, print the plan, exit.")
@click.option("--explain", is_flag=True,
              help="With --check: also every node's resolved settings and where each came from.")
def bridge(config_path: str | None, profile_path: str | None, source: str, interface: str | None, channel: str | None, bitrate: int | None, fd: bool | None, data_bitrate: int | None, bus_extra: dict[str, Any],
           rate_hz: float | None, name: str, log_format: str | None, log_level: str | None, status_every: float | None,
           duration_s: float | None, check: bool, explain: bool, **output_values: Any) -> None:
    """Run the bridge: decode each node's scans, detect, and keep the outputs (by
    default the PLC's register blocks) up to date, until SIGTERM, SIGINT, SIGHUP or
    SIGQUIT (then every block reads BRIDGE_OFFLINE; SIGUSR1 logs the counters).  With no output given, the PLC as the profile
    describes it; --plc keeps it beside another output."""
    from dataclasses import replace

    from ..bridge.config import BridgeConfig, check_sources, load_bridge_config, output_classes, probe_outputs, resolve
    from ..bridge.config import explain as explain_node
    from ..bridge.logs import EventLog
    from ..bridge.notify import Notifier
    from ..bridge.runtime import Bridge
    from ..bridge.signals import EXIT_FAILED, handled_signals
    from ..modbus.pymodbus_io import quiet_pymodbus

    if (config_path is None) == (profile_path is None):
        raise click.UsageError("give --config FILE, or --profile P for one node")
    bus = dict(interface=interface, channel=channel, bitrate_bps=bitrate, fd=fd, data_bitrate_bps=data_bitrate,
               **bus_extra)
    if config_path is not None:
        given = [opt for opt, value in (("--source", source != "can"), ("-i", interface), ("-c", channel),
                                        ("-b", bitrate), ("--fd", fd is not None), ("--data-bitrate", data_bitrate),
                                        ("--rate", rate_hz), ("--name", name != "node")) if value]
        given += given_output_options(output_values)
        if given:  # never silently ignored: the file says it all
            raise click.UsageError(f"{', '.join(given)}: one-node options; with --config the file gives them")
        with warnings.catch_warnings(record=True) as moved:  # logged once the log is there (below)
            warnings.simplefilter("always", DeprecatedKey)
            cfg = load_bridge_config(config_path)
    else:
        assert profile_path is not None  # one of the two, checked above
        moved = []
        node = node_from_options(profile_path, source, bus, node_outputs_from_cli(output_values), rate_hz, name)
        cfg = BridgeConfig(node=(node,), outputs=outputs_from_cli(output_values))
    log_level = log_level or {-1: "warning", 1: "debug", 2: "debug"}.get(verbosity())  # -q / -v
    logs = cfg.log
    if log_format is not None:
        logs = replace(logs, format=cast(Literal["plain", "json"], log_format))
    if log_level is not None:
        logs = replace(logs, level=cast(Literal["debug", "info", "warning", "error"], log_level))
    if status_every is not None:
        logs = replace(logs, status_every_s=status_every)
    cfg = replace(cfg, log=logs)
    with warnings.catch_warnings(record=True) as moved_in_profiles:
        warnings.simplefilter("always", DeprecatedKey)
        nodes = resolve(cfg)  # every profile loads and the nodes fit together, or one line and exit 2
    # once each (two nodes on one profile load it twice)
    deprecated = list(dict.fromkeys(str(w.message) for w in (*moved, *moved_in_profiles)
                                    if issubclass(w.category, DeprecatedKey)))
    check_sources(cfg, nodes)  # files and scenes the sources need exist
    if check:
        for line in deprecated:
            click.echo(f"eskin-bus: warning: {line}", err=True)
        # an output or method whose extra is not installed (exit 4, as the run would)
        check_extras([*(("output", kind) for kind in cfg.output_kinds()),
                      *(("method", n.profile.detector.method) for n in nodes)])
        probe_outputs(cfg, nodes)  # a server's port is free (the run would fail to listen)
        outputs = output_classes(cfg)
        for n in nodes:
            where = ", ".join(cls.describe(options, n) for cls, options in outputs)
            click.echo(f"{n.name}: {n.profile.name} ({n.profile.source}), {n.rate_hz:g} Hz, "
                       f"{n.kind.describe(n)} -> {where}")
            if explain:
                for key, value, origin in explain_node(cfg, n):
                    click.echo(f"  {key} = {value!r}  ({origin})")
        return
    if explain:
        raise click.UsageError("--explain goes with --check")
    quiet_pymodbus()
    log = EventLog(sys.stderr, logs.format, logs.level)
    for line in deprecated:  # in the log's own format: a JSON log stays JSON
        log.event("deprecated_key", level="warning", message=line)
    br = Bridge(cfg, nodes, log, notifier=Notifier.from_env())
    # From here on, no signal but KILL ends the process without the offline image
    # (a signal during open stops the bridge as soon as it has started).
    with handled_signals() as flags:
        try:
            br.open()
        except BaseException:
            log.close()
            raise
        _registers_to_the_console(br)
        try:
            if not flags.reason:  # a signal during open: straight to the offline image
                br.start()
            br.wait(duration_s, signals=flags)
        finally:  # an unexpected error too: every block offline, the deaths sent
            br.stop()
            br.log_counters("final")
            log.close()
    failure = br.failure or (f"{flags.reason} (systemd's watchdog signal: a loop hung)" if flags.failing else "")
    if failure:
        _say(f"eskin-bus: error: bridge stopped: {failure}")
        sys.exit(EXIT_FAILED)


def _registers_to_the_console(bridge: Bridge) -> None:
    """The web console's register block: each node's served PLC block, read as the PLC
    reads it (server mode; a client-mode PLC's writes are the writer's own)."""
    from ..outputs.plc.kept import served_table
    from ..outputs.web.sink import web_sinks

    for run in bridge.runs:
        webs = web_sinks(run.sinks)
        tables = [t for t in (served_table(getattr(s, "inner", s)) for s in run.sinks) if t is not None]
        for web in webs:
            if tables:
                web.set_registers(tables[0])


def _say(line: str) -> None:
    """A last line on stderr, which may be gone (a closed terminal, a dead pipe)."""
    try:
        click.echo(line, err=True)
    except OSError:
        pass
