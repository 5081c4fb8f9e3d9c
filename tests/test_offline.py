"""One offline path: `detect`, `plot` and the evaluation give the same updates for the
same frames, with the same method and model binding; a CAN log through a file, the
live reader and `plot` gives one answer too."""

from __future__ import annotations

import io
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import can
import numpy as np
import pytest
from click.testing import CliRunner

from eskin_industrial import methods, offline
from eskin_industrial.bus.can.layout import CanLayout
from eskin_industrial.bus.can.log import LiveLogScans, log_scans
from eskin_industrial.calibration import Calibrator
from eskin_industrial.cli import main, plot_cmd
from eskin_industrial.detect.methods import get_method
from eskin_industrial.detect.state import GraspState
from eskin_industrial.detect.updates import UpdateTable
from eskin_industrial.evaluation.suite import run_one
from eskin_industrial.frames import RawScan
from eskin_industrial.pipeline import Pipeline
from eskin_industrial.profile import Profile, load_profile
from eskin_industrial.recording import read_recording, write_recording, write_updates
from eskin_industrial.scenes import render
from tests.helpers.can_frames import scans_to_messages
from tests.helpers.paths import PROFILES

PAPER = str(PROFILES / "paper-5x5.toml")


def csv_of(table: UpdateTable) -> str:
    out = io.StringIO()
    write_updates(out, table)
    return out.getvalue()


def states(csv_text: str) -> list[str]:
    """The state column of an updates CSV."""
    return [line.split(",")[3] for line in csv_text.splitlines()[1:]]


def counts(csv_text: str) -> str:
    """What `plot` says on stderr of these updates."""
    labels = states(csv_text)
    return f"{len(labels)} updates, " + ", ".join(f"{s.label} {labels.count(s.label)}" for s in GraspState)


@pytest.fixture(scope="module")
def case2(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Any]:
    """The paper's case 2 (a slide) as a recording file, and the scene rendered."""
    rendered = render("case2", 100.0, 1000)
    path = tmp_path_factory.mktemp("offline") / "case2.csv"
    write_recording(path, rendered.t, rendered.forces)
    return path, rendered


def spied(monkeypatch: pytest.MonkeyPatch, name: str) -> list[offline.Detected]:
    """What `plot` gets from the offline path's ``name`` (the real function, watched)."""
    seen: list[offline.Detected] = []
    real: Callable[..., offline.Detected] = getattr(offline, name)

    def watch(*args: Any, **kwargs: Any) -> offline.Detected:
        seen.append(real(*args, **kwargs))
        return seen[-1]

    monkeypatch.setattr(plot_cmd, name, watch)
    return seen


def detect_plot_and_evaluate(method: str, path: Path, rendered: Any, tmp_path: Path,
                             monkeypatch: pytest.MonkeyPatch) -> tuple[str, str, str, str]:
    """The updates of one recording file through `detect`, `plot` and the evaluation's
    run, as CSV text; and what `plot` said of its updates."""
    prof = load_profile(PAPER)
    out = tmp_path / "out.csv"
    got = CliRunner().invoke(main, ["detect", "-p", PAPER, "--method", method, str(path), "-o", str(out), "-q"])
    assert got.exit_code == 0, got.output
    drawn = spied(monkeypatch, "detect_recording")
    got = CliRunner().invoke(main, ["plot", "-p", PAPER, "--method", method, str(path), "-o",
                                    str(tmp_path / "out.png")])
    assert got.exit_code == 0, got.output
    # the evaluation's run over the same frames (as the file holds them) at the file's rate
    back = read_recording(path, prof.taxels)
    frames = replace(rendered, t=back.t, forces=back.values, rate_hz=back.rate_hz(prof.sensor.rate_hz))
    scored, _ = run_one(get_method(method).stream, prof.detector, frames)
    (plotted,) = drawn
    return out.read_text(), csv_of(plotted.table), csv_of(scored), got.stderr


def test_detect_plot_and_the_evaluation_give_one_answer(case2: tuple[Path, Any], tmp_path: Path,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    path, rendered = case2
    detected, plotted, scored, said = detect_plot_and_evaluate("cof-track", path, rendered, tmp_path, monkeypatch)
    assert detected == plotted == scored
    assert said.strip().endswith(counts(detected)) and "slip 0" not in said  # the slide is found, by all three


def test_the_learned_method_is_bound_to_one_model_everywhere(case2: tuple[Path, Any], tmp_path: Path,
                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    # a stand-in for the shipped model: slip while the contact lasts
    asked: list[int] = []

    def default_model() -> Callable[[np.ndarray], np.ndarray]:
        asked.append(1)
        return lambda x: np.array([0.3, 0.1, 0.6]) if x[10] > 1.0 else np.array([0.8, 0.1, 0.1])

    monkeypatch.setattr(methods, "default_model", default_model)
    path, rendered = case2
    detected, plotted, scored, said = detect_plot_and_evaluate("learned", path, rendered, tmp_path, monkeypatch)
    assert len(asked) == 3  # detect, plot, the evaluation: each bound the one default model
    assert detected == plotted == scored
    assert {"stable", "slip"} <= set(states(detected))
    assert said.strip().endswith(counts(detected))
    # the bridge's pipeline, on the same frames as raw scans, binds it the same way
    prof = load_profile(PAPER)
    back = read_recording(path, prof.taxels)
    raw = Calibrator.from_section(prof.calibration, prof.taxels).to_raw(back.values)
    pipe = Pipeline(prof, rate_hz=back.rate_hz(100.0), method="learned")
    live = [u for k in range(len(raw)) for u in pipe.push(RawScan(k, float(back.t[k]), raw[k]))]
    assert len(asked) == 4
    assert [GraspState(u.state).label for u in live] == states(detected)


#: Scans of the node's log: case 2 (14 s at 100 Hz), its slide included.
SCANS = 1400


def candump(path: Path, prof: Profile) -> Path:
    """A candump -L log of the node playing case 2, written by python-can's writer."""
    rendered = render("case2", 100.0, 1000)
    raw = np.rint(Calibrator.from_section(prof.calibration, prof.taxels).to_raw(rendered.forces[:SCANS]))
    with can.CanutilsLogWriter(path) as log:
        for m in scans_to_messages(CanLayout.from_profile(prof), np.arange(SCANS) % 4096, raw):
            m.timestamp += 1.7e9
            m.channel = "can0"
            log.on_message_received(m)
    return path


def test_a_log_is_read_to_the_same_scans_whole_or_as_it_comes(tmp_path: Path) -> None:
    prof = load_profile(PAPER)
    log = candump(tmp_path / "traffic.log", prof)
    whole, counters = log_scans(prof, log)
    with open(log, encoding="utf-8") as stream:
        live = LiveLogScans(prof, stream, name=str(log))
        coming = list(live)
    assert len(whole) == len(coming) == SCANS
    assert all(a.seq == b.seq and a.t == b.t and np.array_equal(a.raw, b.raw) for a, b in zip(whole, coming))
    assert live.counters() == counters


def test_a_log_through_detect_its_live_reader_and_plot(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    prof = load_profile(PAPER)
    log = candump(tmp_path / "traffic.log", prof)
    runner = CliRunner()
    from_file = runner.invoke(main, ["detect", "-p", PAPER, "--method", "cof-track", "--can-log", str(log), "-q"])
    from_pipe = runner.invoke(main, ["detect", "-p", PAPER, "--method", "cof-track", "--can-log", "-", "-q"],
                              input=log.read_text())
    assert from_file.exit_code == from_pipe.exit_code == 0, from_pipe.output
    assert from_file.stdout == from_pipe.stdout
    drawn = spied(monkeypatch, "detect_can_log")
    got = runner.invoke(main, ["plot", "-p", PAPER, "--method", "cof-track", "--can-log", str(log), "-o",
                               str(tmp_path / "log.png")])
    assert got.exit_code == 0, got.output
    (plotted,) = drawn
    assert csv_of(plotted.table) == from_file.stdout
    assert plotted.forces is not None and plotted.forces.shape == (SCANS, prof.taxels)
    assert got.stderr.strip().endswith(counts(from_file.stdout)) and "slip 0" not in got.stderr
