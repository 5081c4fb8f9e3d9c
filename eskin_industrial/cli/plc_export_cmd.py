"""``eskin-bus plc export``: the register map as files a PLC's engineering tool imports."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from ..plc.export import codesys_st, flat_csv, ident, tia_xlsx
from .common import open_profile, profile_option

#: File name (the profile's name in it) of each format.
_FILES = {"codesys": "eskin_{}.st", "tia": "eskin_{}_tags.xlsx", "csv": "eskin_{}_tags.csv"}


@click.command("export")
@profile_option()
@click.option("--format", "fmt", type=click.Choice(["codesys", "tia", "csv"]), required=True,
              help="codesys: structured types, GVL and FB_SlipGuard (Structured Text); tia: a TIA Portal PLC tag "
                   "table (.xlsx); csv: one row per tag with IEC 61131-3 types.")
@click.option("-o", "--output-dir", "out_dir", type=click.Path(file_okay=False),
              help="Write the file into this folder (created if missing); default: standard output.")
@click.option("--input-word", type=click.IntRange(0, 65535), default=0, show_default=True,
              help="codesys: %IW address of the read channel (from the device tree's I/O mapping).")
@click.option("--output-word", type=click.IntRange(0, 65535), default=0, show_default=True,
              help="codesys: %QW address of the write channel.")
@click.option("--m-byte", type=click.IntRange(0, 65534), default=0, show_default=True,
              help="tia: the M byte (even) where the block's first register lands: MB_CLIENT's DATA_PTR, or "
                   "MB_SERVER's MB_HOLD_REG start + 2 x base_address.")
def export(profile_path: str, fmt: str, out_dir: str | None, input_word: int, output_word: int, m_byte: int) -> None:
    """Write PLC import files for the profile's register image: a Codesys source, a
    TIA Portal tag table or a flat CSV tag list (see docs/plc.md)."""
    prof = open_profile(profile_path)
    settings = prof.modbus.plc
    if m_byte % 2:
        raise click.BadParameter(f"expected an even byte address (a word's), got {m_byte}", param_hint="--m-byte")
    data: bytes
    if fmt == "codesys":
        data = codesys_st(settings, prof.name, input_word, output_word).encode()
    elif fmt == "csv":
        data = flat_csv(settings).encode()
    else:
        data = tia_xlsx(settings, prof.name, m_byte)
    if out_dir is None:
        if fmt == "tia" and sys.stdout.isatty():
            raise click.UsageError("--format tia writes an .xlsx workbook: give -o DIR or redirect the output")
        sys.stdout.buffer.write(data)
        sys.stdout.flush()
        return
    folder = Path(out_dir)
    path = folder / _FILES[fmt].format(ident(prof.name))
    try:
        folder.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)
    except OSError as exc:
        raise click.FileError(str(path), exc.strerror or str(exc)) from None
    click.echo(f"wrote {path}", err=True)
