"""``eskin-bus examples``: the example files shipped in the package, listed and copied
out, so that every command of the documentation runs from an install, in any folder."""

from __future__ import annotations

import shutil
from pathlib import Path

import click

_DATA = Path(__file__).resolve().parents[1] / "data"
#: bridge.toml, the fingertip-strip hand, the systemd unit (package data)
DEPLOY_DIR = _DATA / "deploy"
#: a recording and its labels, for detect and plot (package data)
RECORDINGS_DIR = _DATA / "examples"

#: Files that cannot say what they are in a comment of their own (CSV).
_ABOUT = {
    "case2.csv": "a recording of the case-2 scene (paper-5x5, 100 Hz, N): eskin-bus detect -p paper-5x5 case2.csv",
    "case2-labels.csv": "the ground truth of case2.csv (t,label), for plot --labels",
}


def example_files() -> dict[str, Path]:
    """Every shipped example file by its name (the names are unique across folders)."""
    files = [p for d in (DEPLOY_DIR, RECORDINGS_DIR) for p in d.iterdir() if p.is_file()]
    return {p.name: p for p in sorted(files, key=lambda p: p.name)}


def _about(path: Path) -> str:
    """A file's one-line description: its first comment line, or what _ABOUT says."""
    if path.name in _ABOUT:
        return _ABOUT[path.name]
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.startswith("#"):
            return line.lstrip("# ").strip().rstrip(",:")
    return ""


def _copy(paths: list[Path], target: Path, force: bool) -> None:
    clash = [target / p.name for p in paths if (target / p.name).exists()]
    if clash and not force:
        raise click.UsageError(f"{clash[0]}: exists; give --force to overwrite")
    try:
        target.mkdir(parents=True, exist_ok=True)
        for path in paths:
            shutil.copyfile(path, target / path.name)
    except OSError as exc:
        raise click.UsageError(f"{target}: cannot write: {exc.strerror or exc}") from None


@click.group(invoke_without_command=True)
@click.option("-o", "--output", "out_dir", type=click.Path(file_okay=False), default=None,
              help="Copy every file into this folder (made if missing) instead of listing them.")
@click.option("--force", is_flag=True, help="Overwrite files that exist there.")
@click.pass_context
def examples(ctx: click.Context, out_dir: str | None, force: bool) -> None:
    """List the example files (a bridge configuration, the fingertip-strip hand, a
    systemd unit, a recording and its labels), or copy them out to edit for a cell:
    ``copy NAME [DIR]`` one of them, ``-o DIR`` all.  Their profiles are built-in
    names, so the copies work from any folder."""
    if ctx.invoked_subcommand is not None:
        return
    files = example_files()
    if out_dir is None:
        for name, path in files.items():
            click.echo(f"{name:<26} {_about(path)}")
        return
    _copy(list(files.values()), Path(out_dir), force)
    click.echo(f"{out_dir}: {', '.join(files)}; check with "
               f"`eskin-bus bridge --config {Path(out_dir) / 'bridge.toml'} --check`")


@examples.command("copy")
@click.argument("name", shell_complete=lambda _c, _p, inc: [n for n in example_files() if n.startswith(inc)])
@click.argument("out_dir", metavar="[DIR]", required=False, default=".",
                type=click.Path(file_okay=False))
@click.option("--force", is_flag=True, help="Overwrite the file if it exists there.")
def copy_cmd(name: str, out_dir: str, force: bool) -> None:
    """Copy the example file NAME (as `eskin-bus examples` lists it, or `all`) into DIR
    (default: the current folder; made if missing)."""
    files = example_files()
    if name != "all" and name not in files:
        raise click.BadParameter(f"{name!r}: no such example; there are {', '.join(files)} (or all)",
                                 param_hint="NAME")
    chosen = list(files.values()) if name == "all" else [files[name]]
    _copy(chosen, Path(out_dir), force)
    click.echo(f"{Path(out_dir) / chosen[0].name if len(chosen) == 1 else out_dir}: written")
