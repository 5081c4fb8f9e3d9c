"""``eskin-bus modbus-node`` (a sensor node simulator, Modbus RTU slave) and
``eskin-bus modbus-bridge`` (deprecated: ``eskin-bus bridge --source rtu:PORT`` under
its old option names)."""

from __future__ import annotations

import shlex
import threading
from typing import TYPE_CHECKING, Any

import click

from .bridge_cmd import bridge
from .common import host_port, host_value, open_profile, profile_option, scene_or_recording
from .completion import complete_scene
from .console import quiet

if TYPE_CHECKING:
    from ..profile import Profile


@click.command("modbus-node")
@profile_option()
@click.option("--port", "port", required=True, help="Serial port to serve on (e.g. one end of a socat pty pair).")
@click.option("--scene", default=None, shell_complete=complete_scene, help="Built-in scene name or scene .toml.")
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
@click.option("--rtu", "rtu_port", default=None, help="Serial port of the sensor node: bridge --source rtu:PORT.")
@click.option("--recording", type=click.Path(dir_okay=False), default=None,
              help="Replay a recording instead of polling a node: bridge --source recording:FILE.")
@click.option("--baud", "baudrate", type=int, default=None,
              help="Node baud rate (default: the profile's): bridge --source rtu:PORT@BAUD.")
@click.option("--plc-host", default=None, callback=host_value,
              help="Client mode: the PLC's host (default: the profile's): bridge --plc tcp:HOST:PORT.")
@click.option("--plc-port", type=int, default=None,
              help="Client mode: the PLC's port (default: the profile's): bridge --plc tcp:HOST:PORT.")
@click.option("--plc-rtu", default=None, metavar="PORT",
              help="Client mode over Modbus RTU, the PLC's serial port: bridge --plc rtu:PORT.")
@click.option("--plc-baud", type=int, default=115200, show_default=True, help="Baud rate for --plc-rtu.")
@click.option("--plc-timeout", type=click.FloatRange(0.01, 30.0), default=None,
              help="Client mode: seconds the PLC has to answer (default: the profile's timeout_s).")
@click.option("--serve", "serve", default=None, metavar="HOST:PORT",
              help="Server mode over TCP (default host: the profile's [modbus.plc] bind): bridge --plc serve:HOST:PORT.")
@click.option("--serve-rtu", default=None, metavar="PORT",
              help="Server mode over Modbus RTU on this serial port: bridge --plc serve-rtu:PORT.")
@click.option("--serve-baud", type=int, default=115200, show_default=True, help="Baud rate for --serve-rtu.")
@click.option("--duration", "duration_s", type=click.FloatRange(min=0.0), default=None,
              help="Stop after this many seconds (default: until interrupted).")
@click.option("--status-every", type=click.FloatRange(min=0.0), default=None,
              help="Log the counters every N seconds (default: the bridge's, 60; 0: only at the end).")
@click.pass_context
def modbus_bridge(ctx: click.Context, profile_path: str, rtu_port: str | None, recording: str | None,
                  baudrate: int | None, plc_host: str | None, plc_port: int | None, plc_rtu: str | None,
                  plc_baud: int, plc_timeout: float | None, serve: str | None, serve_rtu: str | None,
                  serve_baud: int, duration_s: float | None, status_every: float | None) -> None:
    """Deprecated: ``eskin-bus bridge --source rtu:PORT`` (or ``recording:FILE``) under
    the old option names.  It prints the equivalent ``bridge`` command line on stderr,
    then runs it: the same loop, log lines, signals and exit codes."""
    args = bridge_args(profile_path, rtu_port, recording, baudrate, plc_host, plc_port, plc_rtu, plc_baud,
                       plc_timeout, serve, serve_rtu, serve_baud, duration_s, status_every)
    if not quiet():
        line = shlex.join(["eskin-bus", "bridge", *(word for flag, _, value in args for word in (flag, _word(value)))])
        click.echo(f"eskin-bus: warning: modbus-bridge is deprecated; it runs: {line}", err=True)
    # From the group's context, as if `bridge` had been typed (-q/-v before the
    # command still apply); a usage error of the bridge's names its command.
    parent = ctx.parent or ctx
    try:
        parent.invoke(bridge, **{dest: value for _, dest, value in args})
    except click.UsageError as exc:
        if exc.ctx is None or exc.ctx is parent:
            exc.ctx = click.Context(bridge, info_name="bridge", parent=parent)
        raise


def bridge_args(profile_path: str, rtu_port: str | None, recording: str | None, baudrate: int | None,
                plc_host: str | None, plc_port: int | None, plc_rtu: str | None, plc_baud: int,
                plc_timeout: float | None, serve: str | None, serve_rtu: str | None, serve_baud: int,
                duration_s: float | None, status_every: float | None) -> list[tuple[str, str, Any]]:
    """``modbus-bridge``'s options as ``bridge``'s: ``(flag, parameter, value)`` each,
    one table for both the printed command line and the call (so they cannot differ).
    Combinations the old command refused are refused the same way."""
    if (rtu_port is None) == (recording is None):
        raise click.UsageError("give one of --rtu PORT or --recording REC.csv")
    if recording is not None and baudrate is not None:
        raise click.UsageError("--baud is the node's serial line: it goes with --rtu, not --recording")
    if serve and serve_rtu:
        raise click.UsageError("--serve and --serve-rtu exclude each other")
    tcp_client = plc_host is not None or plc_port is not None
    if (tcp_client or plc_rtu is not None or plc_timeout is not None) and (serve or serve_rtu):
        raise click.UsageError("client options (--plc-*) and server options (--serve*) exclude each other")
    if tcp_client and plc_rtu is not None:
        raise click.UsageError("--plc-rtu and --plc-host/--plc-port exclude each other")
    source = f"rtu:{rtu_port}" + (f"@{baudrate}" if baudrate is not None else "") if rtu_port is not None \
        else f"recording:{recording}"
    args: list[tuple[str, str, Any]] = [("-p", "profile_path", profile_path), ("--source", "source", source)]
    baud = None
    if serve_rtu:
        plc, baud = f"serve-rtu:{serve_rtu}", serve_baud
    elif serve:
        host, port = host_port(serve, "--serve", require_port=True)
        plc = f"serve:{_endpoint(host, port)}"
    elif plc_rtu:
        plc, baud = f"rtu:{plc_rtu}", plc_baud
    elif tcp_client or plc_timeout is not None:  # as before: any client option asks for client mode
        plc = f"tcp:{_endpoint(plc_host, plc_port)}"
    else:
        plc = None  # the profile's [modbus.plc], as the bridge has it
    if plc is not None:
        args.append(("--plc", "plc", plc))
    if baud is not None and baud != 115200:  # the bridge's default too
        args.append(("--plc-baud", "plc_baud", baud))
    for flag, dest, value in (("--plc-timeout", "plc_timeout", plc_timeout),
                              ("--status-every", "status_every", status_every),
                              ("--duration", "duration_s", duration_s)):
        if value is not None:
            args.append((flag, dest, value))
    return args


def _endpoint(host: str | None, port: int | None) -> str:
    """``HOST:PORT``, ``HOST``, ``:PORT`` or nothing, an IPv6 host in brackets (what
    :func:`eskin_industrial.netaddr.parse_endpoint` reads back)."""
    text = "" if host is None else f"[{host}]" if ":" in host else host
    return text if port is None else f"{text}:{port}"


def _word(value: Any) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)
