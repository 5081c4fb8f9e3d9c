"""The bus options every CAN command shares, with python-can's own names."""

from __future__ import annotations

import click


def bus_options(func):
    """``-i/--interface``, ``-c/--channel``, ``-b/--bitrate``, ``--fd``, ``--data-bitrate``.

    Unset options are left to python-can (its config file, ``CAN_INTERFACE``,
    ``CAN_CHANNEL``); the bit rates default to the profile's ``[can]`` section.
    """
    opts = [
        click.option("-i", "--interface", default=None,
                     help="python-can interface: socketcan, virtual, slcan, pcan, ... "
                          "(default: python-can's configuration, CAN_INTERFACE)."),
        click.option("-c", "--channel", default=None,
                     help="Channel, e.g. vcan0, can0 (default: python-can's configuration, CAN_CHANNEL)."),
        click.option("-b", "--bitrate", type=int, default=None, help="Bit rate in bit/s (default: the profile's)."),
        click.option("--fd/--no-fd", "fd", default=None, help="CAN FD: one frame per scan (default: the profile's)."),
        click.option("--data-bitrate", type=int, default=None,
                     help="CAN FD data-phase bit rate in bit/s (default: the profile's)."),
    ]
    for opt in reversed(opts):
        func = opt(func)
    return func


def bus_kwargs(profile, interface, channel, bitrate, fd, data_bitrate) -> dict:
    """Arguments for :func:`~eskin_industrial.bus.can_source.open_bus`."""
    use_fd = profile.can.fd if fd is None else fd
    # A bit rate is only passed on when given: virtual and socketcan buses ignore it,
    # hardware adapters need it (the profile's when the command line has none).
    rate = bitrate if bitrate is not None else (profile.can.bitrate_bps if interface not in (None, "virtual", "socketcan") else None)
    data = data_bitrate if data_bitrate is not None else (profile.can.data_bitrate_bps if rate is not None else None)
    return dict(interface=interface, channel=channel, bitrate=rate, fd=use_fd, data_bitrate=data)
