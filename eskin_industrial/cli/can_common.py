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
