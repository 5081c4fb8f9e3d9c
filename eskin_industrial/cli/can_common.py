"""The bus options every CAN command shares, with python-can's own names."""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import click

from ..bus.can.busargs import parse_bus_kwargs, parse_filters, parse_timing
from ..errors import NothingReceived
from .completion import complete_interface

if TYPE_CHECKING:
    from ..bus.can.logbus import LogBus
    from ..profile import Profile


def bus_extra(timing: tuple[str, ...], can_filter: tuple[str, ...], kwargs: tuple[str, ...]) -> dict[str, Any]:
    """``--timing``, ``--filter`` and ``--bus-kwargs`` as a node's ``[[node]]`` keys
    (only those given); a malformed one is a usage error naming the option."""
    out: dict[str, Any] = {}
    for option, words, parse, key in (("--timing", timing, parse_timing, "timing"),
                                      ("--filter", can_filter, parse_filters, "filter"),
                                      ("--bus-kwargs", kwargs, parse_bus_kwargs, "bus_kwargs")):
        try:
            value = parse(words)
        except ValueError as exc:
            raise click.BadParameter(str(exc), param_hint=option) from None
        if value:
            out[key] = value if key != "filter" else [w for item in words for w in item.split()]
    return out


def bus_options(func: Callable[..., Any]) -> Callable[..., Any]:
    """``-i/--interface``, ``-c/--channel``, ``-b/--bitrate``, ``--fd``, ``--data-bitrate``,
    ``--timing``, ``--filter``, ``--bus-kwargs``: python-can's names and syntax
    (``can.logger``); the last three reach the command as one ``bus_extra`` dict.

    Unset options are left to python-can (its config file, ``CAN_INTERFACE``,
    ``CAN_CHANNEL``, ``CAN_BITRATE``); the bit rates default to the profile's ``[can]``.
    """
    @functools.wraps(func)
    def wrapper(*args: Any, timing: tuple[str, ...], can_filter: tuple[str, ...], bus_kwargs: tuple[str, ...],
                **kwargs: Any) -> Any:
        return func(*args, bus_extra=bus_extra(timing, can_filter, bus_kwargs), **kwargs)

    opts = [
        click.option("-i", "--interface", default=None, shell_complete=complete_interface,
                     help="python-can interface: socketcan, virtual, slcan, pcan, ... "
                          "(default: python-can's configuration, CAN_INTERFACE)."),
        click.option("-c", "--channel", default=None,
                     help="Channel, e.g. vcan0, can0 (default: python-can's configuration, CAN_CHANNEL)."),
        click.option("-b", "--bitrate", type=int, default=None,
                     help="Bit rate in bit/s (default: python-can's configuration, CAN_BITRATE, then the profile's)."),
        click.option("--fd/--no-fd", "fd", default=None, help="CAN FD: one frame per scan (default: the profile's)."),
        click.option("--data-bitrate", type=int, default=None,
                     help="CAN FD data-phase bit rate in bit/s (default: python-can's configuration, then the profile's)."),
        click.option("--timing", multiple=True, metavar="KEY=INT ...",
                     help="Bit timing, python-can's keys: f_clock=8000000 brp=2 tseg1=5 tseg2=2 sjw=2 nof_samples=1 (CAN FD: "
                          "f_clock nom_brp nom_tseg1 nom_tseg2 nom_sjw data_brp ...); replaces the bit rates. "
                          "Repeatable."),
        click.option("--filter", "can_filter", multiple=True, metavar="ID:MASK ...",
                     help="Receive filters in python-can's syntax, hexadecimal: 200:7F0 passes 0x200-0x20F; "
                          "ID~MASK inverts (SocketCAN). Repeatable."),
        click.option("--bus-kwargs", "bus_kwargs", multiple=True, metavar="KEY=VALUE ...",
                     help="Keyword arguments for the interface's bus class, e.g. app_name=Cell7 serial=1234. "
                          "Repeatable."),
    ]
    out: Callable[..., Any] = wrapper
    for opt in reversed(opts):
        out = opt(out)
    return out


def log_bus(path: str) -> LogBus:
    """A CAN log to write frames to (``--can-log FILE``); a file that cannot be created
    is a usage error naming the option."""
    from ..bus.can.logbus import LogBus

    try:
        return LogBus(path)
    except (OSError, ValueError) as exc:
        detail = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        raise click.BadParameter(f"{path}: cannot write: {detail}", param_hint="--can-log") from None


def nothing_received(profile: Profile, where: str, idle_s: float) -> NothingReceived:
    """``--idle-exit`` with not one scan since the start: one line naming the channel
    and the IDs listened on (exit 6, docs/cli.md)."""
    lo = profile.can.base_id
    return NothingReceived(f"no scan of profile {profile.name}'s node on {where} in {idle_s:g} s (--idle-exit): "
                           f"nothing sent there on IDs {lo:#x}-{lo + 15:#x}; is the node on, on this channel, "
                           "with this base_id?")
