"""The top-level commands, each imported from its module when first asked for."""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterator, MutableMapping

import click


class LazyCommands(MutableMapping[str, click.Command]):
    """A group's ``commands``: ``name -> (module, attribute)``, the module relative to
    ``package``.  A command is imported, then handed to ``dress`` (once), the first time
    it is looked up; anything that walks the mapping (a help page, the completion, a
    test) loads every command first, so it sees what an eager group would."""

    def __init__(self, package: str, table: dict[str, tuple[str, str]],
                 dress: Callable[[str, click.Command], None]) -> None:
        self._package = package
        self._table = dict(table)
        self._dress = dress
        self._loaded: dict[str, click.Command] = {}

    def _load(self, name: str) -> None:
        if name in self._loaded or name not in self._table:
            return
        module, attribute = self._table[name]
        cmd = getattr(importlib.import_module(f"{self._package}.{module}"), attribute)
        self._dress(name, cmd)
        self._loaded[name] = cmd

    def __getitem__(self, name: str) -> click.Command:
        self._load(name)
        return self._loaded[name]

    def __setitem__(self, name: str, cmd: click.Command) -> None:  # (click's add_command)
        self._loaded[name] = cmd

    def __delitem__(self, name: str) -> None:
        if name not in self:
            raise KeyError(name)
        self._table.pop(name, None)
        self._loaded.pop(name, None)

    def __contains__(self, name: object) -> bool:
        return name in self._table or name in self._loaded

    def __iter__(self) -> Iterator[str]:
        for name in self._table:
            self._load(name)
        return iter(list(self._loaded))

    def __len__(self) -> int:
        return len(self._table.keys() | self._loaded.keys())
