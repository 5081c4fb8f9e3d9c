"""``eskin-bus plot``: a recording's indicators over time, states shaded, as a PNG."""

from __future__ import annotations

from typing import Any

import click
import numpy as np

from ..detect.state import GraspState
from ..errors import InputFormatError
from ..methods import method_names
from ..offline import detect_can_log, detect_recording
from .common import open_profile, profile_option

STATE_COLOURS = {GraspState.SLIP: "tab:red", GraspState.VARIABLE_FORCE: "tab:orange"}


@click.command()
@profile_option()
@click.argument("input_path", metavar="[REC.csv]", required=False, type=click.Path(dir_okay=False, allow_dash=True))
@click.option("--can-log", default=None, type=click.Path(dir_okay=False),
              help="Plot a CAN log of the node's traffic instead (candump .log, .asc, .blf, ...).")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="PNG file to write.")
@click.option("--method", type=click.Choice(sorted(method_names())), default=None, help="Detection method (default: the profile's).")
@click.option("--labels", "labels_path", type=click.Path(dir_okay=False, exists=True), default=None,
              help="Ground truth (t,label, from `eskin-bus simulate --labels`) drawn under the states.")
def plot(profile_path: str, input_path: str | None, can_log: str | None, output: str, method: str | None,
         labels_path: str | None) -> None:
    """Draw total force, the two indicators and the detected states of a recording
    (or of a CAN log, through the live receiver's decoding)."""
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
    assert found.t is not None and found.forces is not None  # (kept: asked for, or a recording's)
    t, values, name, rate, chosen, table = found.t, found.forces, found.name, found.rate_hz, found.method, found.table
    col_a, col_b = (s.name for s in chosen.scores)  # the deciding method's own scores

    fig, (ax_f, ax_r) = plt.subplots(2, 1, figsize=(11, 6), sharex=True, gridspec_kw={"height_ratios": [1, 2]})
    ax_f.plot(t, np.nansum(values, axis=1), color="k", lw=0.8)
    ax_f.set_ylabel("total force (N)")
    if labels_path is not None:
        _shade_labels(ax_r, labels_path)
    for state, colour in STATE_COLOURS.items():
        on = table.state == state
        ax_r.fill_between(table.t, 0, 1, where=on, transform=ax_r.get_xaxis_transform(), color=colour,
                          alpha=0.35, step="post", lw=0, label=f"detected {state.label}")
    ax_r.plot(table.t, table.score_a, lw=1.0, label=col_a)
    ax_r.plot(table.t, table.score_b, lw=1.0, label=col_b)
    if chosen.name.startswith("paper"):
        ax_r.axhline(prof.detector.slip_r_coe, color="k", ls="--", lw=0.8, label="slip threshold")
    else:
        ax_r.axhline(1.0, color="k", ls="--", lw=0.8, label="threshold")
    ax_r.set_yscale("symlog", linthresh=1.0)
    ax_r.set_ylim(bottom=0.0)
    ax_r.set_xlabel("time (s)")
    ax_r.legend(fontsize=8, ncol=3, loc="upper left")
    fig.suptitle(f"{name}: {chosen.name} on {prof.name}, {rate:.0f} Hz")
    fig.tight_layout()
    try:
        fig.savefig(output, dpi=100)
    except OSError as exc:
        raise InputFormatError(f"{output}: cannot write: {exc.strerror or exc}") from None
    finally:
        plt.close(fig)
    click.echo(f"{output}: {len(table)} updates, "
               + ", ".join(f"{s.label} {int(np.sum(table.state == s))}" for s in GraspState), err=True)


def _shade_labels(ax: Any, path: str) -> None:
    data = np.genfromtxt(path, delimiter=",", names=True, dtype=None, encoding="utf-8")
    t, labels = np.atleast_1d(data["t"]), np.atleast_1d(data["label"])
    from ..evaluation.metrics import spans

    for label, colour in (("slip", "tab:red"), ("variable_force", "tab:orange")):
        for a, b in spans(labels == label):
            ax.axvspan(t[a], t[b - 1], ymax=0.06, color=colour, alpha=0.9, lw=0)
