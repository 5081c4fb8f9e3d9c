"""``eskin-bus docs``: the pages of docs/, which travel with the package, listed,
printed or opened, so that every "docs/X.md" a help page names can be read from an
install with no checkout and no network (``eskin-bus docs X``)."""

from __future__ import annotations

import re
import sys
import webbrowser
from pathlib import Path

import click

from ..errors import EskinError

#: The pages (package data: a link to the checkout's docs/, copied into the wheel).
DOCS_DIR = Path(__file__).resolve().parents[1] / "docs"
#: Where the same pages are online ([project.urls] Documentation in pyproject.toml).
DOCS_URL = "https://github.com/eskin-industrial/eskin-industrial/tree/main/docs"
#: The line every help page and --version end with.
DOCS_LINE = f"Docs: eskin-bus docs (or {DOCS_URL})"

_HEADING = re.compile(r"^#\s+(.+?)\s*#*\s*$", re.M)


def topics() -> dict[str, Path]:
    """Every page by its topic, the file's name without .md (docs/plc.md: plc)."""
    return {p.stem: p for p in sorted(DOCS_DIR.glob("*.md"))}


def heading(path: Path) -> str:
    """A page's first heading, its title."""
    found = _HEADING.search(path.read_text(encoding="utf-8"))
    return found.group(1) if found else ""


def topic_of(name: str) -> str:
    """The topic a reference names: ``plc``, ``plc.md`` or ``docs/plc.md`` (an anchor,
    ``plc.md#flags``, names its page)."""
    name = name.partition("#")[0].strip()
    name = name.removeprefix("docs/")
    return name.removesuffix(".md")


def _complete(_ctx: click.Context, _param: click.Parameter, incomplete: str) -> list[str]:
    return [t for t in topics() if t.startswith(incomplete)]


@click.command()
@click.argument("topic", required=False, shell_complete=_complete)
@click.option("--open", "open_", is_flag=True, help="Open the page in a web browser instead (Python's webbrowser: $BROWSER, or the desktop's).")
@click.option("--path", "show_path", is_flag=True, help="Print the page's file name instead (or, with no TOPIC, the folder's).")
def docs(topic: str | None, open_: bool, show_path: bool) -> None:
    """List the documentation's topics, or show the page TOPIC (docs/TOPIC.md):
    printed as it is to a pipe, through a pager ($PAGER, else less) on a terminal."""
    pages = topics()
    if topic is None:
        if open_:
            raise click.UsageError("--open needs a TOPIC")
        if show_path:
            click.echo(str(DOCS_DIR))
            return
        width = max(map(len, pages))
        for name, path in pages.items():
            click.echo(f"{name:<{width}}  {heading(path)}")
        click.echo(f"\nShow one: eskin-bus docs TOPIC (online: {DOCS_URL})")
        return
    name = topic_of(topic)
    if name not in pages:
        raise click.UsageError(f"no topic {topic!r}; the topics: {', '.join(pages)}")
    path = pages[name]
    if show_path:
        click.echo(str(path))
    elif open_:
        if not webbrowser.open(path.as_uri()):
            raise EskinError(f"{path}: no web browser to open it in (set BROWSER); read it with `eskin-bus docs {name}`")
    elif sys.stdout.isatty():
        click.echo_via_pager(path.read_text(encoding="utf-8"))
    else:
        click.echo(path.read_text(encoding="utf-8"), nl=False)
