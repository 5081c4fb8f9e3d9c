"""The seams as docs/architecture.md shows them: its example source kind, output kind
and method, taken from the page itself, are each one module plus one registry entry,
and the bridge configuration, the profile and the runtime take them with no other
change."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import numpy as np
import pytest

from eskin_industrial.bridge.config import output_classes, parse_bridge_config, resolve
from eskin_industrial.bridge.logs import EventLog
from eskin_industrial.bridge.runtime import Bridge
from eskin_industrial.bus.source import SOURCES
from eskin_industrial.detect.methods import METHODS
from eskin_industrial.detect.settings import DetectorSettings
from eskin_industrial.detect.state import GraspState
from eskin_industrial.errors import ProfileError
from eskin_industrial.outputs.base import SINKS
from tests.helpers.bridge import LogCapture, wait_for
from tests.helpers.page_kinds import page_examples
from tests.helpers.paths import PROFILES


@pytest.fixture
def kinds(tmp_path, monkeypatch):
    (tmp_path / "pagekinds.py").write_text(page_examples())
    monkeypatch.syspath_prepend(str(tmp_path))
    import pagekinds  # type: ignore[import-not-found]

    monkeypatch.setitem(SOURCES, "const", "pagekinds:ConstSource")  # the one registry entry each
    monkeypatch.setitem(SINKS, "state-log", "pagekinds:StateLogKind")
    monkeypatch.setitem(METHODS, "peak-shift", pagekinds.METHOD)
    yield pagekinds
    sys.modules.pop("pagekinds", None)


def peak_shift_profile(tmp_path) -> str:
    path = tmp_path / "peak.toml"
    text = (PROFILES / "paper-5x5.toml").read_text()
    path.write_text(re.sub(r'(?m)^method = "[^"]*"', 'method = "peak-shift"', text, count=1))
    return str(path)


def config(log_path, profile: str = str(PROFILES / "paper-5x5.toml")) -> str:
    # 600 ohm on every taxel: about 4.4 N each, a firm still grasp
    return (f'[log]\nformat = "json"\nstatus_every_s = 0\n\n[state-log]\npath = "{log_path}"\n\n'
            f'[[node]]\nname = "g"\nprofile = "{profile}"\nsource = "const"\nvalue = 600.0\n')


def test_the_page_examples_run_in_the_bridge(kinds, tmp_path):
    log_path = tmp_path / "states.log"
    cfg = parse_bridge_config(config(log_path, peak_shift_profile(tmp_path)), str(tmp_path / "b.toml"))
    (node,) = resolve(cfg)
    assert node.profile.detector.method == "peak-shift"
    assert node.options.value == 600.0 and [c.name for c, _ in output_classes(cfg)] == ["state-log"]
    capture = LogCapture()
    log = EventLog(capture, "json", "debug")
    bridge = Bridge(cfg, [node], log).open()
    assert [s.kind for s in bridge.runs[0].loop.sinks] == ["state-log"]  # told at open, by the kind
    try:
        bridge.start()
        wait_for(lambda: bridge.counters()["g"]["updates"] >= 20, what="updates from the example source")
    finally:
        bridge.stop()
        log.close()
    lines = [line.split() for line in log_path.read_text().splitlines()]
    # warm-up (no verdict), the still grasp, and the stopped bridge's last snapshot
    assert [(n, m, said) for n, _, m, said in lines] == [
        ("g", "peak-shift", "unknown"), ("g", "peak-shift", "stable"), ("g", "peak-shift", "unknown")], lines
    start = capture.events("start")[0]
    assert start["sources"] == "const" and start["outputs"] == str(log_path)


def test_the_new_kinds_keys_are_checked_like_every_section(kinds, tmp_path):
    text = config(tmp_path / "x.log")
    with pytest.raises(ProfileError, match=r"\[node\[0\]\] valeu: unknown key; did you mean 'value'"):
        parse_bridge_config(text.replace("value =", "valeu ="), "b.toml")
    with pytest.raises(ProfileError, match=r"\[state-log\] paht: unknown key; did you mean 'path'"):
        parse_bridge_config(text.replace("path =", "paht =", 1), "b.toml")
    with pytest.raises(ProfileError, match=r"\[node\[0\]\] value: expected a number"):
        parse_bridge_config(text.replace("600.0", '"600"'), "b.toml")


def test_the_page_method_finds_its_slip(kinds):
    """The page's method decides: a press that moves from one taxel to the next is a slip."""
    x, y = np.tile(np.arange(5) * 5.0, 5), np.repeat(np.arange(5) * 5.0, 5)
    det = kinds.METHOD.stream(DetectorSettings(), x, y, 100.0)
    forces = np.zeros((200, 25))
    forces[:, 12] = 4.0
    forces[100:, 12], forces[100:, 13] = 1.0, 4.0
    states = [u.state for u in det.feed(np.arange(200) / 100.0, forces)]
    assert int(GraspState.SLIP) not in states[:8] and int(GraspState.SLIP) in states
    assert kinds.METHOD.scores[0].name == "peak_moves" == det.columns[0]


def test_the_page_method_reads_its_own_section(kinds, tmp_path):
    """``[detector.peak_shift]`` is the page's method's: read into its dataclass, checked
    (an unknown key and a value past its bounds are one line naming the file), shown,
    and handed to its detector."""
    from eskin_industrial.profile import load_profile

    path = peak_shift_profile(tmp_path)
    base = Path(path).read_text()
    assert kinds.METHOD.settings_of(load_profile(path).detector).margin == 1.2  # left out: the defaults
    Path(path).write_text(base + "\n[detector.peak_shift]\nmargin = 3.0\n")
    detector = load_profile(path).detector
    assert kinds.METHOD.settings_of(detector) == kinds.PeakShiftSettings(margin=3.0)
    assert load_profile(path).to_table()["detector"]["peak_shift"] == {"margin": 3.0}
    # and the Sparkplug DBIRTH's Method properties carry it, as a built-in method's
    from eskin_industrial.outputs.sparkplug import payload as pb
    from eskin_industrial.outputs.sparkplug.properties import method_properties

    assert method_properties(load_profile(path)) == (
        ("method", (pb.STRING, "peak-shift")), ("detector.peak_shift.margin", (pb.DOUBLE, 3.0)),
        ("detector.contact_threshold_n", (pb.DOUBLE, 0.2)))
    x, y = np.tile(np.arange(5) * 5.0, 5), np.repeat(np.arange(5) * 5.0, 5)
    assert kinds.METHOD.stream(detector, x, y, 100.0).margin == 3.0
    for bad, message in (("margn = 3.0", r"\[detector\] peak_shift.margn: unknown key; did you mean 'margin'\?"),
                         ("margin = 0.5", r"\[detector\] peak_shift.margin: expected a value in \[1, 10\], got 0.5")):
        (tmp_path / "bad.toml").write_text(base + f"\n[detector.peak_shift]\n{bad}\n")
        with pytest.raises(ProfileError, match=rf"^{re.escape(str(tmp_path / 'bad.toml'))}: {message}$"):
            load_profile(tmp_path / "bad.toml")


def test_the_page_method_keeps_the_promises(kinds):
    from eskin_industrial.testing import check_method

    check_method("peak-shift")
