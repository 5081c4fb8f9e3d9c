"""``eskin-bus bridge``: sensor nodes -> detector -> PLC register blocks, for months.

One node from the command line (``--profile``, ``--source``, ``--plc``), or several
from a configuration file (``--config``).  SIGTERM and SIGINT stop it cleanly: every
block is left reading BRIDGE_OFFLINE.
"""

from __future__ import annotations

import signal
import sys

import click

from .can_common import bus_options
from .common import host_port


def _split(spec: str, what: str) -> tuple[str, str]:
    kind, sep, rest = spec.partition(":")
    rest = rest[2:] if rest.startswith("//") else rest  # tcp://host:port reads as tcp:host:port
    if not sep and kind not in ("can",):
        raise click.BadParameter(f"expected KIND:WHERE, got {spec!r}", param_hint=what)
    return kind, rest


def node_from_options(profile_path: str, source: str, interface, channel, bitrate, fd, data_bitrate,
                      base_address: int | None, rate_hz: float | None, name: str):
    from ..bridge.config import NodeConfig

    kind, where = _split(source, "--source")
    common = dict(name=name, profile=profile_path, base_address=base_address, rate_hz=rate_hz)
    if kind == "can":
        return NodeConfig(source="can", interface=interface, channel=channel, bitrate_bps=bitrate, fd=fd,
                          data_bitrate_bps=data_bitrate, **common)
    if kind in ("log", "can-log"):
        return NodeConfig(source="can-log", path=where, fd=fd, **common)
    if kind in ("rtu", "modbus-rtu"):
        port, _, baud = where.partition("@")
        if baud and not baud.isdigit():
            raise click.BadParameter(f"expected rtu:PORT[@BAUD], got {source!r}", param_hint="--source")
        return NodeConfig(source="modbus-rtu", serial_port=port, baudrate=int(baud) if baud else None, **common)
    if kind == "scene":
        return NodeConfig(source="scene", scene=where, **common)
    raise click.BadParameter(f"unknown source kind {kind!r}; expected can, log:FILE, rtu:PORT[@BAUD] or "
                             f"scene:NAME", param_hint="--source")


def plc_from_option(spec: str | None, baud: int):
    from ..bridge.config import PlcOutput

    if spec is None:
        return PlcOutput()
    kind, where = _split(spec, "--plc")
    if kind == "tcp":
        host, port = host_port(where, "--plc")
        return PlcOutput(mode="client", host=host, port=port)
    if kind == "rtu":
        return PlcOutput(mode="client", transport="rtu", serial_port=where, baudrate=baud)
    if kind == "serve":
        host, port = host_port(where, "--plc")
        return PlcOutput(mode="server", host=host, port=port)
    if kind == "serve-rtu":
        return PlcOutput(mode="server", transport="rtu", serial_port=where, baudrate=baud)
    raise click.BadParameter(f"unknown PLC kind {kind!r}; expected tcp:HOST:PORT, rtu:PORT, serve:HOST:PORT or "
                             f"serve-rtu:PORT", param_hint="--plc")


@click.command()
@click.option("--config", "config_path", type=click.Path(dir_okay=False), default=None,
              help="Bridge configuration (TOML): several nodes, each to its own register block.")
@click.option("-p", "--profile", "profile_path", type=click.Path(dir_okay=False), default=None,
              help="One node: its sensor profile (instead of --config).")
@click.option("--source", default="can", show_default=True, metavar="SPEC",
              help="One node's scans: can (python-can bus, -i/-c), log:FILE (replay a CAN log), "
                   "rtu:PORT[@BAUD] (poll a Modbus RTU node), scene:NAME (a built-in scene in real time).")
@bus_options
@click.option("--plc", "plc_spec", default=None, metavar="SPEC",
              help="tcp:HOST:PORT (write into the PLC), rtu:PORT (PLC as RTU slave), serve:HOST:PORT "
                   "(serve, the PLC reads), serve-rtu:PORT; default: the profile's [modbus.plc].")
@click.option("--plc-baud", type=int, default=115200, show_default=True, help="Baud rate for rtu: and serve-rtu:.")
@click.option("--base-address", type=click.IntRange(0, 65000), default=None,
              help="One node: its register block (default: the profile's).")
@click.option("--rate", "rate_hz", type=click.FloatRange(min=0.1), default=None,
              help="One node: scan rate in Hz (default: the profile's).")
@click.option("--name", default="node", show_default=True, help="One node: its name in logs.")
@click.option("--log-format", type=click.Choice(["plain", "json"]), default=None,
              help="Log lines (stderr): plain key=value or JSON (default: the configuration's, plain).")
@click.option("--log-level", type=click.Choice(["debug", "info", "warning", "error"]), default=None)
@click.option("--status-every", type=click.FloatRange(min=0.0), default=None,
              help="Log every counter every N seconds (default 60; 0: only at the end).")
@click.option("--duration", "duration_s", type=click.FloatRange(min=0.0), default=None,
              help="Stop after this many seconds (default: until SIGTERM/SIGINT).")
@click.option("--check", is_flag=True, help="Validate the configuration and profiles, print the plan, exit.")
def bridge(config_path, profile_path, source, interface, channel, bitrate, fd, data_bitrate, plc_spec, plc_baud,
           base_address, rate_hz, name, log_format, log_level, status_every, duration_s, check) -> None:
    """Run the bridge: decode each node's scans, detect, and keep the PLC's register
    blocks up to date, until SIGTERM or SIGINT (then every block reads BRIDGE_OFFLINE)."""
    from dataclasses import replace

    from ..bridge.config import BridgeConfig, load_bridge_config, plc_mode, resolve
    from ..bridge.logs import EventLog
    from ..bridge.runtime import Bridge
    from ..bus.can.layout import ID_RANGE
    from ..bus.modbus.io import quiet_pymodbus

    if (config_path is None) == (profile_path is None):
        raise click.UsageError("give --config FILE, or --profile P for one node")
    if config_path is not None:
        given = [opt for opt, value in (("--source", source != "can"), ("-i", interface), ("-c", channel),
                                        ("-b", bitrate), ("--fd", fd is not None), ("--data-bitrate", data_bitrate),
                                        ("--plc", plc_spec), ("--base-address", base_address is not None),
                                        ("--rate", rate_hz), ("--name", name != "node")) if value]
        if given:  # never silently ignored: the file says it all
            raise click.UsageError(f"{', '.join(given)}: one-node options; with --config the file gives them")
        cfg = load_bridge_config(config_path)
    else:
        node = node_from_options(profile_path, source, interface, channel, bitrate, fd, data_bitrate, base_address,
                                 rate_hz, name)
        cfg = BridgeConfig(node=(node,), plc=plc_from_option(plc_spec, plc_baud))
    logs = replace(cfg.log, **{k: v for k, v in (("format", log_format), ("level", log_level),
                                                   ("status_every_s", status_every)) if v is not None})
    cfg = replace(cfg, log=logs)
    object.__setattr__(cfg, "source", config_path or "<command line>")
    nodes = resolve(cfg)  # every profile loads and the nodes fit together, or one line and exit 2
    if check:
        mode = plc_mode(cfg, nodes)
        for n in nodes:
            c = n.config
            src = {"can": f"can {c.interface or '(configured)'} {c.channel or ''} ids {n.profile.can.base_id:#x}+{ID_RANGE}",
                   "can-log": f"log {c.path}", "modbus-rtu": f"rtu {c.serial_port} unit {n.profile.modbus.node.unit_id}",
                   "scene": f"scene {c.scene}"}[c.source]
            click.echo(f"{n.name}: {n.profile.name} ({n.profile.source}), {n.rate_hz:g} Hz, {src} -> PLC {mode} "
                       f"block at {n.profile.modbus.plc.base_address}")
        return
    quiet_pymodbus()
    log = EventLog(sys.stderr, logs.format, logs.level)
    br = Bridge(cfg, nodes, log)
    try:
        br.open()
    except BaseException:
        log.close()
        raise
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda signum, _frame: br.request_stop(signal.Signals(signum).name))
    try:
        br.start()
        br.wait(duration_s)
    finally:
        br.stop()
        br.log_counters("final")
        log.close()
    if br.failure:
        click.echo(f"eskin-bus: error: bridge stopped: {br.failure}", err=True)
        sys.exit(1)
