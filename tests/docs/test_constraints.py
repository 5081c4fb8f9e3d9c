"""constraints.txt pins every extra as tested: each distribution an extra adds to the
runtime (its requirements, followed through this environment's installed metadata)
is pinned at the version installed here, the one the tests ran with.  The runtime
pins themselves are checked against a fresh install by tests/docs/test_packaging.py."""

from __future__ import annotations

import importlib.metadata as md
import re

import pytest
from packaging.requirements import Requirement

from tests.helpers.paths import ROOT

EXTRAS = ("plot", "learn", "opcua", "web")


def norm(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def pins() -> dict[str, str]:
    found = {}
    for line in (ROOT / "constraints.txt").read_text().splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            name, _, version = line.partition("==")
            found[norm(name)] = version
    return found


def closure(requirements: list[str]) -> dict[str, str]:
    """name -> installed version of these requirements and all they require."""
    seen: dict[str, str] = {}
    todo = [Requirement(r) for r in requirements]
    while todo:
        req = todo.pop()
        if norm(req.name) in seen or (req.marker is not None and not req.marker.evaluate({"extra": ""})):
            continue
        dist = md.distribution(req.name)
        seen[norm(req.name)] = dist.version
        todo += [Requirement(r) for r in dist.requires or []]
    return seen


def extra_requirements(extra: str) -> list[str]:
    reqs = [Requirement(r) for r in md.distribution("eskin-industrial").requires or []]
    return [f"{r.name}{r.specifier}" for r in reqs if r.marker is not None and r.marker.evaluate({"extra": extra})]


@pytest.mark.parametrize("extra", EXTRAS)
def test_every_extra_is_pinned_as_tested(extra):
    runtime = closure([f"{r.name}{r.specifier}" for r in map(Requirement, md.distribution("eskin-industrial").requires or [])
                       if r.marker is None])
    wanted = {n: v for n, v in closure(extra_requirements(extra)).items() if n not in runtime}
    assert wanted, f"the extra {extra!r} adds nothing?"
    pinned = pins()
    assert {n: pinned.get(n) for n in wanted} == wanted, f"constraints.txt: the {extra} extra's pins are not the tested versions"
