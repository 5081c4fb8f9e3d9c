"""The package as an integrator installs it: a wheel built from the checkout, installed
with the deployment constraints into a fresh virtualenv, run from an empty folder with
no checkout in sight (the profiles, scenes and example files must travel with it)."""

from __future__ import annotations

import email
import os
import re
import subprocess
import sys
import tarfile
import zipfile
from pathlib import Path

import pytest

from tests.helpers.modbus import free_port
from tests.helpers.paths import ROOT

pytestmark = pytest.mark.slow


def _run(cmd: list[str], cwd: Path, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    done = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert done.returncode == 0, f"{' '.join(cmd)} exited {done.returncode}:\n{done.stdout}\n{done.stderr}"
    return done


def _pins(path: Path) -> dict[str, str]:
    """The runtime pins: those above the extras' section."""
    pins = {}
    for line in path.read_text().split("# --- the extras")[0].splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            name, _, version = line.partition("==")
            pins[name.lower().replace("_", "-")] = version
    return pins


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """(the wheel, the fresh virtualenv's bin folder)."""
    tmp = tmp_path_factory.mktemp("wheel")
    _run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", str(ROOT), "-w", str(tmp / "dist")], tmp)
    (wheel,) = (tmp / "dist").glob("eskin_industrial-*.whl")
    _run([sys.executable, "-m", "venv", str(tmp / "venv")], tmp)
    bin_dir = tmp / "venv" / "bin"
    _run([str(bin_dir / "pip"), "install", "-q", "--disable-pip-version-check",
          "-c", str(ROOT / "constraints.txt"), str(wheel)], tmp)
    return wheel, bin_dir


def test_wheel_carries_profiles_examples_license_and_metadata(installed: tuple[Path, Path]) -> None:
    wheel, _ = installed
    with zipfile.ZipFile(wheel) as zf:
        names = set(zf.namelist())
        meta = email.message_from_bytes(zf.read(next(n for n in names if n.endswith(".dist-info/METADATA"))))
    for profile in (ROOT / "profiles").glob("*.toml"):
        assert f"eskin_industrial/data/profiles/{profile.name}" in names
    for example in ("bridge.toml", "hand-strips.toml", "eskin-bus-bridge.service"):
        assert f"eskin_industrial/data/deploy/{example}" in names
    assert any(n.endswith(".dist-info/licenses/LICENSE") for n in names)
    assert any(n.startswith("eskin_industrial/scenes/builtin/") for n in names)
    assert "eskin_industrial/data/models/learned.npz" in names  # the learned method's model
    for nodeset in ("Opc.Ua.Di.NodeSet2.xml", "Opc.Ua.IA.NodeSet2.xml", "Opc.Ua.Machinery.NodeSet2.xml", "LICENSE"):
        assert f"eskin_industrial/data/nodesets/{nodeset}" in names  # the OPC UA companion specifications
    # the docs (eskin-bus docs): every page of docs/, the file itself, not a link to one
    pages = sorted((ROOT / "docs").glob("*.md"))
    with zipfile.ZipFile(wheel) as zf:
        for page in pages:
            assert zf.read(f"eskin_industrial/docs/{page.name}") == page.read_bytes(), page.name
    assert meta.get_all("Project-URL") and any(u.startswith("Documentation, https://") for u in meta.get_all("Project-URL"))
    assert meta["License-Expression"] == "MIT"
    # the index's description: README.md with its links into the checkout made plain (tests/docs/test_index_readme.py)
    assert meta["Description-Content-Type"] == "text/markdown"
    assert meta.get_payload().strip() == (ROOT / "README.index.md").read_text().strip()
    classifiers = meta.get_all("Classifier") or []
    for version in ("3.11", "3.12", "3.13"):
        assert f"Programming Language :: Python :: {version}" in classifiers


def test_sdist_carries_every_file_the_description_names(tmp_path: Path) -> None:
    """The index description names files by path "in the source distribution": they
    must be there (MANIFEST.in).  Built by setuptools' own backend in a virtualenv of
    its own (the build requirement, setuptools>=77)."""
    _run([sys.executable, "-m", "venv", str(tmp_path / "venv")], tmp_path)
    python = str(tmp_path / "venv" / "bin" / "python")
    _run([python, "-m", "pip", "install", "-q", "--disable-pip-version-check", "setuptools>=77"], tmp_path)
    _run([python, "-c", f"from setuptools import build_meta; build_meta.build_sdist({str(tmp_path / 'dist')!r})"], ROOT)
    (sdist,) = (tmp_path / "dist").glob("eskin_industrial-*.tar.gz")
    with tarfile.open(sdist) as tf:
        names = {n.split("/", 1)[1] for n in tf.getnames() if "/" in n}
    description = (ROOT / "README.index.md").read_text()
    named = set(re.findall(r"`(docs/[^`\s]+)`", description))
    assert "docs/plc.md" in named and named <= names, named - names
    # and what its commands use: the pins, the example recordings, the scripts
    assert {"constraints.txt", "examples/case2.csv", "scripts/demo", "README.index.md", "README.md", "LICENSE",
            "tests/helpers/paths.py"} <= names


def test_constraints_pin_every_installed_distribution(installed: tuple[Path, Path], tmp_path: Path) -> None:
    _, bin_dir = installed
    frozen = _run([str(bin_dir / "pip"), "freeze", "--exclude", "eskin-industrial"], tmp_path).stdout
    pins = _pins(ROOT / "constraints.txt")
    installed_now = {}
    for line in frozen.splitlines():
        name, _, version = line.partition("==")
        installed_now[name.lower().replace("_", "-")] = version
    assert installed_now == pins, "constraints.txt is out of date: regenerate it from the fresh virtualenv's pip freeze"


def test_installed_demo_runs_from_an_empty_folder(installed: tuple[Path, Path], tmp_path: Path) -> None:
    _, bin_dir = installed
    eskin = str(bin_dir / "eskin-bus")
    listed = _run([eskin, "profile", "list"], tmp_path).stdout
    assert {"paper-5x5", "hand-4x5", "strip-1x5"} <= {line.split()[0] for line in listed.splitlines()}
    demo = _run([eskin, "demo", "--plain", "--scene", "case2"], tmp_path, timeout=120).stdout
    assert "slip events 1, found 1, false alarms 0" in demo


def test_installed_docs_list_and_print_with_no_checkout(installed: tuple[Path, Path], tmp_path: Path) -> None:
    _, bin_dir = installed
    eskin = str(bin_dir / "eskin-bus")
    listed = _run([eskin, "docs"], tmp_path).stdout
    assert {p.stem for p in (ROOT / "docs").glob("*.md")} <= {line.split()[0] for line in listed.splitlines() if line}
    shown = _run([eskin, "docs", "plc"], tmp_path).stdout
    assert shown == (ROOT / "docs" / "plc.md").read_text()
    where = Path(_run([eskin, "docs", "plc", "--path"], tmp_path).stdout.strip())
    assert bin_dir.parent in where.parents and not where.is_symlink()  # the install's own copy


def test_the_base_install_runs_the_learned_method(installed: tuple[Path, Path], tmp_path: Path) -> None:
    # no extra, so no scikit-learn: the model is the wheel's package data, and nothing trains
    _, bin_dir = installed
    eskin = str(bin_dir / "eskin-bus")
    assert subprocess.run([str(bin_dir / "python"), "-c", "import sklearn"], capture_output=True).returncode != 0
    _run([eskin, "examples", "copy", "case2.csv"], tmp_path)
    found = _run([eskin, "detect", "-p", "paper-5x5", "case2.csv", "--method", "learned", "--changes"], tmp_path)
    assert ",slip," in found.stdout, found.stdout + found.stderr


@pytest.mark.parametrize(("command", "extra"), [
    (["plot", "-p", "paper-5x5", "case2.csv", "-o", "case2.png"], "plot"),
    (["bridge", "-p", "paper-5x5", "--source", "scene:case2", "--opcua", "opc.tcp://127.0.0.1:4840", "--check"],
     "opcua"),
    (["bridge", "-p", "paper-5x5", "--source", "scene:case2", "--web", "127.0.0.1:8080", "--check"], "web"),
])
def test_the_base_install_names_the_extra_a_command_needs(installed: tuple[Path, Path], tmp_path: Path,
                                                          command: list[str], extra: str) -> None:
    """In the base install (no extra, nothing borrowed: the extra's package is not
    importable), a command that needs an extra says which in one line, exit 4, and a
    ``--check`` finds it before anything starts."""
    _, bin_dir = installed
    module = {"plot": "matplotlib", "opcua": "asyncua", "web": "aiohttp"}[extra]
    assert subprocess.run([str(bin_dir / "python"), "-c", f"import {module}"], capture_output=True).returncode != 0
    _run([str(bin_dir / "eskin-bus"), "examples", "copy", "case2.csv"], tmp_path)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    done = subprocess.run([str(bin_dir / "eskin-bus"), *command], cwd=tmp_path, env=env, capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 4, done.stdout + done.stderr
    assert done.stderr.count("\n") == 1 and f"eskin-industrial[{extra}]" in done.stderr, done.stderr
    assert not list(tmp_path.glob("*.png"))


def test_installed_profiles_and_examples_copy_out_and_check(installed: tuple[Path, Path], tmp_path: Path) -> None:
    _, bin_dir = installed
    eskin = str(bin_dir / "eskin-bus")
    _run([eskin, "profile", "init", "paper-5x5", "-o", "left.toml"], tmp_path)
    assert (tmp_path / "left.toml").read_text() == (ROOT / "profiles" / "paper-5x5.toml").read_text()
    assert "ok" in _run([eskin, "profile", "check", "left.toml", "hand-4x5"], tmp_path).stdout
    _run([eskin, "examples", "-o", "cell"], tmp_path)
    plan = _run([eskin, "bridge", "--config", "cell/bridge.toml", "--check"], tmp_path).stdout
    assert "gripper-left" in plan and "gripper-right" in plan


def test_pipx_installs_the_wheel_with_a_working_command(installed: tuple[Path, Path], tmp_path: Path) -> None:
    """pipx, the way an integrator installs a command-line tool: its own virtualenv,
    the command on PATH, run from an empty folder; with the README's extras and
    ``--include-deps`` (docs/opcua.md), asyncua's command-line tools on PATH too."""
    wheel, bin_dir = installed
    _run([str(bin_dir / "pip"), "install", "-q", "--disable-pip-version-check", "pipx>=1.4,<2"], tmp_path)
    env = {"PIPX_HOME": str(tmp_path / "pipx"), "PIPX_BIN_DIR": str(tmp_path / "bin")}
    done = subprocess.run([str(bin_dir / "pipx"), "install", "--include-deps", "--pip-args",
                           f"-c {ROOT / 'constraints.txt'}", f"{wheel}[plot,opcua]"], cwd=tmp_path,
                          env={**os.environ, **env}, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout + done.stderr
    eskin = str(tmp_path / "bin" / "eskin-bus")
    listed = _run([eskin, "profile", "list"], tmp_path).stdout
    assert listed.startswith("hand-4x5")
    checked = _run([eskin, "bridge", "-p", "paper-5x5", "--source", "scene:case2",
                    "--plc", f"serve:127.0.0.1:{free_port()}", "--check"], tmp_path).stdout
    assert "case2" in checked
    for tool in ("uals", "uaread", "uasubscribe", "uacall"):  # docs/opcua.md's first client
        assert "usage" in _run([str(tmp_path / "bin" / tool), "--help"], tmp_path).stdout.lower(), tool
    _run([eskin, "examples", "copy", "case2.csv"], tmp_path)
    _run([eskin, "plot", "-p", "paper-5x5", "case2.csv", "-o", "case2.png"], tmp_path)
    assert (tmp_path / "case2.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

