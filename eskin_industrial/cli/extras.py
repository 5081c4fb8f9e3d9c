"""What ``bridge --check`` finds missing of the optional dependencies: an output kind
or a detection method a configuration names whose extra ([project.optional-dependencies]
in pyproject.toml) is not installed, found before the run, which would otherwise stop
at opening it (exit 4, as there)."""

from __future__ import annotations

import importlib
from collections.abc import Iterable

from ..errors import MissingExtra

#: What needs an extra: (what, name) -> (the module it imports, the extra that installs it).
#: The sparkplug output's paho-mqtt and the PLC's pymodbus are in the base install; the
#: learned method runs on its shipped model (scikit-learn only trains it); ``plot`` and
#: ``evaluate --charts`` are commands, which say so when run.
NEEDS: dict[tuple[str, str], tuple[str, str]] = {
    ("output", "opcua"): ("asyncua", "opcua"),
    ("output", "web"): ("aiohttp", "web"),
}


def importable(module: str) -> bool:
    """The module imports here (as the run would import it: a broken install, a
    missing shared library, counts as missing too)."""
    try:
        importlib.import_module(module)
    except ImportError:
        return False
    return True


def missing_extras(used: Iterable[tuple[str, str]]) -> list[tuple[str, str, str]]:
    """(what, name, extra) for each used thing whose extra's module does not import."""
    out = []
    for what, name in dict.fromkeys(used):
        need = NEEDS.get((what, name))
        if need is not None and not importable(need[0]):
            out.append((what, name, need[1]))
    return out


def check_extras(used: Iterable[tuple[str, str]]) -> None:
    """One line for all of them: ``the opcua output needs the extra opcua: pip install
    'eskin-industrial[opcua]'`` (quoted for zsh), exit 4."""
    missing = missing_extras(used)
    if not missing:
        return
    extras = list(dict.fromkeys(extra for _, _, extra in missing))
    things = " and ".join(f"the {name} {what}" for what, name, _ in missing)
    noun = "the extra" if len(extras) == 1 else "the extras"
    raise MissingExtra(f"{things} {'needs' if len(missing) == 1 else 'need'} {noun} {', '.join(extras)}: "
                       f"pip install 'eskin-industrial[{','.join(extras)}]'")
