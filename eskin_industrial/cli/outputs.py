"""Command-line options of the output kinds, built from what each kind declares
(:attr:`eskin_industrial.outputs.base.OutputKind.cli_options`), and read back into options."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

import click

from ..outputs.base import CliOption, output_kind, sink_kinds

F = TypeVar("F", bound=Callable[..., Any])


def _all_cli_options(kind: str) -> tuple[CliOption, ...]:
    cls = output_kind(kind)
    return cls.cli_options + cls.node_cli_options


def output_options(func: F) -> F:
    """Every output kind's options (its section's and a one-node bridge's node keys),
    in registry order."""
    return _options(func, list(sink_kinds()))


def kind_options(*kinds: str) -> Callable[[F], F]:
    """The options of these output kinds only, for a command that runs its own chain
    and takes some outputs beside it (``demo --web``, ``monitor --web``)."""
    return lambda func: _options(func, list(kinds))


def _options(func: F, kinds: list[str]) -> F:
    opts = []
    for kind in kinds:
        for o in _all_cli_options(kind):
            if o.secret:
                continue  # secrets come from files or the environment, never argv
            if o.type is bool:
                opts.append(click.option(o.flag, o.dest, is_flag=True, default=bool(o.default), help=o.help))
                continue
            typ: Any = click.Choice(list(o.choices)) if o.choices else o.type
            opts.append(click.option(o.flag, o.dest, type=typ, default=o.default, metavar=o.metavar,
                                     show_default=o.default is not None, help=o.help))
    for opt in reversed(opts):
        func = opt(func)
    return func


def outputs_from_cli(values: dict[str, Any], kinds: tuple[str, ...] | None = None) -> dict[str, Any]:
    """``kind -> options`` for every kind asked for on the command line (of ``kinds``
    only, when given: the ones :func:`kind_options` added)."""
    out = {}
    for kind in kinds or sink_kinds():
        cls = output_kind(kind)
        try:
            options = cls.options_from_cli(values)
        except ValueError as exc:
            flag = cls.cli_options[0].flag if cls.cli_options else f"[{kind}]"
            raise click.BadParameter(str(exc), param_hint=flag) from None
        if options is not None:
            out[kind] = options
    return out


def node_outputs_from_cli(values: dict[str, Any]) -> dict[str, Any]:
    """``kind -> node options`` of a one-node bridge (``--base-address``)."""
    out = {}
    for kind in sink_kinds():
        cls = output_kind(kind)
        try:
            options = cls.node_options_from_cli(values)
        except ValueError as exc:
            flag, _, rest = str(exc).partition(": ")
            raise click.BadParameter(rest or str(exc), param_hint=flag if rest else None) from None
        if options is not None:
            out[kind] = options
    return out


def given_output_options(values: dict[str, Any]) -> list[str]:
    """The output flags given a value other than their default (for refusing them next
    to ``--config``)."""
    given = []
    for kind in sink_kinds():
        for o in _all_cli_options(kind):
            if values.get(o.dest) not in (None, o.default, False):
                given.append(o.flag)
    return given
