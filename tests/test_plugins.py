"""Plug-ins by entry point: a distribution of its own (docs/architecture.md's example
source, output and method, taken from the page) is installed by pip into a
throw-away virtual environment, and ``eskin-bus`` there takes its output kind and
its method from the command line and from ``bridge.toml``, ``--check`` included,
while this environment (without the plug-in) refuses both by name.

The throw-away environment sees this one's packages through a ``.pth`` file (the
checkout's ``eskin_industrial`` and its dependencies), so nothing is downloaded; the
plug-in itself is built and installed by pip as any third-party package would be.
"""

from __future__ import annotations

import re
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

from eskin_industrial import methods
from eskin_industrial.detect.methods import Method
from eskin_industrial.errors import ProfileError
from tests.helpers.page_kinds import page_examples
from tests.helpers.paths import PROFILES, ROOT

PYPROJECT = """\
[build-system]
requires = ["flit_core>=3.12,<4"]
build-backend = "flit_core.buildapi"

[project]
name = "eskin-pagekinds"
version = "1.0"
description = "A source, an output and a method for eskin-industrial"

[project.entry-points."eskin_industrial.sources"]
const = "eskin_pagekinds:ConstSource"

[project.entry-points."eskin_industrial.outputs"]
state-log = "eskin_pagekinds:StateLogKind"

[project.entry-points."eskin_industrial.methods"]
peak-shift = "eskin_pagekinds:METHOD"
"""


def run(python: Path | str, *args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return subprocess.run([str(python), "-m", "eskin_industrial", *args], capture_output=True, text=True,
                          timeout=timeout, cwd=ROOT)


@pytest.fixture(scope="module")
def plugin_python(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The python of a throw-away environment with the plug-in package installed."""
    root = tmp_path_factory.mktemp("plugin")
    package = root / "eskin-pagekinds"
    (package / "eskin_pagekinds").mkdir(parents=True)
    (package / "eskin_pagekinds" / "__init__.py").write_text(page_examples())
    (package / "pyproject.toml").write_text(PYPROJECT)
    venv = root / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=120)
    site = next((venv / "lib").glob("python*/site-packages"))
    (site / "host_packages.pth").write_text(f"{ROOT}\n{sysconfig.get_paths()['purelib']}\n")
    python = venv / "bin" / "python"
    subprocess.run([sys.executable, "-m", "pip", "--python", str(python), "install", "--quiet", "--no-deps",
                    "--no-build-isolation", "--no-index", "--disable-pip-version-check", str(package)],
                   check=True, timeout=300, capture_output=True)
    return python


def peak_profile(tmp_path: Path) -> Path:
    path = tmp_path / "peak.toml"
    text = (PROFILES / "paper-5x5.toml").read_text()
    path.write_text(re.sub(r'(?m)^method = "[^"]*"', 'method = "peak-shift"', text, count=1))
    return path


def said(path: Path) -> list[tuple[str, str, str]]:
    """(node, method, state) of each line the plug-in's output wrote."""
    return [(n, m, s) for n, _, m, s in (line.split() for line in path.read_text().splitlines())]


def test_only_the_environment_with_the_plugin_knows_its_kinds(plugin_python, tmp_path):
    profile = str(peak_profile(tmp_path))
    assert "--state-log PATH" in run(plugin_python, "bridge", "--help").stdout
    assert run(plugin_python, "profile", "check", profile).returncode == 0
    here = run(sys.executable, "profile", "check", profile)
    assert here.returncode == 2 and "[detector] method" in here.stderr and "'peak-shift'" in here.stderr
    missing = run(sys.executable, "bridge", "-p", profile, "--source", "scene:case2", "--state-log", "x", "--check")
    assert missing.returncode == 2 and "--state-log" in missing.stderr


def test_the_plugin_output_and_method_from_the_command_line(plugin_python, tmp_path):
    profile, out = str(peak_profile(tmp_path)), tmp_path / "states.log"
    args = ("bridge", "-p", profile, "--source", "scene:case2", "--state-log", str(out))
    check = run(plugin_python, *args, "--check")
    assert check.returncode == 0, check.stderr
    assert "scene case2 -> state-log" in check.stdout and not out.exists()  # --check opens nothing
    res = run(plugin_python, *args, "--duration", "3")
    assert res.returncode == 0, res.stderr
    lines = said(out)
    assert {m for _, m, _ in lines} == {"peak-shift"}
    assert lines[-1][2] == "unknown"  # the stopped bridge's last snapshot claims nothing
    assert {s for _, _, s in lines} - {"unknown"}, lines  # and before it, verdicts


def test_the_plugin_source_output_and_method_from_bridge_toml(plugin_python, tmp_path):
    out = tmp_path / "states.log"
    config = tmp_path / "bridge.toml"
    config.write_text(f'[state-log]\npath = "{out}"\n\n[[node]]\nname = "g"\nprofile = "{peak_profile(tmp_path)}"\n'
                      f'source = "const"\nvalue = 600.0\n')
    check = run(plugin_python, "bridge", "--config", str(config), "--check")
    assert check.returncode == 0, check.stderr
    assert "-> state-log" in check.stdout
    config.with_name("b2.toml").write_text(config.read_text().replace("value =", "valeu ="))
    typo = run(plugin_python, "bridge", "--config", str(config.with_name("b2.toml")), "--check")
    assert typo.returncode == 2 and "valeu: unknown key; did you mean 'value'" in typo.stderr
    res = run(plugin_python, "bridge", "--config", str(config), "--duration", "2")
    assert res.returncode == 0, res.stderr
    # a still firm grasp: warm-up, stable (no slip: the load never moves), the stopped
    # bridge's "unknown" last (a loaded host may hold the source back in between: stale)
    lines = said(out)
    assert lines[0] == ("g", "peak-shift", "unknown") and lines[-1] == ("g", "peak-shift", "unknown"), lines
    assert {s for _, _, s in lines} == {"unknown", "stable"}, lines


# -- the method registry's rules, on entry points given in-process -----------------

@pytest.fixture
def entry_points(monkeypatch: pytest.MonkeyPatch) -> dict[str, str]:
    """The method group's entry points, as the test sets them."""
    found: dict[str, str] = {}
    monkeypatch.setattr(methods, "plugins", lambda group: found)
    methods._plugin.cache_clear()
    yield found
    methods._plugin.cache_clear()


#: A plug-in's method of each kind (the built-in cof-track's factories under other names).
_base = methods.get_method("cof-track")
GOOD = Method("spare", "a plug-in", _base.stream, _base.batch, code=4242, scores=_base.scores)
TAKEN = Method("taken", "a plug-in", _base.stream, _base.batch, code=_base.code)
ZERO = Method("zero", "a plug-in", _base.stream, _base.batch, code=0)
MISNAMED = Method("other", "a plug-in", _base.stream, _base.batch, code=4243)
TWIN = Method("twin", "a plug-in", _base.stream, _base.batch, code=4242)
NOT_A_METHOD = object()


def test_a_plugin_method_is_found_by_name_and_code(entry_points):
    entry_points["spare"] = "tests.test_plugins:GOOD"
    assert methods.method_names()[-1] == "spare" and methods.get_method("spare") is GOOD
    assert methods.method_of_code(4242) is GOOD and methods.method_of_stream(_base.stream) is _base
    with pytest.raises(KeyError, match=r"unknown detection method 'spar' \(did you mean 'spare'\?\)"):
        methods.get_method("spar")


@pytest.mark.parametrize(("name", "target", "message"), [
    ("taken", "TAKEN", r"code 7 is already 'cof-track''s METHOD_ID"),
    ("zero", "ZERO", r"code 0 is not a METHOD_ID"),
    ("misnamed", "MISNAMED", r"its Method is named 'other'"),
    ("thing", "NOT_A_METHOD", r"expected an eskin_industrial.detect.methods.Method, got object"),
])
def test_a_plugin_method_that_breaks_a_rule_is_refused_naming_it(entry_points, name, target, message):
    entry_points[name] = f"tests.test_plugins:{target}"
    with pytest.raises(ProfileError, match=rf"method plug-in '{name}' \(tests.test_plugins:{target}\): {message}"):
        methods.get_method(name)


def test_two_plugins_cannot_share_a_code(entry_points):
    entry_points.update(spare="tests.test_plugins:GOOD", twin="tests.test_plugins:TWIN")
    with pytest.raises(ProfileError, match="method plug-ins 'spare' and 'twin' both take METHOD_ID 4242"):
        methods.get_method("spare")


def test_a_plugin_never_replaces_a_built_in_method(entry_points):
    entry_points["cof-track"] = "tests.test_plugins:GOOD"
    assert methods.get_method("cof-track") is _base and methods.method_names().count("cof-track") == 1
