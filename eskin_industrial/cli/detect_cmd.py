"""``eskin-bus detect``: run a detector over a recording, offline."""

from __future__ import annotations

import json
import sys

import click
import numpy as np

from ..calibration import Calibrator, full_scale
from ..detect.hygiene import TIME_FAULTS, rate_problem, time_verdicts
from ..detect.methods import METHODS, get_method
from ..detect.state import GraspState
from ..detect.updates import COLUMNS, UpdateTable
from ..errors import InputFormatError
from ..frames import FrameFlag
from ..profile import Profile
from ..recording import read_recording, write_updates
from .common import open_profile, profile_option
from .console import PROGRESS_DELAY_S, Counter, Ticker


@click.command()
@profile_option()
@click.argument("input_path", metavar="INPUT.csv", required=False, type=click.Path(dir_okay=False, allow_dash=True))
@click.option("--can-log", default=None, type=click.Path(dir_okay=False, allow_dash=True),
              help="Instead of INPUT.csv: a CAN log (.log candump, .blf, .asc, ...) of the profile's node; "
                   "'-': candump -L lines from stdin, each update written as soon as its scan is complete "
                   "(candump -L can0 | eskin-bus detect -p P --can-log -).")
@click.option("-o", "--output", default="-", type=click.Path(dir_okay=False, allow_dash=True), show_default=True,
              help="Output CSV, one row per detector update ('-' for stdout).")
@click.option("--method", type=click.Choice(sorted(METHODS)), default=None,
              help="Detection method (default: the profile's).")
@click.option("--rate", "rate_hz", type=float, default=None,
              help="Sample rate in Hz (default: from the timestamps; the profile's if there are too few).")
@click.option("--engine", type=click.Choice(["batch", "stream"]), default="batch", show_default=True,
              help="Vectorized over the whole file, or frame by frame as the bridge runs (same output).")
@click.option("--changes", is_flag=True, help="Write only the updates where the state changes (and the first).")
@click.option("--fail-on-time-faults", is_flag=True,
              help="Exit 2 (after writing the output) if any frame of INPUT.csv was refused for its time: "
                   "repeated, backward, or no time (NaN, infinite, beyond 1e10 s).  (A CAN log's scans are "
                   "timed by the node's counter.)")
@click.option("--json", "as_json", is_flag=True,
              help="The summary on stderr as one JSON object (input, frames, rate, method, updates, states, "
                   "refused times, and a CAN log's transport counters).")
@click.option("-q", "--quiet", is_flag=True, help="No summary on stderr.")
def detect(profile_path: str, input_path: str | None, can_log: str | None, output: str, method: str | None,
           rate_hz: float | None, engine: str, changes: bool, fail_on_time_faults: bool, as_json: bool,
           quiet: bool) -> None:
    """Detect grasp states in a recording CSV (header t,f0,...,f{n-1} in newtons,
    or t,raw0,... in the profile's raw unit), or in a CAN log (--can-log)."""
    prof = open_profile(profile_path)
    if (input_path is None) == (can_log is None):
        raise click.UsageError("give exactly one of INPUT.csv or --can-log LOG")
    if can_log == "-":  # live: a row as soon as its scan is complete
        _detect_live(prof, output, rate_hz, method, changes, as_json, quiet)
        return
    with Ticker(own_quiet=quiet, delay_s=PROGRESS_DELAY_S) as ticker:
        table, name, time_faults = _detect_file(prof, input_path, can_log, rate_hz, method, engine, as_json, quiet,
                                                ticker)
    if changes:
        keep = np.ones(len(table), bool)
        keep[1:] = table.state[1:] != table.state[:-1]
        table = UpdateTable(**{c: getattr(table, c)[keep] for c in COLUMNS})
    write_updates(output, table)
    refused = sum(time_faults.values())
    if fail_on_time_faults and refused:
        raise InputFormatError(f"{name}: {refused} frames refused for their time ({_faults(time_faults)}); "
                               "--fail-on-time-faults")


def _detect_file(prof: Profile, input_path: str | None, can_log: str | None, rate_hz: float | None,
                 method: str | None, engine: str, as_json: bool, quiet: bool,
                 ticker: Ticker) -> tuple[UpdateTable, str, dict[str, int]]:
    """The updates of a recording or a CAN log file, its name and its refused times;
    the summary on stderr (after the bar) unless quiet."""
    time_faults: dict[str, int] = {}
    name = ""
    if can_log is not None:  # the live receiver's path, on recorded traffic: same output
        from ..bus.can.log import detect_log

        table, counters = detect_log(prof, can_log, rate_hz, method, progress=ticker)
        ticker.close()
        if not quiet:
            _summary(can_log, counters["scans"], rate_hz or prof.sensor.rate_hz, method or prof.detector.method,
                     table, {k: counters[k] for k in TIME_FAULTS.values()}, as_json, counters)
    else:
        assert input_path is not None  # exactly one of the two, checked above
        rec = read_recording(input_path, prof.taxels, progress=ticker)
        name = rec.name
        if rate_hz is not None and not (rate_hz > 0 and np.isfinite(rate_hz)):
            raise InputFormatError(f"--rate: expected a positive sample rate, got {rate_hz}")
        expected = rate_hz if rate_hz is not None else prof.sensor.rate_hz
        problem = rate_problem(rec.t, expected, "--rate" if rate_hz is not None else f"profile {prof.name}'s rate_hz")
        if problem is not None:
            raise InputFormatError(f"{rec.name}: {problem}")
        values = rec.values
        if rec.unit == "raw":
            values, flags = Calibrator.from_section(prof.calibration, prof.taxels).to_newtons(values)
        else:  # newtons: the same full-scale rule as a calibrated scan
            values, flags = full_scale(values, prof.calibration.full_scale_n)
        verdicts = time_verdicts(rec.t)
        time_faults = {name: int(np.count_nonzero(verdicts == code)) for code, name in TIME_FAULTS.items()}
        rate = rate_hz if rate_hz is not None else rec.rate_hz(prof.sensor.rate_hz)
        settings = prof.detector
        chosen = get_method(method or settings.method)
        if chosen.needs_model:  # learned: the default model, trained on the tuning seeds
            from ..evaluation.train import ready

            chosen = ready(chosen)
        x, y = prof.coordinates_mm
        if engine == "batch" and chosen.vectorized:
            table = chosen.batch(settings, x, y, rate, rec.t, values, flags)
        else:  # the stream detector, fed in pieces to show progress: the same updates as all at once
            det = chosen.stream(settings, x, y, rate)
            ticker.stage("detecting", len(rec.t))
            updates = []
            for a in range(0, len(rec.t), _PIECE_FRAMES):
                b = a + _PIECE_FRAMES
                updates += det.feed(rec.t[a:b], values[a:b], flags[a:b])
                ticker.advance(len(rec.t[a:b]))
            table = UpdateTable.from_updates(updates)
        ticker.close()
        if not quiet:
            _summary(rec.name, len(rec.t), rate, chosen.name, table, time_faults, as_json)
    return table, name, time_faults


#: Frames fed to a stream detector at a time (progress between pieces).
_PIECE_FRAMES = 10_000


def _faults(time_faults: dict[str, int]) -> str:
    return ", ".join(f"{k} {v}" for k, v in time_faults.items() if v)


def _summary(name: str, frames: int, rate: float, method: str, table: UpdateTable, time_faults: dict[str, int],
             as_json: bool, transport: dict[str, int] | None = None) -> None:
    """One line on stderr: prose, or with --json one object; the same figures for a
    recording, a CAN log and a live log."""
    counts = {s.label: int(np.sum(table.state == s)) for s in GraspState}
    # (WARMUP and TURN_UNSEEN say what the update could not do, not what was wrong with a frame)
    flagged = int(np.sum(table.flags & ~int(FrameFlag.WARMUP | FrameFlag.TURN_UNSEEN) != 0))
    unseen = int(np.sum(table.flags & int(FrameFlag.TURN_UNSEEN) != 0))
    valid = int(table.valid.sum())
    refused = sum(time_faults.values())
    if as_json:
        line = json.dumps({"input": name, "frames": frames, "rate_hz": rate, "method": method,
                           "updates": len(table), "valid": valid, "flagged": flagged, "turn_unseen": unseen,
                           "states": counts,
                           "refused_times": time_faults, **({"transport": transport} if transport else {})})
    else:
        states = ", ".join(f"{k} {v}" for k, v in counts.items())
        line = (f"{name}: {frames} {'scans' if transport else 'frames'} at {rate:.1f} Hz, method {method} -> "
                f"{len(table)} updates ({valid} valid, {flagged} with flagged frames, {unseen} turn unseen); {states}; "
                f"{refused} frames refused for their time" + (f" ({_faults(time_faults)})" if refused else ""))
        if transport:
            line += "; " + ", ".join(f"{k} {v}" for k, v in transport.items()
                                     if v and k not in time_faults and k not in ("scans", "updates"))
    click.echo(line, err=True)
    sys.stderr.flush()


def _detect_live(prof, output: str, rate_hz: float | None, method: str | None, changes: bool, as_json: bool,
                 quiet: bool) -> None:
    from ..bus.can.log import detect_live_log
    from ..detect.updates import Update
    from ..recording import update_row

    updates: list[Update] = []
    last: list[int] = []

    # no length to show a share of: a count of the updates, once it has run a second
    with click.open_file(output, "w", encoding="utf-8") as out, \
            Counter("updates", own_quiet=quiet, delay_s=PROGRESS_DELAY_S, stdout_data=output == "-") as counter:
        out.write(",".join(COLUMNS) + "\n")
        out.flush()

        def emit(u: Update) -> None:
            updates.append(u)
            counter.add()
            if changes and last and last[0] == u.state:
                return
            last[:] = [u.state]
            out.write(update_row(u, GraspState(u.state).label))
            out.flush()  # a pipe's reader sees each row as it comes

        counters = detect_live_log(prof, sys.stdin, emit, rate_hz, method)
    if not quiet:
        table = UpdateTable.from_updates(updates)
        _summary("<stdin>", counters["scans"], rate_hz or prof.sensor.rate_hz, method or prof.detector.method,
                 table, {k: counters[k] for k in TIME_FAULTS.values()}, as_json, counters)
