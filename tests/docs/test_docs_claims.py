"""What README.md, docs/*.md, the shipped example files and the help pages claim about
the command line, checked against the command line itself (in this process, no
install: tests/docs/test_docs_run.py runs the commands from a wheel).

- every ``eskin-bus`` command they show names a command that exists, with options it has;
- an option named in the prose of the bridge's pages is the bridge's (or that of a
  command the same paragraph names);
- no command, help page or shipped file points into a checkout (``profiles/*.toml``,
  ``examples/...``): from an install those paths do not exist;
- the register block's size is the code's (IMAGE_COUNT), wherever an example counts it.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

import click
import pytest

from eskin_industrial.cli import main
from eskin_industrial.outputs.plc.image import IMAGE_COUNT
from tests.helpers.doc_commands import all_blocks, inline_commands, invocations, pages, prose
from tests.helpers.paths import ROOT

PACKAGE_DATA = ROOT / "eskin_industrial" / "data"
#: A path only a checkout has: a profile file of the repository or an example by its folder.
CHECKOUT_PATH = re.compile(r"(?<![\w/.-])(profiles/[\w.-]+\.toml|examples/[\w./-]+)")


def _commands() -> Iterator[tuple[str, str]]:
    """(where, command line) of every command the pages show, fenced or inline."""
    for block in all_blocks():
        for command in block.commands:
            yield block.where, command
    for page in pages():
        for line, span in inline_commands(page):
            yield f"{page.relative_to(ROOT)}:{line}", span


def _resolve(args: list[str]) -> tuple[click.Command, list[str], str]:
    """The command an argument list reaches, the arguments left, its path."""
    cmd: click.Command = main
    path = ["eskin-bus"]
    rest = list(args)
    while isinstance(cmd, click.Group):
        while rest and rest[0].startswith("-"):  # global options before the subcommand
            _check_option(cmd, rest.pop(0), " ".join(path))
        if not rest or rest[0] not in cmd.commands:
            break
        path.append(rest[0])
        cmd = cmd.commands[rest.pop(0)]
    return cmd, rest, " ".join(path)


def _options(cmd: click.Command) -> set[str]:
    return {o for p in cmd.params for o in (*getattr(p, "opts", []), *getattr(p, "secondary_opts", []))} | \
        {"-h", "--help"}


def _check_option(cmd: click.Command, word: str, path: str) -> None:
    name = word.split("=", 1)[0]
    if re.fullmatch(r"-[a-zA-Z]{2,}", name) and len(set(name[1:])) == 1:
        name = name[:2]  # -vv
    assert name in _options(cmd), f"{path} has no option {name}"


def _check_invocation(args: list[str]) -> None:
    cmd, rest, path = _resolve(args)
    if isinstance(cmd, click.Group) and rest and not rest[0].startswith("-") and not rest[0].isupper():  # CMD
        raise AssertionError(f"{path} has no subcommand {rest[0]!r}")
    for word in rest:
        if word.startswith("-") and word != "-" and not re.fullmatch(r"-\d.*", word):
            _check_option(cmd, word, path)


def test_every_documented_command_exists_with_its_options() -> None:
    problems = []
    seen = 0
    for where, command in _commands():
        for args in invocations(command):
            seen += 1
            try:
                _check_invocation(args)
            except AssertionError as exc:
                problems.append(f"{where}: {command}\n    {exc}")
    assert seen > 60  # the pages do show commands
    assert not problems, "\n".join(problems)


#: Pages about the bridge, and where on them (up to a heading): an option their prose
#: names is the bridge's or that of a command the same paragraph names.
BRIDGE_PAGES = {"plc.md": "## Numbering", "operations.md": None}
_OPTION = re.compile(r"`(--[a-z][a-z0-9-]*[a-z0-9])[` =]")
_COMMAND_NAMED = re.compile(r"`(?:eskin-bus )?([a-z][a-z-]*(?: [a-z][a-z-]*)?)[` ]")


def _commands_named(text: str) -> list[click.Command]:
    named = []
    for words in _COMMAND_NAMED.findall(text):
        cmd, rest, _ = _resolve(words.split())
        if cmd is not main and not rest:
            named.append(cmd)
    return named


@pytest.mark.parametrize("page", BRIDGE_PAGES)
def test_options_the_bridge_pages_name_are_the_commands(page: str) -> None:
    problems = []
    path = ROOT / "docs" / page
    until = BRIDGE_PAGES[page]
    end = path.read_text().splitlines().index(until) + 1 if until else 10**9
    for line, text in prose(path):
        if line > end:
            break
        owners = [main.commands["bridge"], *_commands_named(text)]
        for option in _OPTION.findall(text):
            if not any(option in _options(c) for c in owners):
                problems.append(f"docs/{page}:{line}: {option} is not an option of "
                                f"{' or '.join(c.name or '?' for c in owners)}")
    assert not problems, "\n".join(problems)


def test_no_documented_command_points_into_a_checkout() -> None:
    found = [f"{where}: {command}" for where, command in _commands() if CHECKOUT_PATH.search(command)
             and not command.startswith(("./scripts/", "scripts/"))]
    assert not found, "from an install these paths do not exist:\n" + "\n".join(found)


def _help_pages(cmd: click.Command, path: list[str]) -> Iterator[tuple[str, str]]:
    with click.Context(cmd, info_name=" ".join(path)) as ctx:
        yield " ".join(path), cmd.get_help(ctx)
    if isinstance(cmd, click.Group):
        for name, sub in cmd.commands.items():
            yield from _help_pages(sub, [*path, name])


def test_no_help_page_points_into_a_checkout() -> None:
    found = [f"{path}: {m.group(0)}" for path, text in _help_pages(main, ["eskin-bus"])
             for m in CHECKOUT_PATH.finditer(text.replace("\n", " "))]
    assert not found, "\n".join(found)


def test_no_shipped_file_points_into_a_checkout() -> None:
    found = [f"{p.relative_to(ROOT)}: {m.group(0)}" for p in sorted(PACKAGE_DATA.rglob("*"))
             if p.is_file() and p.suffix not in (".csv", ".npz")  # (data, no text: the learned model)
             for m in CHECKOUT_PATH.finditer(p.read_text())]
    assert not found, "\n".join(found)


def test_profile_init_writes_no_checkout_path(tmp_path: Path) -> None:
    from click.testing import CliRunner

    for name in ("paper-5x5", "hand-4x5", "strip-1x5"):
        out = tmp_path / f"{name}.toml"
        done = CliRunner().invoke(main, ["profile", "init", name, "-o", str(out)])
        assert done.exit_code == 0, done.output
        assert not CHECKOUT_PATH.search(out.read_text()), CHECKOUT_PATH.search(out.read_text())


# -- the register block's size -------------------------------------------------------

_RANGE = re.compile(r"base_address = (\d+)\s*# holding registers (\d+)\.\.(\d+) \(4(\d{4})\.\.4(\d{4})\)")


def test_example_register_ranges_are_the_codes_block() -> None:
    checked = 0
    for path in sorted((PACKAGE_DATA / "deploy").glob("*.toml")):
        for m in _RANGE.finditer(path.read_text()):
            base, first, last, ref_first, ref_last = (int(g) for g in m.groups())
            assert (first, last) == (base, base + IMAGE_COUNT - 1), f"{path.name}: {m.group(0)}"
            assert (ref_first, ref_last) == (first + 1, last + 1), f"{path.name}: {m.group(0)}"
            checked += 1
    assert checked >= 2


def test_documented_block_reads_and_counts_are_the_codes() -> None:
    """mbpoll reading a whole block from its start (-r 1) reads IMAGE_COUNT registers;
    a sentence that gives the block's size gives IMAGE_COUNT."""
    reads, sizes = 0, 0
    for page in pages():
        text = page.read_text()
        for m in re.finditer(r"mbpoll [^`\n]*-r 1 [^`\n]*-c (\d+)", text):
            assert int(m.group(1)) == IMAGE_COUNT, f"{page.name}: {m.group(0)}"
            reads += 1
        for m in re.finditer(r"(?:register block \(|block is now )(\d+) registers", text):
            assert int(m.group(1)) == IMAGE_COUNT, f"{page.name}: {m.group(0)}"
            sizes += 1
    assert reads >= 1 and sizes >= 2
