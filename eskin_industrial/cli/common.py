"""Options and helpers shared by the subcommands."""

from __future__ import annotations

import click

from ..profile import Profile, load_profile


def profile_option(required: bool = True):
    return click.option(
        "-p", "--profile", "profile_path", type=click.Path(dir_okay=False), required=required,
        help="Sensor profile (TOML), e.g. profiles/paper-5x5.toml.",
    )


def open_profile(path: str) -> Profile:
    """Load and validate; a bad profile stops the command before anything starts."""
    return load_profile(path)
