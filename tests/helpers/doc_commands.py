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

Every other ``sh`` block runs (tests/docs/test_docs_run.py).  What its text claims a
block gives is marked with ``expect=`` (repeatable; quoted with spaces, as in a shell),
and checked after it ran, in an empty folder, as well as its exit status::

    ```sh expect="out:slip events 1"     the block's output (stdout or stderr) holds this text
    ```sh expect=file:cell.toml          the block wrote this file, not empty
    ```sh expect=png:hand.png            the block wrote this PNG image
    ```sh expect=grep:out.csv:,slip,     this file holds this text
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

#: The kinds of claim an ``expect=`` makes (checked by :func:`unmet`).
EXPECTS = ("out", "file", "png", "grep")

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
    expects: tuple[str, ...] = ()

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
            words = [w.split("=", 1) for w in shlex.split(rest) if "=" in w]
            needs = next((v for k, v in words if k == "needs"), None)
            if needs is not None and needs not in NEEDS:
                raise ValueError(f"{page.name}:{i + 1}: needs={needs}: not one of {', '.join(NEEDS)}")
            expects = tuple(v for k, v in words if k == "expect")
            for e in expects:
                if e.partition(":")[0] not in EXPECTS or not e.partition(":")[2]:
                    raise ValueError(f"{page.name}:{i + 1}: expect={e}: not one of {', '.join(EXPECTS)} with a value")
            found.append(Block(page, i + 1, needs, _commands(lines[i + 1:end]), expects))
        i = end + 1
    return found


def unmet(expects: tuple[str, ...], output: str, folder: Path) -> list[str]:
    """The claims of ``expects`` that the block's ``output`` and the files it left in
    ``folder`` do not bear out, each said in one line."""
    failed: list[str] = []
    for e in expects:
        kind, _, value = e.partition(":")
        if kind == "out":
            if value not in output:
                failed.append(f"output lacks {value!r}")
            continue
        name, _, text = value.partition(":") if kind == "grep" else (value, "", "")
        path = folder / name
        if not path.is_file() or path.stat().st_size == 0:
            failed.append(f"{name}: not written")
        elif kind == "png" and path.read_bytes()[:8] != b"\x89PNG\r\n\x1a\n":
            failed.append(f"{name}: not a PNG image")
        elif kind == "grep" and text not in path.read_text(errors="replace"):
            failed.append(f"{name}: lacks {text!r}")
    return failed


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
