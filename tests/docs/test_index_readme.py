"""The description a package index shows (README.index.md, pyproject's ``readme``):
written from README.md by scripts/index-readme, current, rendered as twine check
renders it (readme_renderer), and with no link that goes nowhere away from the
checkout."""

from __future__ import annotations

import importlib.machinery
import importlib.util
import re
import subprocess
import sys
import tomllib
from html.parser import HTMLParser
from types import ModuleType

import readme_renderer.markdown

from tests.helpers.paths import ROOT

SCRIPT = ROOT / "scripts" / "index-readme"


def _script() -> ModuleType:
    loader = importlib.machinery.SourceFileLoader("index_readme", str(SCRIPT))
    spec = importlib.util.spec_from_loader("index_readme", loader)
    assert spec is not None
    module = importlib.util.module_from_spec(spec)
    loader.exec_module(module)
    return module


class _Links(HTMLParser):
    """Every href and src of a page, and the ids it defines."""

    def __init__(self) -> None:
        super().__init__()
        self.targets: list[str] = []
        self.ids: set[str] = set()

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        for name, value in attrs:
            if name in ("href", "src") and value is not None:
                self.targets.append(value)
            elif name == "id" and value is not None:
                self.ids.add(value)


def _broken(html: str) -> list[str]:
    """The links and images of a rendered page that lead nowhere on an index: relative
    paths, and anchors to no id of the page."""
    page = _Links()
    page.feed(html)
    return [t for t in page.targets
            if not re.match(r"^[A-Za-z][A-Za-z0-9+.-]*:", t) and not (t.startswith("#") and t[1:] in page.ids)]


def test_the_index_description_is_current() -> None:
    done = subprocess.run([sys.executable, str(SCRIPT), "--check"], capture_output=True, text=True, timeout=30)
    assert done.returncode == 0, done.stderr


def test_pyproject_gives_it_as_markdown() -> None:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert project["readme"] == {"file": "README.index.md", "content-type": "text/markdown"}
    # where the docs are, beside the description (Project-URL; the pages are also in the wheel: eskin-bus docs)
    assert {"Homepage", "Documentation", "Source", "Issues"} <= set(project["urls"])


def test_it_renders_with_no_link_that_goes_nowhere() -> None:
    readme = (ROOT / "README.md").read_text()
    assert _broken(readme_renderer.markdown.render(readme)), "README.md itself has relative links: the check sees them"
    index = (ROOT / "README.index.md").read_text()
    html = readme_renderer.markdown.render(index)  # (None: it does not render, as twine check says)
    assert html is not None and "<h1" in html
    assert _broken(html) == []
    assert "Written by scripts/index-readme" not in html  # the comment for editors stays out of the page
    # nothing lost: every file README.md links to is still named
    for path in set(re.findall(r"\]\((docs/[^)#]+)", readme)):
        assert f"<code>{path}</code>" in html, path


def test_links_images_anchors_and_code() -> None:
    readme = (
        "# t\n\n"
        "See [the map](docs/plc.md#status), [docs/can.md](docs/can.md), [home](https://example.org/x),\n"
        "[up](#layout), [`docs/cli.md`](<docs/cli.md>) and ![chart](docs/img/a.png \"a title\").\n\n"
        "```sh\necho '[not](a/link)'\n```\n\n"
        "[after](docs/method.md)\n"
    )
    got = _script().index_description(readme)
    header, title, blank, note, *body = got.splitlines()
    assert header.startswith("<!--") and title == "# t" and blank == "" and "source distribution" in note
    assert "\n".join(body) == (
        "\n"
        "See the map (`docs/plc.md`), `docs/can.md`, [home](https://example.org/x),\n"
        "up, `docs/cli.md` and chart (image: `docs/img/a.png`).\n\n"
        "```sh\necho '[not](a/link)'\n```\n\n"
        "after (`docs/method.md`)"
    )
    assert _broken(readme_renderer.markdown.render(got) or "") == []
