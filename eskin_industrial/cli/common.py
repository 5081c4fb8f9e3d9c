"""Options and helpers shared by the subcommands."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import TypeVar

import click
import numpy as np
from click.shell_completion import CompletionItem

from ..calibration import Calibrator, full_scale
from ..errors import InputFormatError, OutputFileError
from ..profile import Profile, load_profile
from ..recording import read_recording
from .completion import files_for

FC = TypeVar("FC", bound=Callable[..., object])


def complete_profile(ctx: click.Context, param: click.Parameter, incomplete: str) -> list[CompletionItem]:
    """Shell completion of a profile: the built-in names, then profile files."""
    from ..profile import builtin_profiles

    names = [CompletionItem(n) for n in builtin_profiles() if n.startswith(incomplete)]
    return names + files_for(incomplete, ".toml")


def profile_option(required: bool = True) -> Callable[[FC], FC]:
    return click.option(
        "-p", "--profile", "profile_path", type=click.Path(dir_okay=False), required=required,
        shell_complete=complete_profile,
        help="Sensor profile: a TOML file, or a built-in name (eskin-bus profile list), e.g. paper-5x5.",
    )


def host_port(text: str, what: str, require_port: bool = False) -> tuple[str | None, int | None]:
    """``HOST:PORT`` (``HOST``, ``:PORT`` or nothing when the port is not required):
    None for what is left out, for the caller's default."""
    from ..outputs.plc.options import parse_host_port

    try:
        return parse_host_port(text, require_port)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint=what) from None


def host_value(ctx: click.Context, param: click.Parameter, value: str | None) -> str | None:
    """A click callback: ``value`` is a host (:func:`eskin_industrial.netaddr.check_host`)."""
    from ..netaddr import check_host

    if value is None:
        return None
    try:
        return check_host(value)
    except ValueError as exc:
        raise click.BadParameter(str(exc)) from None


def check_output(path: str | None, option: str) -> None:
    """Before the work: the folder of a file to write (``-o``, ``--labels``) is there
    and writable, or one line naming the option, exit 2 (as ``receive -o`` and
    ``bridge --check`` refuse it).  ``-`` (stdout) and None pass."""
    from ..preflight import check_writable_dir

    if path is None or path == "-":
        return
    try:
        check_writable_dir(path, option)
    except ValueError as exc:
        raise OutputFileError(str(exc)) from None


@contextmanager
def writing(path: str, option: str) -> Iterator[None]:
    """Around the writing of ``path``: what the folder check cannot know (a file
    without write permission, a full disk) as one line naming the option, exit 2."""
    try:
        yield
    except BrokenPipeError:
        raise  # stdout's reader went away: the group's business (exit 0)
    except OSError as exc:
        if path == "-":
            raise
        raise OutputFileError(f"{option}: {path}: cannot write: {(exc.strerror or str(exc)).lower()}") from None


def open_profile(path: str) -> Profile:
    """Load and validate; a bad profile stops the command before anything starts."""
    return load_profile(path)


@dataclass(frozen=True)
class NodeScans:
    """What a node simulator plays: times, forces in N, the scan rate, and the raw
    values when the recording already holds them (so they are sent unchanged)."""

    t: np.ndarray
    forces: np.ndarray
    rate_hz: float
    raw: np.ndarray | None = None

    def raw_values(self, profile: Profile) -> np.ndarray:
        if self.raw is not None:
            return self.raw
        return Calibrator.from_section(profile.calibration, profile.taxels).to_raw(self.forces)


def scene_or_recording(prof: Profile, scene: str | None, recording: str | None, rate_hz: float | None,
                       seed: int = 0) -> NodeScans:
    """The scans of ``--scene NAME`` (rendered at ``--rate``, else the profile's) or
    ``--recording REC.csv`` (at ``--rate``, else the rate its timestamps show)."""
    if (scene is None) == (recording is None):
        raise click.UsageError("give exactly one of --scene NAME or --recording REC.csv")
    if rate_hz is not None and not rate_hz > 0:
        raise click.BadParameter(f"expected a positive rate, got {rate_hz}", param_hint="--rate")
    if scene is not None:
        from ..scenes import render

        rate = rate_hz or prof.sensor.rate_hz
        rendered = render(scene, rate, seed)
        if rendered.forces.shape[1] != prof.taxels:
            raise InputFormatError(f"--scene {scene}: {rendered.forces.shape[1]} taxels ({rendered.profile_name}), "
                                   f"but profile {prof.name} has {prof.taxels}")
        return NodeScans(rendered.t, rendered.forces, rate)
    assert recording is not None  # exactly one of the two, checked above
    rec = read_recording(recording, prof.taxels)
    rate = rate_hz or rec.rate_hz(prof.sensor.rate_hz)
    if rec.unit == "raw":
        forces, _ = Calibrator.from_section(prof.calibration, prof.taxels).to_newtons(rec.values)
        return NodeScans(rec.t, forces, rate, rec.values)
    return NodeScans(rec.t, full_scale(rec.values, prof.calibration.full_scale_n)[0], rate)
