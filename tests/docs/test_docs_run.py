"""Every shell block of README.md and docs/*.md, run as a user pastes it: from an
installed wheel, in an empty folder, each block in one shell with ``set -e`` (so a
failing line fails it).  Blocks marked ``needs=...`` (tests/helpers/doc_commands.py,
docs/cli.md) are skipped with their reason; a new block runs unless marked.

The wheel and its virtualenv are made once per session (tests/helpers/installed.py).
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from tests.helpers.doc_commands import NEEDS, Block, all_blocks, unmet
from tests.helpers.installed import build_and_install, user_env

pytestmark = pytest.mark.slow

BLOCKS = all_blocks()


@pytest.fixture(scope="session")
def installed_bin(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build_and_install(tmp_path_factory.mktemp("docs-install"))


def test_most_documented_commands_run() -> None:
    """What runs and what is skipped, counted: marking is for what cannot run here,
    not a way out."""
    ran = sum(len(b.commands) for b in BLOCKS if b.needs is None)
    skipped = {need: sum(len(b.commands) for b in BLOCKS if b.needs == need) for need in NEEDS}
    print(f"documented commands: {ran} run, {sum(skipped.values())} skipped "
          f"({', '.join(f'{n} {k}' for k, n in skipped.items() if n)})")
    assert ran >= 20 and ran > skipped["long"] + skipped["peer"]


@pytest.mark.parametrize("block", BLOCKS, ids=[b.where for b in BLOCKS])
def test_documented_block_runs_from_an_install(block: Block, installed_bin: Path, tmp_path: Path) -> None:
    if block.needs is not None:
        pytest.skip(f"{NEEDS[block.needs]} ({len(block.commands)} commands)")
    script = "set -euo pipefail\n" + "\n".join(block.commands) + "\n"
    done = subprocess.run(["bash", "-c", script], cwd=tmp_path, env=user_env(installed_bin),
                          capture_output=True, text=True, timeout=300, stdin=subprocess.DEVNULL)
    assert done.returncode == 0, (f"{block.where} exited {done.returncode} in an empty folder:\n{script}\n"
                                  f"--- stdout\n{done.stdout[-3000:]}\n--- stderr\n{done.stderr[-3000:]}")
    failed = unmet(block.expects, done.stdout + done.stderr, tmp_path)
    assert not failed, (f"{block.where}: what the page claims it gives, it does not: {'; '.join(failed)}\n"
                        f"--- stdout\n{done.stdout[-3000:]}\n--- stderr\n{done.stderr[-3000:]}")


def test_claims_are_checked_and_a_false_one_is_named(tmp_path: Path) -> None:
    """The pages' ``expect=`` claims are read (as many as the pages make), and a claim
    the output or the files do not bear out is reported, one line each."""
    assert sum(len(b.expects) for b in BLOCKS) >= 20
    (tmp_path / "out.csv").write_text("t,state\n9.42,slip\n")
    (tmp_path / "a.png").write_bytes(b"not an image")
    claims = ("out:slip events 1", "grep:out.csv:,slip", "file:out.csv", "out:found 2", "file:none.csv",
              "png:a.png", "grep:out.csv:stable")
    assert unmet(claims, "slip events 1, found 1", tmp_path) == [
        "output lacks 'found 2'", "none.csv: not written", "a.png: not a PNG image", "out.csv: lacks 'stable'"]
