"""Shell completion as the shell asks for it: the program run with click's variables
(``_ESKIN_BUS_COMPLETE=bash_complete``, ``COMP_WORDS``, ``COMP_CWORD``), and bash
itself running the script ``eskin-bus completion bash`` prints."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import can
import pytest

from eskin_industrial.methods import method_names
from eskin_industrial.profile import builtin_profiles
from eskin_industrial.scenes import list_scenes

EXE = str(Path(sys.executable).parent / "eskin-bus")


def _complete(line: str, cwd: Path | None = None) -> list[str]:
    """The candidates for the last word of ``line`` (an empty one after a space)."""
    words = line.split()
    cword = len(words) if line.endswith(" ") else len(words) - 1
    done = subprocess.run([EXE], env={**os.environ, "_ESKIN_BUS_COMPLETE": "bash_complete", "COMP_WORDS": line,
                                      "COMP_CWORD": str(cword)}, capture_output=True, text=True, timeout=30, cwd=cwd)
    assert done.returncode == 0, done.stderr
    return [row.split(",", 1)[1] for row in done.stdout.splitlines() if row.startswith("plain,")]


def test_scene_names_complete_on_every_scene_option(tmp_path: Path) -> None:
    scenes = list(list_scenes())
    assert _complete("eskin-bus demo --scene ", tmp_path) == scenes
    (tmp_path / "slide.toml").write_text("")
    assert _complete("eskin-bus demo --scene ", tmp_path) == [*scenes, "slide.toml"]  # a scene file too
    assert _complete("eskin-bus simulate ca") == [s for s in scenes if s.startswith("ca")]
    assert _complete("eskin-bus evaluate -s ho") == [s for s in scenes if s.startswith("ho")]
    assert _complete("eskin-bus node --scene case") == [s for s in scenes if s.startswith("case")]
    assert "scene:" in _complete("eskin-bus bridge --source ")
    assert _complete("eskin-bus bridge --source scene:ha", tmp_path) == [f"scene:{s}" for s in scenes if s.startswith("ha")]


def test_profile_names_then_profile_files(tmp_path: Path) -> None:
    (tmp_path / "cell.toml").write_text("")
    (tmp_path / "notes.txt").write_text("")
    (tmp_path / "cells").mkdir()
    (tmp_path / "cells" / "left.toml").write_text("")
    names = list(builtin_profiles())
    assert _complete("eskin-bus bridge -p ", tmp_path) == [*names, "cell.toml", "cells/"]
    assert _complete("eskin-bus plc export -p cells/", tmp_path) == ["cells/left.toml"]
    assert _complete("eskin-bus simulate -p pa", tmp_path) == [n for n in names if n.startswith("pa")]


def test_python_can_interfaces_and_methods() -> None:
    assert _complete("eskin-bus node -i ") == sorted(can.interfaces.VALID_INTERFACES)
    assert _complete("eskin-bus receive -i sock") == ["socketcan", "socketcand"]
    assert _complete("eskin-bus detect -m cof") == sorted(m for m in method_names() if m.startswith("cof"))
    assert _complete("eskin-bus docs pl") == ["plant", "plc"]


@pytest.mark.skipif(shutil.which("bash") is None, reason="no bash")
def test_bash_offers_the_names_through_the_printed_script(tmp_path: Path) -> None:
    """The script, sourced by bash, fills COMPREPLY: names and profile files together
    (a "file" item in click's bash script clears what came before it: -p pa offered
    no paper-5x5 when files were left to the shell)."""
    script = subprocess.run([EXE, "completion", "bash"], capture_output=True, text=True, timeout=30)
    assert script.returncode == 0 and "_ESKIN_BUS_COMPLETE=bash_complete" in script.stdout
    (tmp_path / "complete.bash").write_text(script.stdout)
    (tmp_path / "paw.toml").write_text("")
    probe = ('source complete.bash; COMP_WORDS=(eskin-bus detect -p pa); COMP_CWORD=3; '
             '_eskin_bus_completion eskin-bus 2>/dev/null; printf "%s\\n" "${COMPREPLY[@]}"')
    env = {**os.environ, "PATH": f"{Path(EXE).parent}:{os.environ['PATH']}"}
    done = subprocess.run(["bash", "--norc", "-c", probe], capture_output=True, text=True, timeout=30, cwd=tmp_path,
                          env=env)
    assert done.stdout.split() == ["paper-5x5", "paw.toml"], done.stdout + done.stderr


@pytest.mark.parametrize("shell", ["zsh", "fish"])
def test_the_command_prints_what_clicks_variable_does(shell: str) -> None:
    printed = subprocess.run([EXE, "completion", shell], capture_output=True, text=True, timeout=30)
    sourced = subprocess.run([EXE], env={**os.environ, "_ESKIN_BUS_COMPLETE": f"{shell}_source"},
                             capture_output=True, text=True, timeout=30)
    assert printed.returncode == 0 and printed.stdout == sourced.stdout and "eskin-bus" in printed.stdout
