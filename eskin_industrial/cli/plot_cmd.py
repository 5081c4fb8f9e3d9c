"""``eskin-bus plot``: a recording's force, scores, detected states and truth over time, as a PNG
(the figure: plot_figure.py)."""

from __future__ import annotations

import click
import numpy as np

from ..detect.state import LABELS, GraspState
from ..errors import InputFormatError
from ..methods import method_names
from ..offline import Detected, detect_can_log, detect_recording
from ..profile import Profile
from .common import open_profile, profile_option
from .plot_figure import PlotData, centre_of_force, state_figure


@click.command()
@profile_option()
@click.argument("input_path", metavar="[REC.csv]", required=False, type=click.Path(dir_okay=False, allow_dash=True))
@click.option("--can-log", default=None, type=click.Path(dir_okay=False),
              help="Plot a CAN log of the node's traffic instead (candump .log, .asc, .blf, ...).")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="PNG file to write.")
@click.option("-m", "--method", type=click.Choice(sorted(method_names())), default=None,
              help="Detection method (default: the profile's).")
@click.option("--labels", "labels_path", type=click.Path(dir_okay=False, exists=True), default=None,
              help="Ground truth (t,label, from `eskin-bus simulate --labels`) drawn under the states.")
def plot(profile_path: str, input_path: str | None, can_log: str | None, output: str, method: str | None,
         labels_path: str | None) -> None:
    """Draw a recording's total force, the method's two scores, the detected states
    as coloured bands and, with --labels, the truth in a lane below (or a CAN log's,
    through the live receiver's decoding)."""
    if (input_path is None) == (can_log is None):
        raise click.UsageError("give exactly one of REC.csv or --can-log LOG")
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        from ..errors import MissingExtra

        raise MissingExtra.of("plot", "matplotlib", "plot") from None
    prof = open_profile(profile_path)
    if can_log is not None:  # the live receiver's decoding, as detect --can-log
        found = detect_can_log(prof, can_log, method=method, keep_forces=True)
    else:
        assert input_path is not None  # exactly one of the two, checked above
        found = detect_recording(prof, input_path, method=method)
    data = plot_data(prof, found, labels_path)
    table = found.table
    fig = state_figure(plt, data)
    try:
        fig.savefig(output, dpi=100)
    except OSError as exc:
        raise InputFormatError(f"{output}: cannot write: {exc.strerror or exc}") from None
    finally:
        plt.close(fig)
    click.echo(f"{output}: {len(table)} updates, "
               + ", ".join(f"{s.label} {int(np.sum(table.state == s))}" for s in GraspState), err=True)


def plot_data(prof: Profile, found: Detected, labels_path: str | None) -> PlotData:
    """What the figure shows of a detection run (and of its truth, ``--labels``)."""
    assert found.t is not None and found.forces is not None  # (kept: asked for, or a recording's)
    t, values, name, rate, chosen, table = found.t, found.forces, found.name, found.rate_hz, found.method, found.table
    col_a, col_b = (s.name for s in chosen.scores)  # the deciding method's own scores
    if chosen.name.startswith("paper"):
        threshold, threshold_name = prof.detector.slip_r_coe, "slip threshold"
    else:
        threshold, threshold_name = 1.0, "threshold"
    return PlotData(t=t, total_n=np.nansum(values, axis=1),
                    centre_mm=centre_of_force(values, *prof.layout.coordinates_mm()), update_t=table.t,
                    states=np.asarray(LABELS)[np.asarray(table.state, dtype=int)],
                    scores=((col_a, table.score_a), (col_b, table.score_b)), threshold=threshold,
                    threshold_name=threshold_name, title=f"{name}: {chosen.name} on {prof.name}, {rate:.0f} Hz",
                    truth=_read_labels(labels_path) if labels_path is not None else None)


def _read_labels(path: str) -> tuple[np.ndarray, np.ndarray]:
    """The ground truth's (t, label) columns, as ``simulate --labels`` writes them."""
    data = np.genfromtxt(path, delimiter=",", names=True, dtype=None, encoding="utf-8")
    try:
        return np.atleast_1d(data["t"]).astype(float), np.atleast_1d(data["label"]).astype(str)
    except (ValueError, TypeError):
        raise InputFormatError(f"--labels: {path}: expected the columns t,label") from None
