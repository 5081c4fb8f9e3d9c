"""The docs' figures are as their sources draw them today (scripts/figures, with the
register docs/figures.toml): a change to what a chart or a table is drawn from, with
no redraw, fails here with the figure named and the command that redraws it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from tests.helpers.paths import ROOT

SCRIPT = ROOT / "scripts" / "figures"


def figures(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, str(SCRIPT), *args], capture_output=True, text=True, timeout=60)


def test_no_figure_of_the_docs_is_stale() -> None:
    done = figures("--check")
    assert done.returncode == 0, done.stdout + done.stderr
    lines = done.stdout.splitlines()
    assert len(lines) >= 8 and all(": fresh" in line or ": known stale (" in line for line in lines), done.stdout


def test_a_change_to_a_figures_sources_names_it_and_its_command(tmp_path: Path) -> None:
    """In a copy: a figure marked as drawn, then its source edited, is reported stale
    with its redraw command and fails --check; marking it again makes it fresh; a
    missing figure file is named too."""
    (tmp_path / "src").mkdir()
    (tmp_path / "src" / "rule.py").write_text("THRESHOLD = 1.0\n")
    (tmp_path / "chart.png").write_bytes(b"png")
    register = tmp_path / "figures.toml"
    register.write_text('[[figure]]\nname = "chart"\nfiles = ["chart.png"]\ncommand = "draw --chart"\n'
                        'sources = ["src"]\ndrawn_from = ""\n')
    args = ("--register", str(register), "--root", str(tmp_path))
    assert figures(*args, "--mark", "chart").stdout.strip() == "chart: fresh"
    (tmp_path / "src" / "rule.py").write_text("THRESHOLD = 1.2\n")
    stale = figures(*args, "--check")
    assert stale.returncode == 1 and "chart: STALE" in stale.stdout and "redraw: draw --chart" in stale.stdout
    assert figures(*args, "--mark", "chart", "--check").returncode == 0
    (tmp_path / "chart.png").unlink()
    gone = figures(*args, "--check")
    assert gone.returncode == 1 and "chart: MISSING: chart.png does not exist" in gone.stdout


def test_every_chart_the_docs_show_is_registered() -> None:
    """A chart in docs/img that no figure of the register names would go stale unseen."""
    import tomllib

    named = {f for entry in tomllib.loads((ROOT / "docs" / "figures.toml").read_text())["figure"]
             for f in entry.get("files", [])}
    shown = {f"docs/img/{p.name}" for p in (ROOT / "docs" / "img").glob("*.png")}
    assert shown <= named, sorted(shown - named)
