"""The package as a wheel, installed into a throw-away virtualenv, for tests that run
``eskin-bus`` as an integrator does: from an empty folder, with no checkout in sight.

The wheel is built once per test session from the checkout (pip wheel --no-deps);
the virtualenv has no pip and borrows this environment's dependencies through a
``.pth`` line (its own site-packages, with the installed package, comes first), so
nothing but the build backend is fetched and the install takes seconds.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

from tests.helpers.paths import ROOT


def build_and_install(root: Path) -> Path:
    """The ``bin`` folder of a virtualenv under ``root`` with the checkout's wheel installed."""
    # From a copy of the sources: setuptools builds in the tree, and a build/ folder left
    # there by an earlier build would lend the wheel files the sources no longer have.
    sources = root / "src"
    shutil.copytree(ROOT, sources, symlinks=True, ignore=shutil.ignore_patterns(
        ".git", ".venv", "build", "dist", "node_modules", "*.egg-info", "__pycache__", ".*_cache", ".hypothesis"))
    dist = root / "dist"
    subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--disable-pip-version-check",
                    str(sources), "-w", str(dist)], check=True, timeout=600, capture_output=True, cwd=root)
    (wheel,) = dist.glob("eskin_industrial-*.whl")
    venv = root / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=120)
    site = next((venv / "lib").glob("python*/site-packages"))
    (site / "host_packages.pth").write_text(f"{sysconfig.get_paths()['purelib']}\n")
    python = venv / "bin" / "python"
    # --force-reinstall: this environment's own (editable) eskin-industrial is on the
    # borrowed path with the same version, which pip would otherwise take as installed.
    subprocess.run([sys.executable, "-m", "pip", "--python", str(python), "install", "--quiet", "--no-deps",
                    "--no-index", "--force-reinstall", "--disable-pip-version-check", str(wheel)], check=True,
                   timeout=300, capture_output=True)
    assert (site / "eskin_industrial" / "__init__.py").is_file(), "the wheel did not install"
    return venv / "bin"


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
