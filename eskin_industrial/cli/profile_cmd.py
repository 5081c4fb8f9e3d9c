"""``eskin-bus profile check|show|dbc``."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import click

from ..errors import ProfileError
from ..profile import Profile, builtin_profiles, load_profile
from .common import complete_profile
from .console import echo_json
from .toml_out import dumps


@click.group()
def profile() -> None:
    """Validate and inspect sensor profiles."""


@profile.command()
@click.argument("files", nargs=-1, required=True, type=click.Path(dir_okay=False), shell_complete=complete_profile)
@click.option("--format", "fmt", type=click.Choice(["text", "json"]), default="text", show_default=True,
              help="One line per profile, or one JSON document (a list: file, ok, error, warnings, summary).")
def check(files: tuple[str, ...], fmt: str) -> None:
    """Validate profiles; one line each, exit 2 if any is refused."""
    results = [_check_one(path) for path in files]
    if fmt == "json":
        echo_json(results)
    else:
        for r in results:
            if r["ok"]:
                click.echo(f"{r['file']}: ok ({r['summary']})")
            else:
                click.echo(f"eskin-bus: error: {r['error']}", err=True)
            for w in r["warnings"]:
                click.echo(f"eskin-bus: warning: {w}", err=True)
    if not all(r["ok"] for r in results):
        raise SystemExit(2)


def _check_one(path: str) -> dict[str, Any]:
    try:
        p = load_profile(path)
    except ProfileError as exc:
        return {"file": path, "ok": False, "error": str(exc), "warnings": [], "summary": None}
    warnings = []
    try:  # the transports' own checks; only the commands that use them refuse
        from ..bus.can.layout import CanLayout

        CanLayout.from_profile(p)
    except ProfileError as exc:
        warnings.append(f"{exc} (CAN commands will refuse this profile)")
    return {"file": path, "ok": True, "error": None, "warnings": warnings, "summary": _brief(p)}


@profile.command()
@click.argument("file", type=click.Path(dir_okay=False), shell_complete=complete_profile)
@click.option("--format", "fmt", type=click.Choice(["toml", "json"]), default="toml", show_default=True)
def show(file: str, fmt: str) -> None:
    """Print the profile as loaded: every key with its default filled in, plus the
    values derived from it (taxel coordinates, detector sizes in samples)."""
    p = load_profile(file)
    table = p.to_table()
    geo = p.detector.geometry(p.sensor.rate_hz)
    x, y = p.coordinates_mm
    table["derived"] = {
        "taxels": p.taxels,
        "x_mm": x.tolist(),
        "y_mm": y.tolist(),
        "at_rate_hz": p.sensor.rate_hz,
        "window_samples": geo.window,
        "hop_samples": geo.hop,
        "lag_samples": geo.lag,
        "wavelet_filter_len": geo.filter_len,
    }
    if fmt == "json":
        click.echo(json.dumps(table, indent=2))
    else:
        import tomllib

        given = tomllib.loads(Path(p.source).read_text(encoding="utf-8"))  # loaded once already: valid TOML
        given["derived"] = table["derived"]  # computed, not defaults
        click.echo(f"# {file}: {_brief(p)}")
        click.echo("# every key, as resolved: '# default' marks what the file leaves to the default")
        click.echo(dumps(table, given=given), nl=False)


@profile.command()
@click.argument("file", type=click.Path(dir_okay=False), shell_complete=complete_profile)
@click.option("--fd/--no-fd", "fd", default=None, help="Describe CAN FD frames (default: the profile's).")
def dbc(file: str, fd: bool | None) -> None:
    """Write a DBC describing the profile's CAN frames (taxels scaled to newtons)."""
    from ..bus.can.dbc import dbc_text
    from ..bus.can.layout import CanLayout

    p = load_profile(file)
    click.echo(dbc_text(p, CanLayout.from_profile(p, fd=fd)), nl=False)


@profile.command(name="list")
def list_() -> None:
    """The built-in profiles: their names work wherever a profile file does (-p NAME)."""
    for name, path in builtin_profiles().items():
        click.echo(f"{name:<12} {_brief(load_profile(path))}")


@profile.command()
@click.argument("name")
@click.option("-o", "--output", type=click.Path(dir_okay=False), default=None,
              help="Where to write it (default: NAME.toml in the working directory).")
@click.option("--force", is_flag=True, help="Overwrite an existing file.")
def init(name: str, output: str | None, force: bool) -> None:
    """Copy a built-in profile out, to edit it for an installation."""
    builtin = builtin_profiles().get(name.removesuffix(".toml"))
    if builtin is None:
        raise click.BadParameter(f"{name!r} is not a built-in profile (built-in: {', '.join(builtin_profiles())})",
                                 param_hint="NAME")
    target = Path(output or f"{builtin.stem}.toml")
    if target.exists() and not force:
        raise click.UsageError(f"{target}: exists; give --force to overwrite it")
    try:
        shutil.copyfile(builtin, target)
    except OSError as exc:
        raise click.UsageError(f"{target}: cannot write: {exc.strerror or exc}") from None
    click.echo(f"{target}: written from the built-in profile {builtin.stem}; check it with "
               f"`eskin-bus profile check {target}`")


def _brief(p: Profile) -> str:
    return (f"{p.name}, {p.layout.rows}x{p.layout.cols} taxels, {p.sensor.rate_hz:g} Hz, "
            f"{p.calibration.raw_unit}, method {p.detector.method}")
