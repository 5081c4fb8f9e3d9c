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

import dataclasses
import re
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

from eskin_industrial import methods
from eskin_industrial.detect.methods import Method
from eskin_industrial.errors import ProfileError
from eskin_industrial.profile import parse_profile
from eskin_industrial.schema import in_range
from tests.helpers.page_kinds import page_examples, page_plugin_test
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

[project.entry-points."eskin_industrial.sinks"]
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
    (root / "test_pagekinds.py").write_text(page_plugin_test())  # the plug-in's own test, beside it
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


def test_the_plugin_methods_section_is_checked_and_shown(plugin_python, tmp_path):
    profile = peak_profile(tmp_path)
    base = profile.read_text()
    shown = run(plugin_python, "profile", "show", str(profile))
    assert shown.returncode == 0, shown.stderr
    assert "[detector.peak_shift]\nmargin = 1.2  # default\n" in shown.stdout  # left out: its defaults, shown
    profile.write_text(base + "\n[detector.peak_shift]\nmargin = 2.5\n")
    assert run(plugin_python, "profile", "check", str(profile)).returncode == 0
    assert "[detector.peak_shift]\nmargin = 2.5\n" in run(plugin_python, "profile", "show", str(profile)).stdout
    profile.write_text(base + "\n[detector.peak_shift]\nmargn = 2.5\n")
    typo = run(plugin_python, "profile", "check", str(profile))
    assert typo.returncode == 2
    assert typo.stderr == (f"eskin-bus: error: {profile}: [detector] peak_shift.margn: unknown key; "
                           f"did you mean 'margin'?\n")
    profile.write_text(base + "\n[detector.peak_shift]\nmargin = 0.5\n")
    check = run(plugin_python, "bridge", "-p", str(profile), "--source", "scene:case2", "--check")
    assert check.returncode == 2 and "[detector] peak_shift.margin: expected a value in [1, 10], got 0.5" in check.stderr
    # this environment, without the plug-in, knows no such section
    profile.write_text(base.replace('method = "peak-shift"', 'method = "paper"') + "\n[detector.peak_shift]\nmargin = 2.5\n")
    here = run(sys.executable, "profile", "check", str(profile))
    assert here.returncode == 2 and "[detector] peak_shift: unknown key" in here.stderr


def test_the_plugins_own_test_calls_the_conformance_checks(plugin_python):
    test = plugin_python.parents[2] / "test_pagekinds.py"
    res = subprocess.run([str(plugin_python), "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:xdist",
                          "-W", "error", str(test)], capture_output=True, text=True, timeout=300, cwd=test.parent)
    assert res.returncode == 0, res.stdout + res.stderr
    assert "1 passed" in res.stdout


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


@dataclasses.dataclass
class LooseSettings:  # not frozen
    z: float = 1.0


@dataclasses.dataclass(frozen=True)
class SpareSettings:
    z: float = dataclasses.field(default=1.0, metadata=in_range(0.5, 2.0))


LOOSE = Method("loose", "a plug-in", _base.stream, _base.batch, code=4244, settings=LooseSettings)
SHADOW = Method("varying-force", "a plug-in", _base.stream, _base.batch, code=4245, settings=SpareSettings)
SPARE = Method("spare", "a plug-in", _base.stream, _base.batch, code=4242, scores=_base.scores, settings=SpareSettings)


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
    ("loose", "LOOSE", r"its settings must be a frozen dataclass"),
    ("varying-force", "SHADOW", r"its settings cannot be \[detector.varying_force\] \(a key of \[detector\] itself"),
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


def test_a_plugin_methods_section_is_read_only_from_its_profile_key(entry_points, tmp_path):
    entry_points["spare"] = "tests.test_plugins:SPARE"
    base = re.sub(r'(?m)^method = "[^"]*"', 'method = "spare"', (PROFILES / "paper-5x5.toml").read_text(), count=1)
    assert SPARE.settings_of(parse_profile(base).detector) == SpareSettings()  # left out: the defaults
    detector = parse_profile(base + "\n[detector.spare]\nz = 1.5\n").detector
    assert SPARE.settings_of(detector) == SpareSettings(1.5) and detector.plugins == (("spare", SpareSettings(1.5)),)
    with pytest.raises(ProfileError, match=r"^p.toml: \[detector\] spare.z: expected a value in \[0.5, 2\], got 3.0$"):
        parse_profile(base + "\n[detector.spare]\nz = 3.0\n", "p.toml")
    with pytest.raises(ProfileError, match=r"^p.toml: \[detector\] spare: expected a table, got 1$"):
        parse_profile(base.replace('method = "spare"', 'method = "spare"\nspare = 1', 1), "p.toml")
