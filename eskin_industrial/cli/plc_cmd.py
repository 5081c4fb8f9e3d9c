"""``eskin-bus plc map``: the PLC register map of a profile, as CSV or Markdown."""

from __future__ import annotations

import csv
import sys

import click

from ..plc.image import map_rows
from .common import open_profile, profile_option
from .console import echo_json

_COLUMNS = ("table", "name", "address", "ref", "type", "unit", "access", "description")
_HEAD = ("table", "name", "address (0-based)", "reference (1-based)", "type", "unit", "access", "description")


@click.group()
def plc() -> None:
    """The PLC side: register map."""


@plc.command("map")
@profile_option()
@click.option("--format", "fmt", type=click.Choice(["csv", "md", "json"]), default="md", show_default=True,
              help="A table (CSV or Markdown), or JSON: a list of rows with the same keys.")
def map_cmd(profile_path: str, fmt: str) -> None:
    """Print the register map (holding registers, coils, discrete inputs) with the
    profile's base address: 0-based protocol addresses and 1-based references
    (4xxxx holding, 0xxxx coils, 1xxxx discrete inputs).  R_COE and R_DW are the
    paper's indicators; METHOD_ID, SCORE_A and SCORE_B are described for the profile's
    ``[detector] method``."""
    prof = open_profile(profile_path)
    rows = map_rows(prof.modbus.plc, prof.detector.method)
    if fmt == "json":
        echo_json([{c: r[c] for c in _COLUMNS} for r in rows])
        return
    if fmt == "csv":
        w = csv.writer(sys.stdout, lineterminator="\n")
        w.writerow(_COLUMNS)
        for r in rows:
            w.writerow([r[c] for c in _COLUMNS])
        return
    click.echo(markdown(rows))


def markdown(rows: list[dict[str, str]]) -> str:
    lines = ["| " + " | ".join(_HEAD) + " |", "|" + "---|" * len(_HEAD)]
    for r in rows:
        lines.append("| " + " | ".join(r[c].replace("|", "\\|") for c in _COLUMNS) + " |")
    return "\n".join(lines)


from .plc_export_cmd import export  # noqa: E402  (its own module: the import files)

plc.add_command(export)
