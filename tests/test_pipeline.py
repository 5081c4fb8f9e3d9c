from __future__ import annotations

import ast
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from eskin_industrial.calibration import Calibrator
from eskin_industrial.detect import GraspState, get_method, paper_batch
from eskin_industrial.detect.settings import LearnedSettings
from eskin_industrial.frames import RawScan
from eskin_industrial.pipeline import Pipeline
from tests.helpers.scenes import grasp


def test_raw_scans_give_the_offline_answer(paper_profile):
    f = grasp(600, seed=9)
    f[:100] = 0.0
    cal = Calibrator.from_section(paper_profile.calibration, 25)
    raw = np.rint(cal.to_raw(f))  # what the node sends: integer 0.1 ohm units
    pipe = Pipeline(paper_profile, method="paper")
    t = np.arange(600) / 100.0
    updates = []
    for k in range(600):
        if k in (300, 301):  # two scans lost on the way
            continue
        updates += pipe.push(RawScan(seq=k, t=t[k], raw=raw[k]))
    assert pipe.counters.lost_scans == 2 and pipe.counters.scans == 598
    keep = np.ones(600, bool)
    keep[[300, 301]] = False
    x, y = paper_profile.coordinates_mm
    forces, _ = cal.to_newtons(raw)
    offline = paper_batch(paper_profile.detector, x, y, 100.0, t[keep], forces[keep])
    assert len(updates) == len(offline)
    np.testing.assert_allclose([u.r_coe for u in updates], offline.r_coe, atol=1e-9)
    np.testing.assert_array_equal([u.state for u in updates], offline.state)
    assert updates[0].state == GraspState.NO_CONTACT and updates[-1].state != GraspState.NO_CONTACT
    assert pipe.last_update is updates[-1]
    changes = int(np.count_nonzero(np.diff(offline.state)))  # the first state is no change
    assert pipe.counters.state_changes == changes


def test_a_method_that_needs_a_model_is_handed_it(paper_profile):
    # the registry's learned factory cannot build without a model (detect/ never trains)
    x, y = paper_profile.coordinates_mm
    assert get_method("learned").needs_model
    with pytest.raises(TypeError, match="model"):
        get_method("learned").stream(paper_profile.detector, x, y, 100.0)
    # a model that always says slip: the pipeline runs it, and slip is read once trusted
    always_slip = lambda _x: np.array([0.0, 0.0, 1.0])  # noqa: E731
    pipe = Pipeline(paper_profile, method="learned", model=always_slip)
    f = grasp(300, seed=9)
    cal = Calibrator.from_section(paper_profile.calibration, 25)
    raw = np.rint(cal.to_raw(f))
    states = [u.state for k in range(300) for u in pipe.push(RawScan(seq=k, t=k / 100.0, raw=raw[k]))]
    assert states[0] == GraspState.STABLE and states[-1] == GraspState.SLIP



def test_the_learned_decision_rule_comes_from_the_profile(paper_profile):
    # a model 60 % sure of slip: slip at the default slip_p 0.5, never at 0.7
    unsure = lambda _x: np.array([0.2, 0.2, 0.6])  # noqa: E731
    f = grasp(300, seed=9)
    raw = np.rint(Calibrator.from_section(paper_profile.calibration, 25).to_raw(f))

    def states(profile):
        pipe = Pipeline(profile, method="learned", model=unsure)
        return {u.state for k in range(300) for u in pipe.push(RawScan(seq=k, t=k / 100.0, raw=raw[k]))}

    strict = replace(paper_profile, detector=replace(paper_profile.detector,
                                                      learned=LearnedSettings(slip_p=0.7)))
    assert GraspState.SLIP in states(paper_profile)
    assert GraspState.SLIP not in states(strict)

ROOT = Path(__file__).resolve().parent.parent / "eskin_industrial"


def _imports(path: Path, module: str) -> set[str]:
    """Modules of the package ``path`` imports, anywhere in it (functions too), resolved;
    not those under ``if TYPE_CHECKING:`` (a name for the type checker loads nothing)."""
    package = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
    found = set()
    tree = ast.parse(path.read_text())
    for block in ast.walk(tree):
        if isinstance(block, ast.If) and isinstance(block.test, ast.Name) and block.test.id == "TYPE_CHECKING":
            block.body = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            base = package[:len(package) - node.level + 1] if node.level else []
            name = ".".join(base + ([node.module] if node.module else []))
            found |= {name} | {f"{name}.{a.name}" for a in node.names}
        elif isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
    return {n for n in found if n.startswith("eskin_industrial")}


def _graph() -> dict[str, set[str]]:
    modules = {}
    for path in ROOT.rglob("*.py"):
        parts = ("eskin_industrial",) + path.relative_to(ROOT).with_suffix("").parts
        modules[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    graph = {}
    for name, path in modules.items():
        edges = set()
        for target in _imports(path, name):
            while target not in modules:  # "from .m import f": the module is m
                target = target.rpartition(".")[0]
            if target != name:
                edges.add(target)
        graph[name] = edges
    return graph


def test_the_numeric_core_imports_nothing_above_it():
    allowed = ("eskin_industrial.detect", "eskin_industrial.frames", "eskin_industrial.errors", "eskin_industrial.schema")
    outside = {(m, t) for m, edges in _graph().items() if m.startswith("eskin_industrial.detect")
               for t in edges if not t.startswith(allowed)}
    assert outside == set()


def test_the_package_has_no_import_cycle():
    graph = _graph()
    done: set[str] = set()

    def visit(node: str, path: tuple[str, ...]) -> None:
        assert node not in path, " -> ".join(path[path.index(node):] + (node,))
        if node in done:
            return
        for target in graph[node]:
            visit(target, path + (node,))
        done.add(node)

    for node in graph:
        visit(node, ())
