"""``eskin-bus profile check|show|dbc``."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any
from warnings import catch_warnings, simplefilter

import click

from ..errors import DeprecatedKey, ProfileError
from ..profile import Profile, builtin_profiles, load_profile
from .common import complete_profile
from .console import echo_json, json_alias
from .profile_tune import tune
from .toml_out import dumps


@click.group()
def profile() -> None:
    """Validate and inspect sensor profiles."""


profile.add_command(tune)


@profile.command()
@click.argument("files", nargs=-1, required=True, type=click.Path(dir_okay=False), shell_complete=complete_profile)
@click.option("--format", "fmt", type=click.Choice(["text", "json"]), default="text", show_default=True,
              help="One line per profile, or one JSON document (a list: file, ok, error, warnings, summary).")
@json_alias
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
    with catch_warnings(record=True) as caught:
        simplefilter("always", DeprecatedKey)
        try:
            p = load_profile(path)
        except ProfileError as exc:
            return {"file": path, "ok": False, "error": str(exc), "warnings": [], "summary": None}
    # a key that moved: said here, with the file's other warnings (each line names the file)
    warnings = [str(w.message) for w in caught if issubclass(w.category, DeprecatedKey)]
    try:  # the transports' own checks; only the commands that use them refuse
        from ..bus.can.layout import CanLayout

        CanLayout.from_profile(p)
    except ProfileError as exc:
        warnings.append(f"{exc} (CAN commands will refuse this profile)")
    return {"file": path, "ok": True, "error": None, "warnings": warnings, "summary": _brief(p)}


@profile.command()
@click.argument("file", type=click.Path(dir_okay=False), shell_complete=complete_profile)
@click.option("--format", "fmt", type=click.Choice(["toml", "json"]), default="toml", show_default=True)
@json_alias
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
@click.argument("file", type=click.Path(dir_okay=False), required=False, shell_complete=complete_profile)
@click.option("--config", "config_path", type=click.Path(dir_okay=False),
              help="A bridge configuration: one DBC for every CAN node in it (instead of FILE).")
@click.option("--fd/--no-fd", "fd", default=None, help="Describe CAN FD frames (default: the profile's).")
@click.option("--node-name", help="The DBC node, and the prefix of its message names (default: NODE<node_id>, "
                                  "messages prefixed with the profile's name).")
@click.option("--base-id", help="The node's first CAN ID (default: the profile's [can] base_id), e.g. 0x210.")
def dbc(file: str | None, config_path: str | None, fd: bool | None, node_name: str | None,
        base_id: str | None) -> None:
    """Write a DBC describing the profile's CAN frames (taxels scaled to newtons), or
    with --config one DBC for every CAN node of a bridge."""
    if (file is None) == (config_path is None):
        raise click.UsageError("give a profile FILE or --config BRIDGE.toml")
    if config_path is not None:
        if fd is not None or node_name is not None or base_id is not None:
            raise click.UsageError("--fd, --node-name and --base-id go with a profile FILE; with --config each "
                                   "[[node]] gives its own (name, fd, base_id)")
        from .dbc_plant import plant_dbc

        click.echo(plant_dbc(config_path), nl=False)
        return
    from ..bus.can.dbc import dbc_text
    from ..bus.can.layout import CanLayout

    assert file is not None
    p = load_profile(file)
    if base_id is not None:
        p = _with_base_id(p, base_id)
    click.echo(dbc_text(p, CanLayout.from_profile(p, fd=fd), node_name=node_name), nl=False)


def _with_base_id(p: Profile, text: str) -> Profile:
    import dataclasses

    try:
        value = int(text, 0)
    except ValueError:
        raise click.BadParameter(f"expected an integer such as 0x210, got {text!r}", param_hint="--base-id") from None
    try:
        return dataclasses.replace(p, can=dataclasses.replace(p.can, base_id=value))
    except ValueError as exc:  # not a number, or an ID range past the format's last ID
        raise click.BadParameter(str(exc).removeprefix("base_id: "), param_hint="--base-id") from None


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
