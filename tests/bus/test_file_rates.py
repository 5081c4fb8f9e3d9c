"""One rate check for every file source, its boundary inclusive as it says: a 1 kHz
recording is accepted with a 100 Hz profile (10x: the edge) by `detect` and the
bridge alike, a message never contradicts itself, and the bridge's recording source
refuses a rate `detect` refuses (it took `--rate 0.1` and reported slips in a still
hold)."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from eskin_industrial.cli import main
from eskin_industrial.detect.hygiene import rate_problem
from eskin_industrial.recording import read_recording
from tests.helpers.modbus import free_port
from tests.helpers.paths import PROFILES

PAPER = str(PROFILES / "paper-5x5.toml")


@pytest.fixture(scope="module")
def khz(tmp_path_factory) -> str:
    """The README's own 1 kHz recording (`simulate hand --rate 1000`), cut to 3 s."""
    out = tmp_path_factory.mktemp("khz") / "case2.csv"
    res = CliRunner().invoke(main, ["simulate", "case2", "--rate", "1000", "--seed", "3", "-o", str(out)])
    assert res.exit_code == 0, res.output
    lines = out.read_text(encoding="utf-8").splitlines()
    out.write_text("\n".join(lines[:3001]) + "\n", encoding="utf-8")
    return str(out)


def test_the_inclusive_boundary_holds_for_times_written_in_decimal(khz):
    t = read_recording(khz, 25).t
    assert 1.0 / float(np.median(np.diff(t))) != 1000.0  # (the decimal times' own rounding)
    assert rate_problem(t, 100.0) is None
    assert rate_problem(np.arange(50) / 10.0, 100.0) is None  # the lower edge, 10 Hz


def test_a_refusal_shows_a_rate_outside_the_range_it_names():
    message = rate_problem(np.arange(100) / 1000.01, 100.0)
    assert message is not None
    shown = float(message.split("show ")[1].split(" Hz")[0])
    assert shown > 1000.0, message


def test_a_1khz_recording_with_a_100hz_profile_runs_in_detect_and_the_bridge(khz):
    res = CliRunner().invoke(main, ["detect", "-p", PAPER, khz, "-q"])
    assert res.exit_code == 0, res.output
    res = CliRunner().invoke(main, ["bridge", "-p", PAPER, "--source", f"recording:{khz}", "--rate", "1000",
                                    "--check"])
    assert res.exit_code == 0, res.output


def test_the_bridge_refuses_a_recording_at_a_rate_detect_refuses(khz):
    det = CliRunner().invoke(main, ["detect", "-p", PAPER, khz, "--rate", "0.1"])
    assert det.exit_code == 2 and "implausible" in det.output, det.output
    for check in (["--check"], ["--duration", "2"]):
        res = CliRunner().invoke(main, ["bridge", "-p", PAPER, "--source", f"recording:{khz}", "--rate", "0.1",
                                        "--plc", f"serve:127.0.0.1:{free_port()}", *check])
        assert res.exit_code == 2, res.output
        lines = [ln for ln in res.output.splitlines() if ln.strip()]
        assert len(lines) == 1 and "the timestamps show 1000 Hz, implausible for the node's rate_hz" in lines[0], \
            res.output
