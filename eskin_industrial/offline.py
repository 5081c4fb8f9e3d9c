"""Detection from files, offline: a recording CSV (newtons or the node's raw unit), a
CAN log of the node's traffic (any format python-can reads) or a live candump stream,
to detector updates.

The one path every command that detects from a file takes (``eskin-bus detect``,
``eskin-bus plot``): the same calibration, the same rate checks, the method chosen and
bound to its model in one place (``methods.ready_method``, as the bridge and the
evaluation do), batch or stream.  What is transport-specific is reading, and stays
with the transport (``bus/can/log.py``: records, scan assembly, the log's checks); a
log's scans go through the live path's :class:`~eskin_industrial.pipeline.Pipeline`,
so that a log gives what the receiver gave, counters included.

The verdicts are the bridge's: a recording's frames are judged by the same
:class:`~eskin_industrial.detect.integrity.IntegrityWatch` as a node's scans
(:func:`~eskin_industrial.pipeline.frame_faults`), and while a sensor fault is set
(a dead, frozen or mistimed sensor; a log's stream fault too) an update shows no
verdict (:func:`~eskin_industrial.node.verdict.shown`), as every output of the bridge
does.

A rate given by the caller is named ``--rate`` in messages, as the commands take it.
"""

from __future__ import annotations

from collections.abc import Callable
from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Literal, TextIO

import numpy as np

from .bus.can.log import LiveLogScans, log_scans, require_scans
from .calibration import Calibrator, full_scale
from .detect.hygiene import TIME_FAULTS, TIME_KEPT, rate_problem, time_verdicts
from .detect.methods import Method
from .detect.updates import COLUMNS, Update, UpdateTable
from .errors import InputFormatError
from .frames import Frame, RawScan
from .methods import ready_method
from .node.verdict import shown
from .pipeline import Pipeline, frame_faults
from .profile import Profile
from .progress import NO_PROGRESS, Progress
from .recording import read_recording

Engine = Literal["batch", "stream"]

#: Frames fed to a stream detector at a time (progress between pieces).
_PIECE_FRAMES = 10_000
#: A log's scans between two reports of progress.
_PROGRESS_EVERY = 4096


@dataclass(frozen=True)
class Detected:
    """One input's updates, and what a summary says of them."""

    name: str  #: the input, as messages name it
    table: UpdateTable
    frames: int  #: a recording's frames, a log's complete scans
    rate_hz: float  #: the rate the detector ran at
    method: Method  #: the deciding method, bound to its model
    time_faults: dict[str, int]  #: frames refused for their time, by kind (``TIME_FAULTS``' names)
    #: A log's counters: the pipeline's, the refused times, the assembler's (None: a recording).
    transport: dict[str, int] | None = None
    #: The calibrated frames' times and forces in newtons, ``(frames, taxels)``: a
    #: recording's always, a log's when asked (``keep_forces``).
    t: np.ndarray | None = None
    forces: np.ndarray | None = None


def detect_recording(profile: Profile, source: str | Path, rate_hz: float | None = None, method: str | None = None,
                     engine: Engine = "batch", progress: Progress = NO_PROGRESS) -> Detected:
    """A recording CSV (``-``: stdin) through the detector: its rate checked against
    ``rate_hz`` or else the profile's, raw units calibrated by the profile and newtons
    held to its full scale, at the rate given or else the timestamps'.  ``engine``:
    vectorized over the whole file where the method has a batch form, or frame by
    frame (the same updates).  ``progress``: a stage reading, one detecting (stream)."""
    rec = read_recording(source, profile.taxels, progress=progress)
    if rate_hz is not None and not (rate_hz > 0 and np.isfinite(rate_hz)):
        raise InputFormatError(f"--rate: expected a positive sample rate, got {rate_hz}")
    expected = rate_hz if rate_hz is not None else profile.sensor.rate_hz
    problem = rate_problem(rec.t, expected, "--rate" if rate_hz is not None else f"profile {profile.name}'s rate_hz")
    if problem is not None:
        raise InputFormatError(f"{rec.name}: {problem}")
    if rec.unit == "raw":
        forces, flags = Calibrator.from_section(profile.calibration, profile.taxels).to_newtons(rec.values)
    else:  # newtons: the same full-scale rule as a calibrated scan
        forces, flags = full_scale(rec.values, profile.calibration.full_scale_n)
    verdicts = time_verdicts(rec.t)
    time_faults = {name: int(np.count_nonzero(verdicts == code)) for code, name in TIME_FAULTS.items()}
    rate = rate_hz if rate_hz is not None else rec.rate_hz(profile.sensor.rate_hz)
    settings = profile.detector
    chosen = ready_method(method, settings)
    x, y = profile.coordinates_mm
    if engine == "batch" and chosen.vectorized:
        table = chosen.batch(settings, x, y, rate, rec.t, forces, flags)
    else:  # the stream detector, fed in pieces to show progress: the same updates as all at once
        det = chosen.stream(settings, x, y, rate)
        progress.stage("detecting", len(rec.t))
        updates: list[Update] = []
        for a in range(0, len(rec.t), _PIECE_FRAMES):
            b = a + _PIECE_FRAMES
            updates += det.feed(rec.t[a:b], forces[a:b], flags[a:b])
            progress.advance(len(rec.t[a:b]))
        table = UpdateTable.from_updates(updates)
    table = _withdrawn(table, _update_faults(table, rec.t, verdicts,
                                             frame_faults(profile, rate, rec.t, forces, rec.values)))
    return Detected(rec.name, table, len(rec.t), rate, chosen, time_faults, t=rec.t, forces=forces)


def _update_faults(table: UpdateTable, t: np.ndarray, verdicts: np.ndarray, faults: np.ndarray) -> np.ndarray:
    """Each update's sensor-fault bits: those after the frame whose push gave it, as in
    the bridge (an update's time is its newest frame's, the first kept frame at or after
    it: a frame held across a short gap is decided when the next one comes)."""
    kept = np.flatnonzero(verdicts == TIME_KEPT)
    if not len(table) or not kept.size:
        return np.zeros(len(table), np.int64)
    at = np.minimum(np.searchsorted(t[kept], table.t, side="left"), kept.size - 1)
    return faults[kept[at]]


def _withdrawn(table: UpdateTable, faults: np.ndarray) -> UpdateTable:
    """The table with each update under a sensor fault shown as the outputs show it."""
    rows = np.flatnonzero(faults)
    if not rows.size:
        return table
    cols = {c: getattr(table, c).copy() for c in COLUMNS}
    for i in rows.tolist():  # (only the faulted rows: one rule, the outputs')
        u = shown(Update(*(cols[c][i] for c in COLUMNS)), int(faults[i]))
        for c, v in zip(COLUMNS, u):
            cols[c][i] = v
    return UpdateTable(**cols)


def detect_can_log(profile: Profile, path: str | Path, rate_hz: float | None = None, method: str | None = None,
                   progress: Progress = NO_PROGRESS, keep_forces: bool = False) -> Detected:
    """A CAN log of the node's traffic through the live path's assembler and pipeline
    (scans timed by the node's counter at ``rate_hz`` or else the profile's rate);
    ``progress``: a stage reading the file, one detecting."""
    rate = rate_hz or profile.sensor.rate_hz
    scans, assembled = log_scans(profile, path, rate, progress)
    pipeline = Pipeline(profile, rate_hz=rate, method=method)
    frames: list[Frame] | None = [] if keep_forces else None
    updates = _replay(scans, pipeline, progress, frames)
    counters = _counters(pipeline, assembled)
    require_scans(profile, counters, str(path))
    found = _detected(str(path), updates, rate, pipeline, counters)
    if frames is None:
        return found
    return replace(found, t=np.array([f.t for f in frames]), forces=np.stack([f.forces for f in frames]))


def detect_live_log(profile: Profile, stream: TextIO, emit: Callable[[Update], None], rate_hz: float | None = None,
                    method: str | None = None, name: str = "<stdin>",
                    whole: Callable[[], AbstractContextManager[object]] = nullcontext) -> Detected:
    """A candump -L stream read as it comes, each update handed to ``emit`` as soon
    as its scan is complete: the same assembler, checks and pipeline as
    :func:`detect_can_log`.  A live stream ends at its end, or when the reader is
    stopped (Ctrl-C, or SIGTERM as the command line turns it into one): what was
    read is then the result, as at an end.  ``whole``: a block a stop must not cut
    (each scan's updates, counted and emitted), which the command line's handler
    makes wait for its end."""
    rate = rate_hz or profile.sensor.rate_hz
    pipeline = Pipeline(profile, rate_hz=rate, method=method)
    scans = LiveLogScans(profile, stream, rate, name)
    updates: list[Update] = []
    stopped = False
    try:
        for scan in scans:
            with whole():
                for u in pipeline.shown(pipeline.push(scan)):
                    updates.append(u)
                    emit(u)
    except KeyboardInterrupt:
        stopped = True  # (a scan half read when it came is none)
    counters = _counters(pipeline, scans.counters())
    if not stopped:  # (a stop asked before the first scan is no foreign log)
        require_scans(profile, counters, name)
    return _detected(name, updates, rate, pipeline, counters)


def _replay(scans: list[RawScan], pipeline: Pipeline, progress: Progress, frames: list[Frame] | None) -> list[Update]:
    """Every scan through the pipeline, its updates; each calibrated frame appended to
    ``frames`` unless None."""
    updates: list[Update] = []
    progress.stage("detecting", len(scans))
    for i, scan in enumerate(scans, start=1):
        updates += pipeline.shown(pipeline.push(scan))
        if frames is not None and pipeline.last_frame is not None:  # (every push sets it)
            frames.append(pipeline.last_frame)
        if i % _PROGRESS_EVERY == 0:
            progress.advance(_PROGRESS_EVERY)
    progress.advance(len(scans) % _PROGRESS_EVERY)
    return updates


def _counters(pipeline: Pipeline, assembled: dict[str, int]) -> dict[str, int]:
    """A log's counters, in the order the summary lists them: the pipeline's, the
    times it refused by kind, the assembler's."""
    c = pipeline.counters
    return {k: v for k, v in vars(c).items() if k != "extra"} | pipeline.time_faults() | assembled


def _detected(name: str, updates: list[Update], rate: float, pipeline: Pipeline, counters: dict[str, int]) -> Detected:
    """A log's updates, and its counters as the summary reports them."""
    return Detected(name, UpdateTable.from_updates(updates), counters["scans"], rate, pipeline.method,
                    {k: counters[k] for k in TIME_FAULTS.values()}, counters)


__all__ = ["Detected", "Engine", "detect_can_log", "detect_live_log", "detect_recording"]
