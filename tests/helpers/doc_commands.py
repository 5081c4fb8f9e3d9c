"""The shell commands of README.md and docs/*.md, as a user would paste them.

A fenced block whose info string starts with ``sh`` is a list of commands, one per
line (a trailing backslash continues it, ``#`` starts a comment).  Words after ``sh``
mark a block that cannot run from an install in an empty folder, and why
(docs/cli.md, "Commands in these pages")::

    ```sh needs=vcan            a virtual or real CAN interface
    ```sh needs=root            sudo, systemd, /etc or /opt
    ```sh needs=peer            a third-party program or a network peer (mosquitto, an OPC UA client, socat)
    ```sh needs=long            runs until stopped, or minutes
    ```sh needs=checkout        from a checkout of the sources (scripts/, .venv)

Every other ``sh`` block runs (tests/docs/test_docs_run.py).
"""

from __future__ import annotations

import re
import shlex
from dataclasses import dataclass
from pathlib import Path

from tests.helpers.paths import ROOT

#: The reasons a block may be marked with, as the skip message says them.
NEEDS = {
    "vcan": "needs a CAN interface (vcan or hardware)",
    "root": "needs root (sudo, systemd, /etc, /opt)",
    "peer": "needs a third-party program or a network peer",
    "long": "runs until stopped, or for minutes",
    "checkout": "needs a checkout of the sources",
}

_FENCE = re.compile(r"^(\s*)```+\s*(\S*)\s*(.*)$")
_SPAN = re.compile(r"`([^`\n]+)`")


def pages() -> list[Path]:
    return [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


@dataclass(frozen=True)
class Block:
    """One ``sh`` block: where, what it needs (None: it runs), its command lines."""

    page: Path
    line: int  # 1-based, of the opening fence
    needs: str | None
    commands: tuple[str, ...]

    @property
    def where(self) -> str:
        return f"{self.page.relative_to(ROOT)}:{self.line}"


def _commands(lines: list[str]) -> tuple[str, ...]:
    out: list[str] = []
    pending = ""
    for raw in lines:
        line = raw.strip()
        if line.endswith("\\"):
            pending += line[:-1] + " "
            continue
        line = (pending + line).strip()
        pending = ""
        if line and not line.startswith("#"):
            out.append(line)
    return tuple(out)


def blocks(page: Path) -> list[Block]:
    found: list[Block] = []
    lines = page.read_text(encoding="utf-8").splitlines()
    i = 0
    while i < len(lines):
        m = _FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        lang, rest = m.group(2), m.group(3)
        end = next(j for j in range(i + 1, len(lines)) if _FENCE.match(lines[j]))
        if lang == "sh":
            marks = dict(w.split("=", 1) for w in rest.split() if "=" in w)
            needs = marks.get("needs")
            if needs is not None and needs not in NEEDS:
                raise ValueError(f"{page.name}:{i + 1}: needs={needs}: not one of {', '.join(NEEDS)}")
            found.append(Block(page, i + 1, needs, _commands(lines[i + 1:end])))
        i = end + 1
    return found


def all_blocks() -> list[Block]:
    return [b for p in pages() for b in blocks(p)]


def prose(page: Path) -> list[tuple[int, str]]:
    """(line, text) of every paragraph outside code blocks (fenced or indented)."""
    paragraphs: list[tuple[int, str]] = []
    current: list[str] = []
    start = 0
    fenced = False
    for n, line in enumerate(page.read_text(encoding="utf-8").splitlines(), 1):
        if _FENCE.match(line):
            fenced = not fenced
            line = ""
        if fenced or line.startswith("    ") and not current:
            line = ""
        if line.strip():
            if not current:
                start = n
            current.append(line)
        elif current:
            paragraphs.append((start, " ".join(current)))
            current = []
    if current:
        paragraphs.append((start, " ".join(current)))
    return paragraphs


def inline_commands(page: Path) -> list[tuple[int, str]]:
    """(line, span) of every inline code span of the prose that is an eskin-bus command."""
    return [(n, s) for n, text in prose(page) for s in _SPAN.findall(text) if s.startswith("eskin-bus ")]


def invocations(command: str) -> list[list[str]]:
    """The argument lists of the ``eskin-bus`` calls in one command line (after
    ``eskin-bus``), across pipes, ``&&``, ``;`` and ``$(...)``; a path to the program
    (``/opt/.../bin/eskin-bus``) counts."""
    try:
        words = shlex.split(command.replace("$(", " ").replace(")", " "), comments=True)
    except ValueError:  # an unbalanced quote in an inline excerpt: take it word by word
        words = command.split()
    calls: list[list[str]] = []
    current: list[str] | None = None
    for w in words:
        if w in ("|", "||", "&&", ";", "&", ">", "<", "2>", ">>"):
            current = None
            continue
        if w.endswith(";") or w.endswith("&"):
            w = w.rstrip(";&")
            if current is not None and w:
                current.append(w)
            current = None
            continue
        if w == "eskin-bus" or w.endswith("/eskin-bus"):
            current = []
            calls.append(current)
        elif current is not None:
            current.append(w)
    return calls
