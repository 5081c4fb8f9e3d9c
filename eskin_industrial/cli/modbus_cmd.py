"""``eskin-bus modbus-node`` (a sensor node simulator, Modbus RTU slave) and
``eskin-bus modbus-bridge`` (RTU node -> detector -> PLC registers, client or server)."""

from __future__ import annotations

import logging
import sys
import threading
import time
from typing import TYPE_CHECKING

import click

from .common import host_port, host_value, open_profile, profile_option, scene_or_recording

if TYPE_CHECKING:
    from ..bridge.loop import NodeLoop
    from ..profile import Profile


@click.command("modbus-node")
@profile_option()
@click.option("--port", "port", required=True, help="Serial port to serve on (e.g. one end of a socat pty pair).")
@click.option("--scene", default=None, help="Built-in scene name or scene .toml.")
@click.option("--recording", type=click.Path(dir_okay=False), default=None, help="Recording CSV (t,f0,... or t,raw0,...).")
@click.option("--rate", "rate_hz", type=click.FloatRange(min=0.1), default=None,
              help="Scan rate in Hz (default: the recording's, or the profile's for a scene).")
@click.option("--baud", "baudrate", type=int, default=None, help="Baud rate (default: the profile's).")
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--once", is_flag=True, help="Play the scene once and keep its last scan (default: loop).")
@click.option("--duration", "duration_s", type=click.FloatRange(min=0.0), default=None,
              help="Stop after this many seconds (default: until interrupted).")
def modbus_node(profile_path: str, port: str, scene: str | None, recording: str | None, rate_hz: float | None,
                baudrate: int | None, seed: int, once: bool, duration_s: float | None) -> None:
    """Serve a scene as the sensor node: a Modbus RTU slave with the profile's register map."""
    run_rtu_node(open_profile(profile_path), port, scene, recording, rate_hz, baudrate, seed, once, duration_s)


def run_rtu_node(prof: Profile, port: str, scene: str | None, recording: str | None, rate_hz: float | None,
                 baudrate: int | None, seed: int, once: bool, duration_s: float | None) -> None:
    """The RTU node, shared by ``modbus-node`` and ``node --modbus-rtu``."""
    from ..modbus.pymodbus_io import quiet_pymodbus
    from ..sim.modbus_node import serve_scene_rtu

    quiet_pymodbus()
    scans = scene_or_recording(prof, scene, recording, rate_hz, seed)
    t, forces, rate = scans.t, scans.forces, scans.rate_hz
    node = prof.modbus.node
    click.echo(f"modbus-node: unit {node.unit_id} on {port} at {baudrate or node.baudrate} baud, "
               f"{len(t)} scans at {rate:g} Hz, function {node.function} from address {node.start_address}",
               err=True)
    stop = threading.Event()
    try:
        sim = serve_scene_rtu(prof, port, t, forces, rate, baudrate=baudrate, loop=not once,
                              duration_s=duration_s, stop=stop)
    except KeyboardInterrupt:
        stop.set()
        return
    click.echo(f"modbus-node: answered {sim.registers.reads} reads", err=True)


@click.command("modbus-bridge")
@profile_option()
@click.option("--rtu", "rtu_port", default=None, help="Serial port of the sensor node (Modbus RTU master).")
@click.option("--recording", type=click.Path(dir_okay=False), default=None,
              help="Replay a recording instead of polling a node.")
@click.option("--baud", "baudrate", type=int, default=None, help="Node baud rate (default: the profile's).")
@click.option("--plc-host", default=None, callback=host_value, help="Client mode: the PLC's host (default: the profile's).")
@click.option("--plc-port", type=int, default=None, help="Client mode: the PLC's port (default: the profile's).")
@click.option("--plc-rtu", default=None, metavar="PORT", help="Client mode over Modbus RTU: the PLC's serial port.")
@click.option("--plc-baud", type=int, default=115200, show_default=True, help="Baud rate for --plc-rtu.")
@click.option("--plc-timeout", type=click.FloatRange(0.01, 30.0), default=None,
              help="Client mode: seconds the PLC has to answer (default: the profile's timeout_s).")
@click.option("--serve", "serve", default=None, metavar="HOST:PORT",
              help="Server mode over TCP (default host: the profile's [modbus.plc] bind).")
@click.option("--serve-rtu", default=None, metavar="PORT", help="Server mode over Modbus RTU on this serial port.")
@click.option("--serve-baud", type=int, default=115200, show_default=True)
@click.option("--duration", "duration_s", type=click.FloatRange(min=0.0), default=None,
              help="Stop after this many seconds (default: until interrupted).")
@click.option("--status-every", type=click.FloatRange(min=0.0), default=0.0,
              help="Print counters every N seconds (0: only at the end).")
def modbus_bridge(profile_path: str, rtu_port: str | None, recording: str | None, baudrate: int | None,
                  plc_host: str | None, plc_port: int | None, plc_rtu: str | None, plc_baud: int,
                  plc_timeout: float | None, serve: str | None, serve_rtu: str | None, serve_baud: int,
                  duration_s: float | None, status_every: float) -> None:
    """Poll the node over Modbus RTU, detect, and publish the PLC register image:
    written to the PLC (client mode, the default when the profile says so) or served
    (--serve / --serve-rtu).  The same loop as ``eskin-bus bridge --source rtu:PORT``,
    and the same signals: SIGTERM, SIGINT, SIGHUP or SIGQUIT (or --duration) leave the
    PLC reading BRIDGE_OFFLINE; SIGUSR1 prints the counters."""
    from ..bridge.config import BridgeConfig, NodeConfig, resolve
    from ..bridge.runtime import SingleNode
    from ..bridge.signals import EXIT_FAILED, handled_signals
    from ..modbus.pymodbus_io import quiet_pymodbus
    from ..outputs.plc.options import PlcOptions

    quiet_pymodbus()
    prof = open_profile(profile_path)
    plc = prof.modbus.plc
    if (rtu_port is None) == (recording is None):
        raise click.UsageError("give one of --rtu PORT or --recording REC.csv")
    if serve and serve_rtu:
        raise click.UsageError("--serve and --serve-rtu exclude each other")
    client_asked = plc_host is not None or plc_port is not None or plc_rtu is not None or plc_timeout is not None
    if client_asked and (serve or serve_rtu):
        raise click.UsageError("client options (--plc-*) and server options (--serve*) exclude each other")
    if serve_rtu:
        out = PlcOptions(mode="server", transport="rtu", serial_port=serve_rtu, baudrate=serve_baud)
    elif serve:
        host, port = host_port(serve, "--serve", require_port=True)
        out = PlcOptions(mode="server", host=host, port=port)  # no host: the profile's bind
    elif plc_rtu:
        out = PlcOptions(mode="client", transport="rtu", serial_port=plc_rtu, baudrate=plc_baud, timeout_s=plc_timeout)
    else:
        out = PlcOptions(mode="client" if client_asked else None, host=plc_host, port=plc_port, timeout_s=plc_timeout)
    if rtu_port is not None:
        node = NodeConfig.of("node", profile_path, "modbus-rtu", serial_port=rtu_port, baudrate=baudrate)
    else:
        node = NodeConfig.of("node", profile_path, "recording", path=recording)
    cfg = BridgeConfig(node=(node,), outputs={"plc": out})
    (resolved,) = resolve(cfg)
    # The signals of `eskin-bus bridge`: each stopping one leaves the block reading
    # BRIDGE_OFFLINE (SingleNode's exit), USR1 prints the counters.
    package_log = logging.getLogger("eskin_industrial")  # the server's refusals: a line each
    lines, level = _Lines(), package_log.level
    package_log.addHandler(lines)
    package_log.setLevel(logging.INFO)
    try:
        with handled_signals() as flags:
            single = SingleNode(cfg, resolved)
            loop = single.loop
            for sink in loop.sinks:  # the writer's outages: a line each
                sink.on_events(_event_line)
            where = "; ".join(s.where for s in loop.sinks)
            _say(f"modbus-bridge: {prof.name}: {rtu_port or recording} -> {where}, base address {plc.base_address}")
            end = None if duration_s is None else time.monotonic() + duration_s
            next_status = time.monotonic() + status_every if status_every else None
            usr1 = 0
            with single:
                while not flags.reason and not single.failure and (end is None or time.monotonic() < end):
                    loop.step()
                    if flags.counters != usr1:
                        usr1 = flags.counters
                        _say(_counters(loop))
                    if next_status is not None and time.monotonic() >= next_status:
                        next_status += status_every
                        _say(_counters(loop))
            _say(f"modbus-bridge: stopped ({flags.reason or 'duration'}), offline written: "
                 f"{'yes' if single.offline_written else 'no'}")
            _say(_counters(loop))
    finally:
        package_log.removeHandler(lines)
        package_log.setLevel(level)
    if single.failure:
        _say(f"eskin-bus: error: modbus-bridge stopped: {single.failure}")
        sys.exit(EXIT_FAILED)
    if flags.failing:
        sys.exit(EXIT_FAILED)


def _counters(loop: NodeLoop) -> str:
    return "modbus-bridge: " + " ".join(f"{k}={v}" for k, v in loop.counters().items())


class _Lines(logging.Handler):
    """The package's own log records (the Modbus server's events) as lines on stderr."""

    def emit(self, record: logging.LogRecord) -> None:
        _event_line(record.getMessage(), record.levelname.lower(), getattr(record, "fields", {}))


def _event_line(name: str, level: str, fields: dict) -> None:
    _say(f"modbus-bridge: {level} {name} " + " ".join(f"{k}={v}" for k, v in fields.items()))


def _say(line: str) -> None:
    """A line on stderr, which may be gone (a closed terminal, a dead pipe)."""
    try:
        click.echo(line, err=True)
    except OSError:
        pass
