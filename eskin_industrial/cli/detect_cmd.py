"""``eskin-bus detect``: run a detector over a recording, offline."""

from __future__ import annotations

import json
import sys
from typing import cast

import click
import numpy as np

from ..detect.state import GraspState
from ..detect.updates import COLUMNS, Update, UpdateTable
from ..errors import InputFormatError
from ..frames import SENSOR_FAULTS, FrameFlag
from ..methods import method_names
from ..offline import Detected, Engine, detect_can_log, detect_live_log, detect_recording
from ..profile import Profile
from ..recording import update_row, write_updates
from .common import check_output, open_profile, profile_option, writing
from .console import PROGRESS_DELAY_S, Counter, HeldInterrupt, Ticker


@click.command()
@profile_option()
@click.argument("input_path", metavar="INPUT.csv", required=False, type=click.Path(dir_okay=False, allow_dash=True))
@click.option("--can-log", default=None, type=click.Path(dir_okay=False, allow_dash=True),
              help="Instead of INPUT.csv: a CAN log (.log candump, .blf, .asc, ...) of the profile's node; "
                   "'-': candump -L lines from stdin, each update written as soon as its scan is complete "
                   "(candump -L can0 | eskin-bus detect -p P --can-log -).")
@click.option("-o", "--output", default="-", type=click.Path(dir_okay=False, allow_dash=True), show_default=True,
              help="Output CSV, one row per detector update ('-' for stdout).")
@click.option("-m", "--method", type=click.Choice(sorted(method_names())), default=None,
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
    check_output(output, "-o")  # before the input is read
    if can_log == "-":  # live: a row as soon as its scan is complete
        _detect_live(prof, output, rate_hz, method, changes, as_json, quiet)
        return
    with Ticker(own_quiet=quiet, delay_s=PROGRESS_DELAY_S) as ticker:
        if can_log is not None:  # the live receiver's path, on recorded traffic: same output
            found = detect_can_log(prof, can_log, rate_hz, method, progress=ticker)
        else:
            assert input_path is not None  # exactly one of the two, checked above
            found = detect_recording(prof, input_path, rate_hz, method, cast(Engine, engine), progress=ticker)
        ticker.close()
        if not quiet:
            _summary(found, as_json)
    table = found.table
    if changes:
        keep = np.ones(len(table), bool)
        keep[1:] = table.state[1:] != table.state[:-1]
        table = UpdateTable(**{c: getattr(table, c)[keep] for c in COLUMNS})
    with writing(output, "-o"):
        write_updates(output, table)
    refused = sum(found.time_faults.values())
    # (a log's scans are timed by the node's counter: its refused times are the transport's)
    if fail_on_time_faults and refused and found.transport is None:
        raise InputFormatError(f"{found.name}: {refused} frames refused for their time ({_faults(found.time_faults)}); "
                               "--fail-on-time-faults")


def _faults(time_faults: dict[str, int]) -> str:
    return ", ".join(f"{k} {v}" for k, v in time_faults.items() if v)


def _summary(found: Detected, as_json: bool) -> None:
    """One line on stderr: prose, or with --json one object; the same figures for a
    recording, a CAN log and a live log."""
    name, frames, rate, method, table = found.name, found.frames, found.rate_hz, found.method.name, found.table
    time_faults, transport = found.time_faults, found.transport
    counts = {s.label: int(np.sum(table.state == s)) for s in GraspState}
    # (WARMUP and TURN_UNSEEN say what the update could not do, not what was wrong with a frame)
    flagged = int(np.sum(table.flags & ~int(FrameFlag.WARMUP | FrameFlag.TURN_UNSEEN) != 0))
    faulted = int(np.sum(table.flags & SENSOR_FAULTS != 0))  # no verdict: the sensor was no sensor
    unseen = int(np.sum(table.flags & int(FrameFlag.TURN_UNSEEN) != 0))
    valid = int(table.valid.sum())
    refused = sum(time_faults.values())
    if as_json:
        line = json.dumps({"input": name, "frames": frames, "rate_hz": rate, "method": method,
                           "updates": len(table), "valid": valid, "flagged": flagged, "turn_unseen": unseen,
                           "sensor_fault": faulted,
                           "states": counts,
                           "refused_times": time_faults, **({"transport": transport} if transport else {})})
    else:
        states = ", ".join(f"{k} {v}" for k, v in counts.items())
        line = (f"{name}: {frames} {'scans' if transport else 'frames'} at {rate:.1f} Hz, method {method} -> "
                f"{len(table)} updates ({valid} valid, {flagged} with flagged frames, {unseen} turn unseen"
                + (f", {faulted} under a sensor fault: no verdict" if faulted else "") + f"); {states}; "
                f"{refused} frames refused for their time" + (f" ({_faults(time_faults)})" if refused else ""))
        if transport:
            line += "; " + ", ".join(f"{k} {v}" for k, v in transport.items()
                                     if v and k not in time_faults and k not in ("scans", "updates"))
    click.echo(line, err=True)
    sys.stderr.flush()


def _detect_live(prof: Profile, output: str, rate_hz: float | None, method: str | None, changes: bool,
                 as_json: bool, quiet: bool) -> None:
    last: list[int] = []

    # no length to show a share of: a count of the updates, once it has run a second
    with writing(output, "-o"), click.open_file(output, "w", encoding="utf-8") as out, \
            Counter("updates", own_quiet=quiet, delay_s=PROGRESS_DELAY_S, stdout_data=output == "-") as counter:
        out.write(",".join(COLUMNS) + "\n")
        out.flush()

        def emit(u: Update) -> None:
            counter.add()
            if changes and last and last[0] == u.state:
                return
            last[:] = [u.state]
            out.write(update_row(u, GraspState(u.state).label))
            out.flush()  # a pipe's reader sees each row as it comes

        with HeldInterrupt().installed() as held:  # a stop never between an update counted and written
            found = detect_live_log(prof, sys.stdin, emit, rate_hz, method, whole=held.whole)
    if not quiet:
        _summary(found, as_json)
