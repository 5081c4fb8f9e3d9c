"""``eskin-bus plc-sim``: a PLC stand-in for commissioning without a PLC."""

from __future__ import annotations

import time

import click

from .common import host_value, open_profile, profile_option


@click.command("plc-sim")
@profile_option()
@click.option("--host", default="127.0.0.1", show_default=True, callback=host_value, help="Address to listen on.")
@click.option("--port", type=int, default=None, help="TCP port (default: 502, or a profile's deprecated [modbus.plc] port).")
@click.option("--rtu", "rtu_port", default=None, metavar="PORT", help="Be an RTU slave on this serial port instead.")
@click.option("--baud", "baudrate", type=int, default=115200, show_default=True, help="Baud rate for --rtu.")
@click.option("--duration", "duration_s", type=click.FloatRange(min=0.0), default=None,
              help="Stop after this many seconds (default: until interrupted).")
@click.option("--grip-step", type=click.FloatRange(min=0.0), default=2.0, show_default=True,
              help="Newtons added to the grip force at each slip.")
def plc_sim(profile_path: str, host: str, port: int | None, rtu_port: str | None, baudrate: int,
            duration_s: float | None, grip_step: float) -> None:
    """Serve the PLC's receive registers over Modbus TCP (for `bridge --plc tcp:HOST:PORT`,
    client mode), print every status change, and run the example gripper logic: raise the
    grip force when the slip flag comes, acknowledge the latch, hold when the data
    is not valid."""
    from ..sim.plc import Gripper, PlcSimulator

    prof = open_profile(profile_path)
    plc = prof.modbus.plc
    from ..modbus.pymodbus_io import quiet_pymodbus
    from ..modbus.serial_line import SerialSettings

    quiet_pymodbus()
    serial = SerialSettings(rtu_port, baudrate) if rtu_port else None
    sim = PlcSimulator(plc, host, port or plc.port, gripper=Gripper(step_n=grip_step),
                       echo=lambda s: click.echo(s), serial=serial)
    sim.start()
    try:  # from the start line on, Ctrl-C or SIGTERM end with the summary
        click.echo(f"plc-sim: listening on {sim.server.where}, registers from {plc.base_address} "
                   f"(40001 + {plc.base_address}), grip force {sim.gripper.force_n:g} N", err=True)
        if duration_s is None:
            while True:
                time.sleep(1.0)
        else:
            time.sleep(duration_s)
    except KeyboardInterrupt:
        pass
    finally:
        sim.stop()
    click.echo(f"plc-sim: {sim.memory.writes} writes received, {sim.gripper.raises} slip reactions, "
               f"grip force {sim.gripper.force_n:g} N", err=True)
