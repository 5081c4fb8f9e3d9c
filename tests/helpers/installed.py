"""The package as a wheel, installed into a throw-away virtualenv, for tests that run
``eskin-bus`` as an integrator does: from an empty folder, with no checkout in sight.

The wheel is built once per test session from the checkout (pip wheel --no-deps) and
installed the way the README's Install section says, into a virtualenv of its own
with its own pip: the wheel with the extras the pages use (``[plot,opcua,web]``, as
``pipx install 'eskin-industrial[plot,opcua]'`` plus the web console), its
dependencies resolved by pip under ``constraints.txt``.  Nothing is borrowed from
the environment running the tests: a page whose command needs a package the
documented install does not bring fails here as it fails for a user.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

from tests.helpers.paths import ROOT

#: The extras of the documented install the pages' commands run under.
DOCS_EXTRAS = "plot,opcua,web"


def build_wheel(root: Path) -> Path:
    """The checkout's wheel, built under ``root``."""
    # From a copy of the sources: setuptools builds in the tree, and a build/ folder left
    # there by an earlier build would lend the wheel files the sources no longer have.
    sources = root / "src"
    shutil.copytree(ROOT, sources, symlinks=True, ignore=shutil.ignore_patterns(
        ".git", ".venv", "build", "dist", "node_modules", "*.egg-info", "__pycache__", ".*_cache", ".hypothesis"))
    dist = root / "dist"
    subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--disable-pip-version-check",
                    str(sources), "-w", str(dist)], check=True, timeout=600, capture_output=True, cwd=root)
    (wheel,) = dist.glob("eskin_industrial-*.whl")
    return wheel


def clean_install(root: Path, wheel: Path, extras: str = "") -> Path:
    """The ``bin`` folder of a new virtualenv under ``root`` holding ``wheel`` (with
    ``extras``) and only what pip resolves for it under constraints.txt."""
    venv = root / ("venv-" + (extras.replace(",", "-") or "base"))
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=120)
    python = venv / "bin" / "python"
    target = f"{wheel}[{extras}]" if extras else str(wheel)
    done = subprocess.run([str(python), "-m", "pip", "install", "--quiet", "--disable-pip-version-check",
                           "-c", str(ROOT / "constraints.txt"), target], timeout=900, capture_output=True, text=True)
    assert done.returncode == 0, f"pip install {target} failed:\n{done.stdout[-2000:]}{done.stderr[-2000:]}"
    # the interpreter's own path only: no .pth of another environment, no user site
    paths = subprocess.run([str(python), "-s", "-c", "import sys; print('\\n'.join(sys.path))"],
                           check=True, capture_output=True, text=True, timeout=60).stdout.split()
    assert not any(p.startswith(sys.prefix) for p in paths if p), paths
    return venv / "bin"


def build_and_install(root: Path, extras: str = DOCS_EXTRAS) -> Path:
    """The ``bin`` folder of a clean virtualenv under ``root`` with the checkout's wheel
    and ``extras`` installed."""
    return clean_install(root, build_wheel(root), extras)


def user_env(bin_dir: Path) -> dict[str, str]:
    """The environment of a user of that install: its ``bin`` first on PATH (then this
    environment's, for the third-party tools the pages use, such as cantools), no
    PYTHONPATH, no ESKIN_* settings of the caller."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "VIRTUAL_ENV") and not k.startswith("ESKIN_")}
    env["PATH"] = os.pathsep.join([str(bin_dir), str(Path(sys.executable).parent), env.get("PATH", "")])
    env["VIRTUAL_ENV"] = str(bin_dir.parent)
    env["MPLBACKEND"] = "Agg"
    return env
