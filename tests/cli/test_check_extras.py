"""``bridge --check`` finds an output whose optional dependency is not installed, as
the run would find it when it opens the output: one line naming the extra to
install, exit 4.  The dependency is made missing for real: the command runs in a
process whose import system refuses the module (a finder placed first on
``sys.meta_path``), the failure an install without the extra meets."""

from __future__ import annotations

import subprocess
import sys
import tomllib

import pytest

from eskin_industrial.cli.extras import NEEDS
from tests.helpers.modbus import free_port
from tests.helpers.paths import ROOT

#: Runs eskin-bus with the modules named in argv[1] (comma-separated) not importable.
_WITHOUT = """
import sys
class Missing:
    def __init__(self, names): self.names = names
    def find_spec(self, name, path=None, target=None):
        if name.partition('.')[0] in self.names:
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return None
sys.meta_path.insert(0, Missing(set(sys.argv.pop(1).split(','))))
from eskin_industrial.cli import main
main(prog_name='eskin-bus')
"""


def check_without(modules: str, *outputs: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", _WITHOUT, modules, "bridge", "-p", "paper-5x5", "--source",
                           "scene:case2", *outputs, "--check"], capture_output=True, text=True, timeout=120)


def _opcua() -> tuple[str, str]:
    return "--opcua", f"opc.tcp://127.0.0.1:{free_port()}"


def _web() -> tuple[str, str]:
    return "--web", f"127.0.0.1:{free_port()}"


@pytest.mark.parametrize(("module", "option", "extra"), [("asyncua", _opcua, "opcua"), ("aiohttp", _web, "web")])
def test_check_names_the_missing_extra_of_an_output(module: str, option, extra: str) -> None:
    done = check_without(module, *option())
    assert done.returncode == 4 and done.stdout == "", done.stdout + done.stderr
    assert done.stderr == (f"eskin-bus: error: the {extra} output needs the extra {extra}: "
                           f"pip install 'eskin-industrial[{extra}]'\n")
    # with the module there, the same check passes and prints the plan
    there = check_without("nothing-blocked", *option())
    assert there.returncode == 0 and there.stdout.startswith("node: paper-5x5"), there.stderr


def test_two_missing_extras_are_one_line_and_one_pip_install() -> None:
    done = check_without("asyncua,aiohttp", *_opcua(), *_web())
    assert done.returncode == 4
    assert done.stderr == ("eskin-bus: error: the opcua output and the web output need the extras opcua, web: "
                           "pip install 'eskin-industrial[opcua,web]'\n")


def test_an_output_without_its_extra_also_stops_the_run_with_exit_4() -> None:
    """What --check promises: the run itself refuses the same, with the same code."""
    done = subprocess.run([sys.executable, "-c", _WITHOUT, "asyncua", "bridge", "-p", "paper-5x5", "--source",
                           "scene:case2", *_opcua(), "--duration", "1"], capture_output=True, text=True, timeout=120)
    assert done.returncode == 4 and "pip install 'eskin-industrial[opcua]'" in done.stderr, done.stderr


def test_the_table_names_real_extras_and_the_modules_they_install() -> None:
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    for (what, name), (module, extra) in NEEDS.items():
        assert what in ("output", "method", "source"), what
        packages = " ".join(extras[extra]).lower()
        assert module in packages, (name, extra)
