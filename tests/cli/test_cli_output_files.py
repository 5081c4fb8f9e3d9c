"""A file a command cannot write is one line naming the option and the path, exit 2,
never a traceback (as `receive -o nodir/o.csv` was already): a missing folder before
any work, a file that cannot be written (here the full disk of /dev/full) when the
write fails."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from eskin_industrial.cli import main
from tests.helpers.paths import PROFILES

PAPER = str(PROFILES / "paper-5x5.toml")
FULL = "/dev/full"


def one_line(args: list[str], *expected: str) -> None:
    res = CliRunner().invoke(main, args)
    lines = [line for line in res.stderr.splitlines() if line]
    assert res.exit_code == 2, res.output
    assert lines and lines[-1].startswith("eskin-bus: error: "), res.output
    assert not isinstance(res.exception, OSError) and "Traceback" not in res.output
    for text in expected:
        assert text in lines[-1], res.output


@pytest.fixture(scope="module")
def rec(tmp_path_factory: pytest.TempPathFactory) -> str:
    path = tmp_path_factory.mktemp("rec") / "r.csv"
    res = CliRunner().invoke(main, ["simulate", "case2", "-o", str(path)])
    assert res.exit_code == 0, res.output
    return str(path)


@pytest.fixture(scope="module")
def can_log(tmp_path_factory: pytest.TempPathFactory) -> str:
    path = tmp_path_factory.mktemp("log") / "case2.log"
    res = CliRunner().invoke(main, ["simulate", "case2", "--can-log", str(path), "-p", PAPER])
    assert res.exit_code == 0, res.output
    return str(path)


def test_simulate_into_a_missing_folder(tmp_path: Path) -> None:
    one_line(["simulate", "case2", "-o", str(tmp_path / "nodir" / "x.csv")], "-o: ", "no such folder")
    one_line(["simulate", "case2", "-o", str(tmp_path / "x.csv"), "--labels", str(tmp_path / "nodir" / "l.csv")],
             "--labels: ", "no such folder")


def test_detect_into_a_missing_folder(tmp_path: Path, rec: str, can_log: str) -> None:
    one_line(["detect", "-p", PAPER, rec, "-o", str(tmp_path / "nodir" / "o.csv")], "-o: ", "no such folder")
    one_line(["detect", "-p", PAPER, "--can-log", can_log, "-o", str(tmp_path / "nodir" / "o.csv")],
             "-o: ", "no such folder")


def test_receive_logging_into_a_missing_folder(tmp_path: Path) -> None:
    one_line(["receive", "-p", PAPER, "-i", "virtual", "-c", "cli-files", "--duration", "0.1",
              "--log", str(tmp_path / "nodir" / "t.log")], "log: ", "no such folder")


@pytest.mark.skipif(not os.path.exists(FULL), reason="no /dev/full here")
@pytest.mark.parametrize("args", [
    ["simulate", "case2", "-o", FULL],
    ["simulate", "case2", "-o", "{tmp}/x.csv", "--labels", FULL],
    ["detect", "-p", PAPER, "{rec}", "-o", FULL],
], ids=["simulate-o", "simulate-labels", "detect-o"])
def test_a_file_that_cannot_be_written(args: list[str], tmp_path: Path, rec: str) -> None:
    args = [a.format(tmp=tmp_path, rec=rec) for a in args]
    one_line(args, f"{args[-2]}: {FULL}: cannot write: no space left on device")


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes a read-only file")
def test_a_read_only_file(tmp_path: Path) -> None:
    out = tmp_path / "ro.csv"
    out.write_text("")
    out.chmod(0o444)
    one_line(["simulate", "case2", "-o", str(out)], f"-o: {out}: cannot write: permission denied")


#: The command run as an unprivileged user: as root, the child drops to nobody once the
#: interpreter and the command line are loaded (the interpreter may live where nobody
#: may read); as anyone else, it runs as it is.
_AS_NOBODY = """
import os, sys
from eskin_industrial.cli import main
main.commands[sys.argv[1]]  # its modules imported while this Python's own files are readable
if os.geteuid() == 0:
    os.setgroups([]); os.setgid(65534); os.setuid(65534)
sys.argv = ["eskin-bus", *sys.argv[1:]]
main()
"""


def test_a_folder_this_user_may_not_write(tmp_path: Path) -> None:
    res = subprocess.run([sys.executable, "-c", _AS_NOBODY, "simulate", "case2", "-o", "/proc/x.csv"],
                         capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert res.returncode == 2, res.stderr
    assert res.stderr == "eskin-bus: error: -o: /proc/x.csv: folder '/proc' is not writable\n"
