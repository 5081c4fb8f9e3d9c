"""``eskin-bus examples``: the example deployment files shipped in the package."""

from __future__ import annotations

import shutil
from pathlib import Path

import click

#: bridge.toml, the fingertip-strip hand, the systemd unit (package data)
DEPLOY_DIR = Path(__file__).resolve().parents[1] / "data" / "deploy"


def _first_line(path: Path) -> str:
    """A file's first comment line, as its one-line description."""
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.startswith("#"):
            return line.lstrip("# ").strip().rstrip(",:")
    return ""


@click.command()
@click.option("-o", "--output", "out_dir", type=click.Path(file_okay=False), default=None,
              help="Copy the files into this folder (made if missing) instead of listing them.")
@click.option("--force", is_flag=True, help="Overwrite files that exist there.")
def examples(out_dir: str | None, force: bool) -> None:
    """List the example deployment files (a bridge configuration, the fingertip-strip
    hand, a systemd unit), or copy them out with -o DIR to edit for a cell.  Their
    profiles are built-in names, so the copies work from any folder."""
    files = sorted(p for p in DEPLOY_DIR.iterdir() if p.is_file())
    if out_dir is None:
        for path in files:
            click.echo(f"{path.name:<26} {_first_line(path)}")
        return
    target = Path(out_dir)
    clash = [target / p.name for p in files if (target / p.name).exists()]
    if clash and not force:
        raise click.UsageError(f"{clash[0]}: exists; give --force to overwrite")
    try:
        target.mkdir(parents=True, exist_ok=True)
        for path in files:
            shutil.copyfile(path, target / path.name)
    except OSError as exc:
        raise click.UsageError(f"{target}: cannot write: {exc.strerror or exc}") from None
    click.echo(f"{target}: {', '.join(p.name for p in files)}; check with "
               f"`eskin-bus bridge --config {target / 'bridge.toml'} --check`")
