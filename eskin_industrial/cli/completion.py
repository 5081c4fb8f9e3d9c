"""Shell completion: the values the shell offers for scene names, python-can
interfaces and a bridge's ``--source`` (profiles: ``common.complete_profile``), and
``eskin-bus completion SHELL``, the script that wires click's completion into bash,
zsh or fish (the same one ``_ESKIN_BUS_COMPLETE=bash_source eskin-bus`` prints)."""

from __future__ import annotations

from pathlib import Path

import click
from click.shell_completion import CompletionItem, get_completion_class

#: The variable click's completion reads, named after the program.
COMPLETE_VAR = "_ESKIN_BUS_COMPLETE"


def files_for(incomplete: str, suffix: str) -> list[CompletionItem]:
    """Files ending in ``suffix``, and folders to go into, that start with ``incomplete``
    (listed here rather than left to the shell: in click's bash script a "file" item
    clears the names offered before it, so that ``-p pa`` offered no paper-5x5)."""
    folder, _, stem = incomplete.rpartition("/")
    base = Path(folder or ".")
    if not base.is_dir():
        return []
    out = []
    for p in sorted(base.iterdir()):
        if p.name.startswith(stem) and (p.is_dir() or p.name.endswith(suffix)) and not p.name.startswith("."):
            shown = f"{folder}/{p.name}" if folder else p.name
            out.append(CompletionItem(shown + ("/" if p.is_dir() else "")))
    return out


def complete_scene(ctx: click.Context, param: click.Parameter, incomplete: str) -> list[CompletionItem]:
    """A scene: the built-in names (``simulate --list``), then scene files."""
    from ..scenes import list_scenes

    names = [CompletionItem(n, help=about) for n, about in list_scenes().items() if n.startswith(incomplete)]
    return names + files_for(incomplete, ".toml")


def complete_interface(ctx: click.Context, param: click.Parameter, incomplete: str) -> list[CompletionItem]:
    """A python-can interface, by the names python-can itself accepts."""
    from can.interfaces import VALID_INTERFACES

    return [CompletionItem(n) for n in sorted(VALID_INTERFACES) if n.startswith(incomplete)]


def complete_source(ctx: click.Context, param: click.Parameter, incomplete: str) -> list[CompletionItem]:
    """A bridge's ``--source``: its kinds, and after ``scene:`` the scene names."""
    if incomplete.startswith("scene:"):
        return [CompletionItem(f"scene:{c.value}") for c in complete_scene(ctx, param, incomplete[len("scene:"):])]
    from ..bus.source import source_kinds

    kinds = [k if k == "can" else f"{k}:" for k in source_kinds()]
    return [CompletionItem(k) for k in kinds if k.startswith(incomplete)]


@click.command()
@click.argument("shell", type=click.Choice(["bash", "zsh", "fish"]))
@click.pass_context
def completion(ctx: click.Context, shell: str) -> None:
    """Print the shell completion script for SHELL: commands, options, choices, methods,
    profile and scene names, python-can interfaces.  Put it where the shell reads it
    (docs/cli.md), e.g. ``eskin-bus completion bash > ~/.local/share/bash-completion/completions/eskin-bus``."""
    root = ctx.find_root().command
    cls = get_completion_class(shell)
    assert cls is not None  # the three click ships, as the choice says
    click.echo(cls(root, {}, "eskin-bus", COMPLETE_VAR).source(), nl=False)  # (as click prints it)
