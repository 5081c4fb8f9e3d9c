"""The conformance checks (eskin_industrial.testing) over every built-in method, source
kind and output kind, each on what it really talks to (a virtual CAN bus with a node
sending, a CAN log, a serial line with an RTU node, an MQTT broker, a PLC client's
server on loopback); and each check fails, with one line, on a kind that breaks one of
the promises."""

from __future__ import annotations

import contextlib
import dataclasses
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner

from eskin_industrial import testing
from eskin_industrial.bus.source import SOURCES
from eskin_industrial.cli import main
from eskin_industrial.detect.methods import METHODS, Method, batch_via_stream, get_method
from eskin_industrial.detect.updates import UpdateTable
from eskin_industrial.outputs.base import SINKS
from eskin_industrial.profile import load_profile
from eskin_industrial.sim.modbus_node import NodeSimulator
from tests.helpers.bridge import channel, hold_raw, node_thread
from tests.helpers.modbus import free_port, pty_pair, slip_recording
from tests.helpers.paths import ROOT
from tests.helpers.sparkplug import (  # noqa: F401 - an autouse fixture: the edge node's state is the test's
    broker,
    state_home,
)

# -- every built-in method -------------------------------------------------------------

@pytest.mark.parametrize("name", list(METHODS))
def test_every_built_in_method_keeps_the_promises(name):
    testing.check_method(name)


# -- every built-in source kind, on what it reads ---------------------------------------

@contextlib.contextmanager
def _can(tmp: Path) -> Iterator[dict[str, Any]]:
    ch, prof = channel(), load_profile("paper-5x5")
    with node_thread(prof, ch, hold_raw(prof, 100)) as node:  # 1 s of scans (the block waits them out)
        node.start()
        yield {"interface": "virtual", "channel": ch}


@contextlib.contextmanager
def _can_log(tmp: Path) -> Iterator[dict[str, Any]]:
    log = tmp / "case2.log"
    res = CliRunner().invoke(main, ["simulate", "case2", "--can-log", str(log)])
    assert res.exit_code == 0, res.output
    yield {"path": str(log)}


@contextlib.contextmanager
def _rtu(tmp: Path) -> Iterator[dict[str, Any]]:
    _, forces, _ = slip_recording(still_s=3.0, slip_s=0.0, after_s=0.0)
    with pty_pair(tmp) as (a, b), NodeSimulator(load_profile("paper-5x5"), a, forces, 100.0):
        yield {"serial_port": b}


@contextlib.contextmanager
def _given(options: dict[str, Any]) -> Iterator[dict[str, Any]]:
    yield options


SOURCE_SETUPS: dict[str, Callable[[Path], contextlib.AbstractContextManager[dict[str, Any]]]] = {
    "can": _can,
    "can-log": _can_log,
    "modbus-rtu": _rtu,
    "scene": lambda tmp: _given({"scene": "case2"}),
    "recording": lambda tmp: _given({"path": str(ROOT / "examples" / "case2.csv")}),
}

#: Counter names seen so far, by kind: each check adds its own.  A node's counters are
#: one table (the loop's, its source's, each of its outputs'), so no output may share a
#: name with another output or with any source; sources may share theirs (a node has one).
_COUNTERS: dict[str, set[str]] = {}


def _own_counters(kind: str, names: set[str]) -> None:
    for other, theirs in _COUNTERS.items():
        if other != kind and "output" in (kind.split()[0], other.split()[0]):
            shared = sorted(names & theirs)
            assert not shared, f"{kind} and {other} both count {shared[0]!r}"
    _COUNTERS[kind] = names


def test_every_built_in_source_kind_has_a_setup_here():
    assert sorted(SOURCE_SETUPS) == sorted(SOURCES)


@pytest.mark.parametrize("kind", sorted(SOURCE_SETUPS))
def test_every_built_in_source_kind_keeps_the_promises(kind, tmp_path):
    with SOURCE_SETUPS[kind](tmp_path) as options:
        names = testing.check_source(kind, options)
    _own_counters(f"source {kind}", names)


# -- every built-in output kind, on what it talks to -------------------------------------

@contextlib.contextmanager
def _sparkplug(tmp: Path) -> Iterator[dict[str, Any]]:
    with broker(tmp) as port:
        yield {"broker": f"mqtt://127.0.0.1:{port}", "group_id": "conformance", "edge_node_id": "edge"}


SINK_SETUPS: dict[str, Callable[[Path], contextlib.AbstractContextManager[dict[str, Any]]]] = {
    "plc": lambda tmp: _given({"mode": "server", "host": "127.0.0.1", "port": free_port()}),
    "recorder": lambda tmp: _given({"path": str(tmp / "updates.csv")}),
    "sparkplug": _sparkplug,
    "opcua": lambda tmp: _given({"endpoint": f"opc.tcp://127.0.0.1:{free_port()}", "pki_dir": str(tmp / "pki")}),
    "web": lambda tmp: _given({"bind": f"127.0.0.1:{free_port()}"}),
}


def test_every_built_in_output_kind_has_a_setup_here():
    assert sorted(SINK_SETUPS) == sorted(SINKS)


@pytest.mark.parametrize("kind", [pytest.param(k, marks=pytest.mark.slow) if k == "opcua" else k  # (13 s: its server)
                                  for k in sorted(SINK_SETUPS)])
def test_every_built_in_output_kind_keeps_the_promises(kind, tmp_path):
    with SINK_SETUPS[kind](tmp_path) as options:
        names = testing.check_sink(kind, options)
    _own_counters(f"output {kind}", names)


def test_the_loop_counters_are_the_loops_own():
    assert {"scans", "updates", "publications", "state_changes"} <= testing.loop_counters()
    assert not testing.loop_counters() & {"plc_writes", "recorded_updates", "frames"}


# -- each check fails, in one line, on a kind that breaks a promise ---------------------

_track = get_method("cof-track")


def _short_batch(settings: Any, x: np.ndarray, y: np.ndarray, rate: float, t: Any, forces: Any,
                 flags: Any = None) -> UpdateTable:
    """cof-track's batch answer less its last update."""
    return UpdateTable.from_updates(_track.stream(settings, x, y, rate).feed(np.asarray(t), np.asarray(forces))[:-1])


def _stricter_batch(settings: Any, *args: Any) -> Any:
    """cof-track's batch answer with a threshold of its own: not what its stream says."""
    return _track.batch(dataclasses.replace(settings, cof_track=dataclasses.replace(settings.cof_track, z=2.0)), *args)


class _Rewrite:
    """A real detector whose updates are rewritten by ``change`` (a broken method)."""

    def __init__(self, change: Callable[[Any, int], Any], settings: Any, x: np.ndarray, y: np.ndarray,
                 rate: float) -> None:
        self.inner, self.change, self.n = _track.stream(settings, x, y, rate), change, 0

    def __getattr__(self, name: str) -> Any:
        return getattr(self.inner, name)

    def push(self, t: float, forces: np.ndarray, flags: int = 0) -> list[Any]:
        out = []
        for u in self.inner.push(t, forces, flags):
            out.append(self.change(u, self.n))
            self.n += 1
        return out

    def feed(self, t: np.ndarray, forces: np.ndarray, flags: np.ndarray | None = None) -> list[Any]:
        return [u for k in range(len(t)) for u in self.push(float(t[k]), forces[k], 0 if flags is None else int(flags[k]))]


def _rewriting(change: Callable[[Any, int], Any]) -> Callable[..., Any]:
    return lambda settings, x, y, rate: _Rewrite(change, settings, x, y, rate)


@dataclasses.dataclass
class _Loose:  # not frozen
    z: float = 1.0


@dataclasses.dataclass(frozen=True)
class _NoDefault:
    z: float


def _broken(name: str, **kw: Any) -> Method:
    kw.setdefault("stream", _track.stream)
    kw.setdefault("batch", batch_via_stream(kw["stream"]))
    return Method(name, "a broken method", kw.pop("stream"), kw.pop("batch"), code=4300, scores=_track.scores, **kw)


@pytest.mark.parametrize(("method", "message"), [
    (_broken("split", batch=_stricter_batch),
     r"method 'split': scene case2: the stream is not the batch answer: \w+ of update \d+ \(t = "),
    (_broken("fewer", batch=_short_batch),
     r"method 'fewer': scene case2: (\d+) updates frame by frame, (?!\1)\d+ in a batch"),
    (_broken("nan-score", stream=_rewriting(lambda u, k: u._replace(score_b=float("nan")) if k == 90 else u)),
     r"method 'nan-score': scene case2: score_b is not finite at t = 0\.9\d+ s \(nan\)"),
    (_broken("odd-state", stream=_rewriting(lambda u, k: u._replace(state=7) if k == 200 else u)),
     r"method 'odd-state': scene case2: state 7 is no GraspState code \(0 no_contact, 1 stable"),
    (_broken("early", stream=_rewriting(lambda u, k: u._replace(state=1) if k == 0 else u)),
     r"method 'early': scene case2: state 1 at t = 0\.\d+ s, before the first contact"),
    (_broken("loose", settings=_Loose), r"method 'loose': its settings must be a frozen dataclass"),
    (_broken("no-default", settings=_NoDefault),
     r"method 'no-default': its settings need a default for every key: detector.no_default.z: missing key"),
])
def test_check_method_names_the_broken_promise(monkeypatch, method, message):
    monkeypatch.setitem(METHODS, method.name, method)
    with pytest.raises(AssertionError, match=message) as caught:
        testing.check_method(method.name)
    assert "\n" not in str(caught.value)


def test_check_method_refuses_an_unregistered_method():
    with pytest.raises(AssertionError, match=r"method 'nowhere': unknown detection method 'nowhere'"):
        testing.check_method(_broken("nowhere"))


def test_check_source_names_the_broken_promise(tmp_path):
    with pytest.raises(AssertionError, match=r"source kind 'scene': its Options refuse the table given: "
                                             r"scene.scen: unknown key; did you mean 'scene'"):
        testing.check_source("scene", {"scen": "case2"})
    # a recording of 4 taxels played to a 25-taxel profile
    (tmp_path / "small.csv").write_text("t,f0,f1,f2,f3\n" + "".join(f"{k / 100:.2f},1,1,1,1\n" for k in range(50)))
    with pytest.raises(AssertionError, match=r"source kind 'recording': "):
        testing.check_source("recording", {"path": str(tmp_path / "small.csv")})


def test_check_sink_names_the_broken_promise(monkeypatch, tmp_path):
    from eskin_industrial.outputs.recorder import sink as recorder

    monkeypatch.setattr(recorder.Recorder, "counters", lambda self: {"scans": 1})
    with pytest.raises(AssertionError, match=r"output kind 'recorder': counter 'scans' is the node loop's own"):
        testing.check_sink("recorder", {"path": str(tmp_path / "r.csv")})
    monkeypatch.undo()
    calls: list[int] = []
    original = recorder.Recorder.close

    def close_once(self: Any) -> None:
        calls.append(1)
        if len(calls) > 1:
            raise RuntimeError("closed already")
        original(self)

    monkeypatch.setattr(recorder.Recorder, "close", close_once)
    with pytest.raises(AssertionError, match=r"output kind 'recorder': the second close raised RuntimeError: "
                                             r"closed already"):
        testing.check_sink("recorder", {"path": str(tmp_path / "r2.csv")})
    monkeypatch.undo()
    from eskin_industrial.outputs.recorder.kind import RecorderKind

    # a kind that opens its sinks past open_nodes: none is told the kind's name
    monkeypatch.setattr(RecorderKind, "open_nodes", classmethod(lambda cls, o, nodes, c: cls._open_nodes(o, nodes, c)))
    with pytest.raises(AssertionError, match=r"output kind 'recorder': its sink says kind '': open_nodes tells "
                                             r"each sink the kind's name"):
        testing.check_sink("recorder", {"path": str(tmp_path / "r3.csv")})
