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

from tests.helpers.doc_commands import NEEDS, Block, all_blocks
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
