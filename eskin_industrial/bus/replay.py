"""Scans replayed in real time, as if polled: a recording CSV, or a scene rendered by
the scene simulator (``eskin-bus bridge --source scene:case2``: the whole chain with
no hardware)."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..calibration import Calibrator
from ..errors import EskinError
from ..frames import RawScan
from ..profile import Profile
from ..seam import NodeLike, OpenContext
from .source import OptionsT, Source


def _rate_problem(t: np.ndarray, node: NodeLike[Any]) -> str | None:
    """The check ``detect`` makes on a recording, against the node's rate (``--rate``,
    else the profile's): one rule for every file source."""
    from ..detect.hygiene import rate_problem

    return rate_problem(t, node.rate_hz, "the node's rate_hz (--rate, else the profile's)")


class ReplaySource(Source[OptionsT]):
    """Raw scans played at ``rate_hz`` (any speed), as if polled; scan times are the
    recording's (each loop continues them)."""

    def __init__(self, profile: Profile, t: np.ndarray, raw: np.ndarray, rate_hz: float, *, loop: bool = False,
                 where: str = "replay") -> None:
        super().__init__()
        self.t, self.raw, self.rate_hz, self.loop = t, raw, rate_hz, loop
        self.k = 0
        self.where = where
        self._next = time.monotonic()

    @property
    def done(self) -> bool:
        return not self.loop and self.k >= len(self.t)

    def _poll(self, timeout_s: float | None) -> RawScan | None:
        now = time.monotonic()
        if self._next > now:
            time.sleep(self._next - now)
        self._next = max(self._next, now) + 1.0 / self.rate_hz
        if self.done:
            return None
        lap, i = divmod(self.k, len(self.t))
        self.k += 1
        # The recording's own time (each loop continues it), whatever the replay speed.
        t = float(self.t[i]) + lap * (float(self.t[-1] - self.t[0]) + 1.0 / self.rate_hz)
        return RawScan(self.k - 1, t, self.raw[i], 0, time.monotonic())

    def describe_where(self) -> str:
        return self.where


@dataclass(frozen=True)
class SceneOptions:
    """``[[node]]`` keys of ``source = "scene"``: a built-in scene (or a scene .toml)
    rendered at the node's rate and played in real time."""

    scene: str
    seed: int = 0
    loop: bool = True


class SceneSource(ReplaySource["SceneOptions"]):
    kind = "scene"
    spec = "scene:NAME"
    Options = SceneOptions

    @classmethod
    def options_from_spec(cls, where: str, bus: dict[str, Any]) -> dict[str, Any]:
        if not where:
            raise ValueError("expected scene:NAME (eskin-bus simulate --list names them)")
        return {"scene": where}

    @classmethod
    def describe(cls, node: NodeLike[SceneOptions]) -> str:
        return f"scene {node.options.scene}"

    @classmethod
    def check(cls, node: NodeLike[SceneOptions], base_dir: str) -> None:
        from ..scenes import load_scene

        try:
            spec = load_scene(node.options.scene)
        except EskinError as exc:
            raise ValueError(f"scene: {exc}") from None
        taxels = spec.array.rows * spec.array.cols  # what open_node renders, without rendering it
        if taxels != node.profile.taxels:
            raise ValueError(f"scene: {node.options.scene} has {taxels} taxels ({spec.array.rows}x{spec.array.cols}, "
                             f"for profile {spec.scene.profile}), profile {node.profile.name} has {node.profile.taxels}")

    @classmethod
    def open_node(cls, node: NodeLike[SceneOptions], context: OpenContext) -> SceneSource:
        from ..scenes import render

        o, prof = node.options, node.profile
        rec = render(o.scene, node.rate_hz, o.seed)
        if rec.forces.shape[1] != prof.taxels:
            raise EskinError(f"node {node.name!r}: scene {o.scene} has {rec.forces.shape[1]} taxels, "
                             f"profile {prof.name} has {prof.taxels}")
        raw = np.rint(Calibrator.from_section(prof.calibration, prof.taxels).to_raw(rec.forces))
        return cls(prof, rec.t, raw, node.rate_hz, loop=o.loop, where=f"scene {o.scene}")


@dataclass(frozen=True)
class RecordingOptions:
    """``[[node]]`` keys of ``source = "recording"``: a recording CSV (``t,f0,...`` in
    newtons or ``t,raw0,...``) played at the node's rate."""

    path: str
    loop: bool = True


class RecordingSource(ReplaySource["RecordingOptions"]):
    kind = "recording"
    spec = "recording:FILE.csv"
    Options = RecordingOptions

    @classmethod
    def options_from_spec(cls, where: str, bus: dict[str, Any]) -> dict[str, Any]:
        if not where:
            raise ValueError("expected recording:FILE.csv")
        return {"path": where}

    @classmethod
    def describe(cls, node: NodeLike[RecordingOptions]) -> str:
        return f"recording {node.options.path}"

    @classmethod
    def check(cls, node: NodeLike[RecordingOptions], base_dir: str) -> None:
        from ..recording import read_recording

        try:
            rec = read_recording(node.options.path, node.profile.taxels)
        except EskinError as exc:
            raise ValueError(f"path: {exc}") from None
        problem = _rate_problem(rec.t, node)
        if problem is not None:
            raise ValueError(f"path: {rec.name}: {problem}")

    @classmethod
    def open_node(cls, node: NodeLike[RecordingOptions], context: OpenContext) -> RecordingSource:
        from ..recording import read_recording

        prof = node.profile
        rec = read_recording(node.options.path, prof.taxels)
        problem = _rate_problem(rec.t, node)
        if problem is not None:  # (a file that changed since the check)
            raise EskinError(f"node {node.name!r}: {rec.name}: {problem}")
        raw = rec.values if rec.unit == "raw" else \
            Calibrator.from_section(prof.calibration, prof.taxels).to_raw(rec.values)
        # played at the pace its timestamps show (the detector runs at the node's rate)
        return cls(prof, rec.t, raw, rec.rate_hz(node.rate_hz), loop=node.options.loop,
                   where=f"recording {node.options.path}")
