"""The two seams as docs/architecture.md shows them: a new source kind and a new
output kind are each one module plus one registry entry, and the bridge
configuration, ``--check`` and the runtime take them with no other change."""

from __future__ import annotations

import sys
import textwrap

import pytest

from eskin_industrial.bridge.config import output_classes, parse_bridge_config, resolve
from eskin_industrial.bridge.logs import EventLog
from eskin_industrial.bridge.runtime import Bridge
from eskin_industrial.bus.source import SOURCES
from eskin_industrial.errors import ProfileError
from eskin_industrial.sinks.base import SINKS
from tests.helpers.bridge import LogCapture, wait_for
from tests.helpers.paths import PROFILES

MODULE = '''
import time
from dataclasses import dataclass

import numpy as np

from eskin_industrial.bus.source import Source
from eskin_industrial.frames import RawScan
from eskin_industrial.sinks.base import CliOption, Sink


@dataclass(frozen=True)
class ConstOptions:
    value: float = 0.0


class ConstSource(Source):
    kind = "const"
    spec = "const"
    Options = ConstOptions

    def __init__(self, taxels, value):
        super().__init__()
        self.raw, self.seq = np.full(taxels, value), -1

    def _poll(self, timeout_s):
        time.sleep(0.01)
        self.seq += 1
        return RawScan(self.seq, self.seq * 0.01, self.raw, 0, time.monotonic())

    @classmethod
    def open_node(cls, node, context):
        return cls(node.profile.taxels, node.options.value)


@dataclass(frozen=True)
class SeenOptions:
    prefix: str = "seen"


class SeenSink(Sink):
    kind = "seen"
    Options = SeenOptions
    cli_options = (CliOption("--seen", "prefix", "Keep every update.", metavar="PREFIX"),)
    opened = []

    def __init__(self, node_name, prefix):
        super().__init__()
        self.where = f"{prefix}:{node_name}"
        self.updates = []
        self.publications = []

    def on_update(self, update):
        self.updates.append(update)

    def _publish(self, publication):
        self.publications.append(publication)

    @classmethod
    def describe(cls, options, node):
        return f"seen {options.prefix}"

    @classmethod
    def open_nodes(cls, options, nodes, context):
        sinks = [cls(n.name, options.prefix) for n in nodes]
        cls.opened.extend(sinks)
        return sinks
'''


@pytest.fixture
def kinds(tmp_path, monkeypatch):
    (tmp_path / "mykinds.py").write_text(textwrap.dedent(MODULE))
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setitem(SOURCES, "const", "mykinds:ConstSource")  # the one registry entry each
    monkeypatch.setitem(SINKS, "seen", "mykinds:SeenSink")
    yield
    sys.modules.pop("mykinds", None)


def config(tmp_path, extra: str = "") -> str:
    return (f'[log]\nformat = "json"\nstatus_every_s = 0\n\n[seen]\nprefix = "cell7"\n{extra}\n'
            f'[[node]]\nname = "g"\nprofile = "{PROFILES / "paper-5x5.toml"}"\nsource = "const"\nvalue = 1500.0\n')


def test_a_new_source_and_a_new_output_run_in_the_bridge(kinds, tmp_path):
    cfg = parse_bridge_config(config(tmp_path), str(tmp_path / "b.toml"))
    (node,) = resolve(cfg)
    assert node.options.value == 1500.0 and [c.kind for c, _ in output_classes(cfg)] == ["seen"]
    capture = LogCapture()
    log = EventLog(capture, "json", "debug")
    bridge = Bridge(cfg, [node], log).open()
    try:
        bridge.start()
        sink = bridge.runs[0].sinks[0]
        wait_for(lambda: len(sink.updates) >= 20, what="updates from the new source in the new sink")
    finally:
        bridge.stop()
        log.close()
    assert sink.where == "cell7:g" and sink.publications[-1].offline  # BRIDGE_OFFLINE went to it too
    assert [u.t for u in sink.updates] == sorted(u.t for u in sink.updates)
    start = capture.events("start")[0]
    assert start["sources"] == "const" and start["outputs"] == "cell7:g"


def test_the_new_kinds_keys_are_checked_like_every_section(kinds, tmp_path):
    with pytest.raises(ProfileError, match=r"\[node\[0\]\] valeu: unknown key; did you mean 'value'"):
        parse_bridge_config(config(tmp_path).replace("value =", "valeu ="), "b.toml")
    with pytest.raises(ProfileError, match=r"\[seen\] prefx: unknown key; did you mean 'prefix'"):
        parse_bridge_config(config(tmp_path).replace("prefix =", "prefx ="), "b.toml")
    with pytest.raises(ProfileError, match=r"\[node\[0\]\] value: expected a number"):
        parse_bridge_config(config(tmp_path).replace("1500.0", '"1500"'), "b.toml")
