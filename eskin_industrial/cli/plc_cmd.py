"""``eskin-bus plc map``: the PLC register map of a profile, as CSV or Markdown."""

from __future__ import annotations

import csv
import sys

import click

from ..outputs.plc.image import map_rows
from .common import open_profile, profile_option
from .console import echo_json, json_alias

_COLUMNS = ("table", "name", "address", "ref", "type", "unit", "access", "description")
_HEAD = ("table", "name", "address (0-based)", "reference (1-based)", "type", "unit", "access", "description")


@click.group()
def plc() -> None:
    """The PLC side: register map."""


@plc.command("map")
@profile_option()
@click.option("--format", "fmt", type=click.Choice(["csv", "md", "json"]), default="md", show_default=True,
              help="A table (CSV or Markdown), or JSON: a list of rows with the same keys (and words), "
                   "the numbers as numbers.")
@json_alias
def map_cmd(profile_path: str, fmt: str) -> None:
    """Print the register map (holding registers, coils, discrete inputs) with the
    profile's base address: 0-based protocol addresses and 1-based references
    (4xxxx holding, 0xxxx coils, 1xxxx discrete inputs).  R_COE and R_DW are the
    paper's indicators; METHOD_ID, SCORE_A and SCORE_B are described for the profile's
    ``[detector] method``."""
    prof = open_profile(profile_path)
    rows = map_rows(prof.modbus.plc, prof.detector.method)
    if fmt == "json":
        echo_json([_json_row(r) for r in rows])
        return
    if fmt == "csv":
        w = csv.writer(sys.stdout, lineterminator="\n")
        w.writerow(_COLUMNS)
        for r in rows:
            w.writerow([r[c] for c in _COLUMNS])
        return
    click.echo(markdown(rows))


def _json_row(row: dict[str, str]) -> dict[str, str | int]:
    """A row with its numbers as numbers: ``address`` and ``ref`` those of the first
    word (the reference as the integer it reads, 40005; a coil's 00001 is 1), and
    ``words``, how many it takes (2 for a 32-bit pair, whose text reads "4-5")."""
    first, _, last = row["address"].partition("-")
    out: dict[str, str | int] = {c: row[c] for c in _COLUMNS}
    out["address"] = int(first)
    out["ref"] = int(row["ref"].partition("-")[0])
    out["words"] = int(last) - int(first) + 1 if last else 1
    return out


def markdown(rows: list[dict[str, str]]) -> str:
    lines = ["| " + " | ".join(_HEAD) + " |", "|" + "---|" * len(_HEAD)]
    for r in rows:
        lines.append("| " + " | ".join(r[c].replace("|", "\\|") for c in _COLUMNS) + " |")
    return "\n".join(lines)


from .plc_export_cmd import export  # noqa: E402  (its own module: the import files)

plc.add_command(export)
