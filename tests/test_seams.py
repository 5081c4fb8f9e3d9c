"""The two seams as docs/architecture.md shows them: its example source kind and its
example output kind, taken from the page itself, are each one module plus one
registry entry, and the bridge configuration and the runtime take them with no other
change."""

from __future__ import annotations

import re
import sys

import pytest

from eskin_industrial.bridge.config import output_classes, parse_bridge_config, resolve
from eskin_industrial.bridge.logs import EventLog
from eskin_industrial.bridge.runtime import Bridge
from eskin_industrial.bus.source import SOURCES
from eskin_industrial.errors import ProfileError
from eskin_industrial.sinks.base import SINKS
from tests.helpers.bridge import LogCapture, wait_for
from tests.helpers.paths import PROFILES, ROOT

#: What the page's examples take as given.
PRELUDE = '''
import time
from dataclasses import dataclass

import numpy as np

from eskin_industrial.bus.source import Source
from eskin_industrial.detect.state import GraspState
from eskin_industrial.frames import RawScan
from eskin_industrial.sinks.base import CliOption, Sink
'''


def page_examples() -> str:
    """The Python blocks of docs/architecture.md, less their registry lines (the test
    makes those entries itself)."""
    text = (ROOT / "docs" / "architecture.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    assert len(blocks) == 2, "the page shows one source and one output"
    return PRELUDE + "\n".join(re.sub(r"^(SOURCES|SINKS)\[.*$", "", b, flags=re.M) for b in blocks)


@pytest.fixture
def kinds(tmp_path, monkeypatch):
    (tmp_path / "pagekinds.py").write_text(page_examples())
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setitem(SOURCES, "const", "pagekinds:ConstSource")  # the one registry entry each
    monkeypatch.setitem(SINKS, "state-log", "pagekinds:StateLog")
    yield
    sys.modules.pop("pagekinds", None)


def config(log_path) -> str:
    # 600 ohm on every taxel: about 4.4 N each, a firm still grasp
    return (f'[log]\nformat = "json"\nstatus_every_s = 0\n\n[state-log]\npath = "{log_path}"\n\n'
            f'[[node]]\nname = "g"\nprofile = "{PROFILES / "paper-5x5.toml"}"\nsource = "const"\nvalue = 600.0\n')


def test_the_page_examples_run_in_the_bridge(kinds, tmp_path):
    log_path = tmp_path / "states.log"
    cfg = parse_bridge_config(config(log_path), str(tmp_path / "b.toml"))
    (node,) = resolve(cfg)
    assert node.options.value == 600.0 and [c.kind for c, _ in output_classes(cfg)] == ["state-log"]
    capture = LogCapture()
    log = EventLog(capture, "json", "debug")
    bridge = Bridge(cfg, [node], log).open()
    try:
        bridge.start()
        wait_for(lambda: bridge.counters()["g"]["updates"] >= 20, what="updates from the example source")
    finally:
        bridge.stop()
        log.close()
    lines = log_path.read_text().splitlines()
    assert lines and lines[-1].startswith("g ") and lines[-1].endswith(" stable"), lines
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
