"""The docs from the install: ``eskin-bus docs`` lists and shows the pages of docs/
(package data), every "docs/X.md" a help page names is one of its topics, and the
help, --version and the metadata say where the docs are."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import click
from click.testing import CliRunner

from eskin_industrial.cli import main
from eskin_industrial.cli.docs_cmd import DOCS_LINE, DOCS_URL, topics
from tests.helpers.paths import ROOT

_REFERENCE = re.compile(r"\bdocs/([a-z][\w-]*\.md)\b")  # (docs/TOPIC.md: a placeholder)


def _pages(group: click.Group, ctx: click.Context | None = None, path: tuple[str, ...] = ("eskin-bus",)):
    """Every help page, as the user sees it, by its command path."""
    here = click.Context(group, info_name=path[-1], parent=ctx)
    yield path, group.get_help(here)
    for name, cmd in getattr(group, "commands", {}).items():
        yield from _pages(cmd, here, (*path, name))


def _run(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "eskin_industrial", *args], capture_output=True, text=True,
                          timeout=60, env={**os.environ, **(env or {})})


def test_every_page_a_help_names_is_a_topic_of_eskin_bus_docs() -> None:
    known = set(topics())
    named = {}
    for path, page in _pages(main):
        for ref in _REFERENCE.findall(page.replace("\n", " ")):
            named.setdefault(ref, " ".join(path))
    assert len(named) >= 5, named  # (docs/cli.md, plc.md, opcua.md, web.md, ...: the pattern finds them)
    unknown = {ref: where for ref, where in named.items() if ref.removesuffix(".md") not in known}
    assert not unknown, f"help pages name pages eskin-bus docs does not know: {unknown}"
    # and each prints as the page itself
    for ref in named:
        shown = CliRunner().invoke(main, ["docs", ref.removesuffix(".md")])
        assert shown.exit_code == 0 and shown.output == (ROOT / "docs" / ref).read_text(encoding="utf-8")


def test_the_topics_are_the_pages_of_docs_with_their_titles() -> None:
    listed = _run("docs")
    assert listed.returncode == 0, listed.stderr
    pages = sorted(p.stem for p in (ROOT / "docs").glob("*.md"))
    rows = [line.split(None, 1) for line in listed.stdout.splitlines() if line and not line.startswith("Show")]
    assert [name for name, _ in rows] == pages
    assert dict(rows)["plc"] == (ROOT / "docs" / "plc.md").read_text().splitlines()[0].removeprefix("# ")
    # plc, plc.md and docs/plc.md, as a help page names it, are one topic; piped, the page as it is
    for name in ("plc", "plc.md", "docs/plc.md"):
        shown = _run("docs", name)
        assert shown.returncode == 0 and shown.stdout == (ROOT / "docs" / "plc.md").read_text(), name


def test_an_unknown_topic_is_one_line_naming_the_known_ones_and_exit_2() -> None:
    done = _run("docs", "plcs")
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.count("\n") == 1 and "no topic 'plcs'" in done.stderr
    assert all(name in done.stderr for name in topics())


def test_a_terminal_gets_the_page_through_the_pager(tmp_path: Path) -> None:
    """On a terminal (a pseudo-terminal here) the page goes through $PAGER, as git's do."""
    import pty

    seen = tmp_path / "paged.md"
    pager = tmp_path / "pager"
    pager.write_text(f"#!/bin/sh\ncat > {seen}\n")
    pager.chmod(0o755)
    pid, fd = pty.fork()
    if pid == 0:  # the child: stdout is the terminal
        os.environ.update(PAGER=str(pager), TERM="dumb")
        os.execv(sys.executable, [sys.executable, "-m", "eskin_industrial", "docs", "can"])
    output = b""
    while True:
        try:
            chunk = os.read(fd, 65536)
        except OSError:
            break
        if not chunk:
            break
        output += chunk
    _, status = os.waitpid(pid, 0)
    assert os.waitstatus_to_exitcode(status) == 0, output
    assert seen.read_text().strip() == (ROOT / "docs" / "can.md").read_text().strip()


def test_open_hands_the_page_to_the_browser(tmp_path: Path) -> None:
    """``--open``: Python's webbrowser, which runs $BROWSER with the page's file URL."""
    got = tmp_path / "url"
    browser = tmp_path / "browser"
    browser.write_text(f"#!/bin/sh\necho \"$1\" > {got}\n")
    browser.chmod(0o755)
    done = _run("docs", "plc", "--open", env={"BROWSER": str(browser)})
    assert done.returncode == 0, done.stderr
    url = got.read_text().strip()
    assert url.startswith("file://") and url.endswith("/docs/plc.md")
    assert Path(url.removeprefix("file://")).read_text() == (ROOT / "docs" / "plc.md").read_text()


def test_help_version_and_metadata_say_where_the_docs_are() -> None:
    urls = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["urls"]
    assert set(urls) == {"Homepage", "Documentation", "Source", "Issues", "Changelog"}
    assert urls["Documentation"] == DOCS_URL
    assert len({u.split("/tree/")[0].split("/issues")[0].split("/commits")[0] for u in urls.values()}) == 1
    version = _run("--version")
    assert version.returncode == 0 and version.stdout.splitlines()[-1] == DOCS_LINE
    for path, page in _pages(main):
        assert page.rstrip().splitlines()[-1].strip() == DOCS_LINE, path  # one line, unwrapped


def test_the_package_holds_the_pages_it_lists() -> None:
    """In a checkout the package's pages are docs/ itself (a link): one source.  (The
    wheel holds copies: tests/docs/test_packaging.py.)"""
    import eskin_industrial

    assert (Path(eskin_industrial.__file__).parent / "docs").resolve() == (ROOT / "docs").resolve()
