"""What every command shares: -v/-q, options from ESKIN_* variables, JSON where a
script reads the result, progress on a terminal only, one format for a missing extra."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import click
import pytest
from click.testing import CliRunner

from eskin_industrial.cli import main
from tests.helpers.modbus import free_port
from tests.helpers.paths import ROOT


def _leaves(group: click.Group, path: tuple[str, ...] = ()):
    for name, cmd in group.commands.items():
        if isinstance(cmd, click.Group):
            yield from _leaves(cmd, (*path, name))
        else:
            yield (*path, name), cmd


def test_every_command_has_verbose_and_quiet() -> None:
    missing = [" ".join(p) for p, cmd in _leaves(main)
               if not {"-v", "--verbose", "-q", "--quiet"} <= {o for prm in cmd.params for o in getattr(prm, "opts", [])}]
    assert not missing, f"without -v/-q: {missing}"


def test_every_long_option_has_an_eskin_variable() -> None:
    for path, cmd in _leaves(main):
        for prm in cmd.params:
            longs = [o for o in getattr(prm, "opts", []) if o.startswith("--") and o != "--help"]
            if isinstance(prm, click.Option) and longs:
                want = "ESKIN_" + "_".join(p.upper().replace("-", "_") for p in path) + "_" + \
                    longs[0][2:].upper().replace("-", "_")
                assert prm.envvar == want, (path, longs[0], prm.envvar)


def test_options_from_the_environment_and_the_command_line_wins() -> None:
    runner = CliRunner()
    env = {"ESKIN_PLC_MAP_PROFILE": "hand-4x5", "ESKIN_PLC_MAP_FORMAT": "json"}
    from_env = runner.invoke(main, ["plc", "map"], env=env)
    assert from_env.exit_code == 0, from_env.output
    rows = json.loads(from_env.output)
    assert rows[0]["name"] == "STATUS"
    over = runner.invoke(main, ["plc", "map", "--format", "csv"], env=env)
    assert over.output.startswith("table,name,address")


def test_json_outputs_parse(tmp_path: Path) -> None:
    runner = CliRunner()
    checked = runner.invoke(main, ["profile", "check", "--format", "json", "paper-5x5", str(tmp_path / "none.toml")])
    assert checked.exit_code == 2
    ok, bad = json.loads(checked.stdout)
    assert ok["ok"] and ok["summary"].startswith("paper-5x5") and not bad["ok"] and "cannot read" in bad["error"]
    shown = runner.invoke(main, ["profile", "show", "--format", "json", "strip-1x5"])
    assert json.loads(shown.output)["layout"]["cols"] == 5
    ev = runner.invoke(main, ["evaluate", "-m", "cof-track", "-s", "case2", "--seeds", "1000", "--format", "json"])
    assert ev.exit_code == 0, ev.output
    doc = json.loads(ev.stdout)
    (row,) = doc["methods"]
    assert row["method"] == "cof-track" and row["events"] == 1 and row["found"] == 1
    assert row["per_scene"]["case2"]["found"] == 1 and doc["seed_list"] == [1000]


def _on_a_terminal(args: list[str], timeout: float = 60) -> tuple[int, str]:
    """Run ``eskin-bus ARGS`` with stderr on a pseudo-terminal; (exit code, what it showed)."""
    from tests.helpers.terminal import on_a_terminal

    run = on_a_terminal(args, Path(os.devnull), timeout_s=timeout)
    return run.code, run.shown


def test_progress_on_a_terminal_only_and_never_with_quiet() -> None:
    args = ["evaluate", "-m", "paper", "-s", "case2", "-s", "case4", "--seeds", "1000..1002"]
    code, shown = _on_a_terminal(args)
    assert code == 0 and "6/6" in shown and "paper, case4" in shown
    code, shown = _on_a_terminal([*args, "-q"])
    assert code == 0 and "6/6" not in shown
    piped = subprocess.run([sys.executable, "-m", "eskin_industrial", *args], capture_output=True, text=True,
                           timeout=60)
    assert piped.returncode == 0 and "6/6" not in piped.stderr and piped.stderr == ""


def test_every_missing_extra_reads_alike_and_exits_4(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # import matplotlib -> ImportError
    monkeypatch.setitem(sys.modules, "sklearn", None)
    runner = CliRunner()
    csv = tmp_path / "r.csv"
    csv.write_text("t," + ",".join(f"f{i}" for i in range(25)) + "\n" +
                   "\n".join(f"{i / 100}," + ",".join(["0"] * 25) for i in range(10)) + "\n")
    plot = runner.invoke(main, ["plot", "-p", "paper-5x5", str(csv), "-o", str(tmp_path / "x.png")])
    assert plot.exit_code == 4, plot.output
    assert plot.output.strip() == "eskin-bus: error: plot needs matplotlib: pip install 'eskin-industrial[plot]'"
    # the learned method runs on its shipped model: scikit-learn is for training only
    learned = runner.invoke(main, ["detect", "-p", "paper-5x5", str(csv), "--method", "learned", "-q"])
    assert learned.exit_code == 0, learned.output


@pytest.mark.parametrize("shell", ["bash", "zsh", "fish"])
def test_shell_completion_scripts_and_profile_names(shell: str) -> None:
    exe = str(Path(sys.executable).parent / "eskin-bus")
    script = subprocess.run([exe], env={**os.environ, "_ESKIN_BUS_COMPLETE": f"{shell}_source"},
                            capture_output=True, text=True, timeout=30)
    assert script.returncode == 0 and "_ESKIN_BUS_COMPLETE" in script.stdout
    if shell == "bash":
        done = subprocess.run([exe], env={**os.environ, "_ESKIN_BUS_COMPLETE": "bash_complete",
                                          "COMP_WORDS": "eskin-bus detect -p pa", "COMP_CWORD": "3"},
                              capture_output=True, text=True, timeout=30)
        assert "plain,paper-5x5" in done.stdout.splitlines()


def test_bridge_quiet_and_verbose_set_its_log_level() -> None:
    from tests.helpers.modbus import free_port

    def run(*extra: str) -> str:
        done = subprocess.run([sys.executable, "-m", "eskin_industrial", "bridge", "-p", "paper-5x5", "--source",
                               "scene:case2", "--plc", f"serve:127.0.0.1:{free_port()}", "--duration", "0.5", *extra],
                              capture_output=True, text=True, timeout=60)
        assert done.returncode == 0, done.stderr
        return done.stderr

    normal, quiet_ = run(), run("-q")
    assert " info " in normal and " start " in normal
    assert " info " not in quiet_ and " start " not in quiet_
    # an explicit level wins: the same info events (state lines depend on how far the
    # scene got in its half second, so they are left out of the comparison)
    def events(log: str) -> list[str]:
        return [line.split()[2] for line in log.splitlines() if " info " in line and line.split()[2] != "state"]
    assert events(run("-q", "--log-level", "info")) == events(normal)


def _all_commands(group: click.Group, path: tuple[str, ...] = ()):
    for name, cmd in group.commands.items():
        yield (*path, name), cmd
        if isinstance(cmd, click.Group):
            yield from _all_commands(cmd, (*path, name))


def test_every_help_page_ends_with_examples_and_its_variables() -> None:
    from tests.docs.test_docs_claims import CHECKOUT_PATH, _check_invocation
    from tests.helpers.doc_commands import invocations

    for path, cmd in _all_commands(main):
        page = CliRunner().invoke(main, [*path, "--help"]).output
        tail = page[page.rindex("--help  "):]  # (click caches a command's help option: "-h, --help" or "--help" by the first context)
        assert "Examples:\n    eskin-bus " + " ".join(path) in tail, (path, tail)
        examples = [line.strip() for line in tail.split("Examples:\n", 1)[1].split("\n\n")[0].splitlines()]
        for line in examples:
            assert not CHECKOUT_PATH.search(line), line
            for args in invocations(line):
                _check_invocation(args)
        names = [p.envvar for p in cmd.params if isinstance(p, click.Option) and p.envvar]
        env = " ".join(tail.split("Environment:", 1)[1].split()) if names else ""
        for name in names:
            assert name in env, (path, name)


def test_options_before_the_command(tmp_path: Path) -> None:
    """-q and -v are the program's as well as each command's: before the command they
    act on it (a -q there used to be refused)."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("ESKIN_")}
    here = str(ROOT)
    env["PYTHONPATH"] = here
    recording = tmp_path / "case2.csv"
    CliRunner().invoke(main, ["examples", "copy", "case2.csv", str(tmp_path)])

    def run(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([sys.executable, "-m", "eskin_industrial", *args], capture_output=True, text=True,
                              timeout=120, env=env, cwd=tmp_path)

    loud = run("detect", "-p", "paper-5x5", str(recording), "-o", os.devnull)
    assert loud.returncode == 0 and "1400 frames" in loud.stderr
    quiet = run("-q", "detect", "-p", "paper-5x5", str(recording), "-o", os.devnull)
    assert quiet.returncode == 0 and quiet.stderr == ""
    plan = run("-q", "bridge", "-p", "paper-5x5", "--source", "scene:case2", "--plc",
               f"serve:127.0.0.1:{free_port()}", "--check")
    assert plan.returncode == 0 and "case2" in plan.stdout, plan.stderr
    told = run("-v", "profile", "list")
    assert told.returncode == 0 and "paper-5x5" in told.stdout


def test_json_is_json_everywhere_and_numbers_are_numbers() -> None:
    """Every command that offers JSON takes --json (--format json kept where it was),
    and gives the same document either way; the map's addresses are integers."""
    runner = CliRunner()
    offering = [" ".join(p) for p, cmd in _leaves(main)
                if any(isinstance(prm, click.Option) and isinstance(prm.type, click.Choice) and "json" in prm.type.choices
                       and "--format" in prm.opts for prm in cmd.params)]
    assert {"plc map", "profile check", "profile show", "evaluate"} <= set(offering)
    for path in offering:
        cmd = main
        for word in path.split():
            cmd = cmd.commands[word]  # type: ignore[attr-defined]
        assert "--json" in {o for prm in cmd.params for o in getattr(prm, "opts", [])}, path
    for args in (["plc", "map", "-p", "paper-5x5"], ["profile", "show", "strip-1x5"], ["profile", "check", "hand-4x5"]):
        a = runner.invoke(main, [*args, "--json"])
        b = runner.invoke(main, [*args, "--format", "json"])
        assert a.exit_code == 0 and json.loads(a.output) == json.loads(b.output), args
    rows = {r["name"]: r for r in json.loads(runner.invoke(main, ["plc", "map", "-p", "hand-4x5", "--json"]).output)
            if r["table"] == "holding register"}
    assert rows["F_SUM"]["address"] == 104 and rows["F_SUM"]["words"] == 2 and rows["F_SUM"]["ref"] == 40105
    assert all(isinstance(r[k], int) for r in rows.values() for k in ("address", "ref", "words"))
