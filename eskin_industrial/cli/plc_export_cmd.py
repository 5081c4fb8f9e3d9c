"""``eskin-bus plc export``: the register map as files a PLC's engineering tool imports."""

from __future__ import annotations

import dataclasses
import sys
from dataclasses import dataclass
from pathlib import Path

import click

from .. import __version__
from ..outputs.plc.export import codesys_st, flat_csv, ident, tia_xlsx
from ..outputs.plc.plcopen import plcopen_xml
from ..profile import ModbusPlcSection
from .common import complete_profile, open_profile

#: File name (the node's or profile's name in it) of each format.
_FILES = {"codesys": "eskin_{}.st", "plcopen": "eskin_{}.xml", "tia": "eskin_{}_tags.xlsx",
          "csv": "eskin_{}_tags.csv"}


@dataclass(frozen=True)
class _Block:
    """One node's register block: what names it, where it is."""

    name: str
    settings: ModbusPlcSection
    prefix: str  #: before every tag name ("" for a lone profile)
    method: str  #: the deciding method (what METHOD_ID and the scores hold)


@click.command("export")
@click.option("-p", "--profile", "profile_path", type=click.Path(dir_okay=False), shell_complete=complete_profile,
              help="Sensor profile: a TOML file, or a built-in name (eskin-bus profile list), e.g. paper-5x5.")
@click.option("--config", "config_path", type=click.Path(dir_okay=False),
              help="A bridge configuration: one file per node, tags prefixed with the node's name, each at its "
                   "base_address (instead of -p; needs -o).")
@click.option("--format", "fmt", type=click.Choice(["plcopen", "codesys", "tia", "csv"]), required=True,
              help="plcopen: a PLCopen XML project (IEC 61131-10) that Codesys and TwinCAT import: the structured "
                   "types, the GVL at the channels' %IW/%QW words, F_EskinJoin32 and FB_SlipGuard; codesys: the same "
                   "as Structured Text to paste; tia: a TIA Portal PLC tag table (.xlsx); csv: a generic tag list, one "
                   "row per tag with IEC 61131-3 types (no tool's import format).")
@click.option("-o", "--output-dir", "out_dir", type=click.Path(file_okay=False),
              help="Write the file into this folder (created if missing); default: standard output.")
@click.option("--node-name", help="With -p: name the node (tag prefix NAME_, tag table, types, file name).")
@click.option("--base-address", type=click.IntRange(0, 65000),
              help="With -p: the block's base address, instead of the profile's [modbus.plc] base_address.")
@click.option("--input-word", type=click.IntRange(0, 65535), default=0, show_default=True,
              help="plcopen, codesys: %IW address of the read channel (from the device tree's I/O mapping).")
@click.option("--output-word", type=click.IntRange(0, 65535), default=0, show_default=True,
              help="plcopen, codesys: %QW address of the write channel.")
@click.option("--m-byte", type=click.IntRange(0, 65534), default=0, show_default=True,
              help="tia: the M byte (even) where the first block's first register lands: MB_CLIENT's DATA_PTR, or "
                   "MB_SERVER's MB_HOLD_REG start + 2 x base_address; other nodes' blocks follow at their distance.")
def export(profile_path: str | None, config_path: str | None, fmt: str, out_dir: str | None, node_name: str | None,
           base_address: int | None, input_word: int, output_word: int, m_byte: int) -> None:
    """Write PLC import files for a register image: a PLCopen XML project, a Codesys
    source, a TIA Portal tag table or a generic CSV tag list (see docs/plc.md)."""
    if (profile_path is None) == (config_path is None):
        raise click.UsageError("give a profile (-p PROFILE) or a bridge configuration (--config BRIDGE.toml)")
    if m_byte % 2:
        raise click.BadParameter(f"expected an even byte address (a word's), got {m_byte}", param_hint="--m-byte")
    if config_path is not None:
        if node_name is not None or base_address is not None:
            raise click.UsageError("--node-name and --base-address go with -p; with --config each [[node]] gives its "
                                   "own name and base_address")
        if out_dir is None:
            raise click.UsageError("--config writes one file per node: give -o DIR")
        from ..bridge.config import load_bridge_config, resolve

        blocks = [_Block(n.name, n.profile.modbus.plc, f"{ident(n.name)}_", n.profile.detector.method)
                  for n in resolve(load_bridge_config(config_path))]
    else:
        assert profile_path is not None
        prof = open_profile(profile_path)
        settings = prof.modbus.plc
        if base_address is not None:
            settings = dataclasses.replace(settings, base_address=base_address)
        blocks = [_Block(node_name or prof.name, settings, f"{ident(node_name)}_" if node_name else "",
                         prof.detector.method)]
    first = min(b.settings.base_address for b in blocks)
    for b in blocks:
        data: bytes
        if fmt == "plcopen":
            data = plcopen_xml(b.settings, b.name, input_word, output_word, b.method, __version__).encode()
        elif fmt == "codesys":
            data = codesys_st(b.settings, b.name, input_word, output_word, b.method).encode()
        elif fmt == "csv":
            data = flat_csv(b.settings, b.prefix, b.method).encode()
        else:
            data = tia_xlsx(b.settings, b.name, m_byte + 2 * (b.settings.base_address - first), b.prefix, b.method)
        if out_dir is None:
            if fmt == "tia" and sys.stdout.isatty():
                raise click.UsageError("--format tia writes an .xlsx workbook: give -o DIR or redirect the output")
            sys.stdout.buffer.write(data)
            sys.stdout.flush()
        else:
            _write(Path(out_dir) / _FILES[fmt].format(ident(b.name)), data)


def _write(path: Path, data: bytes) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)
    except OSError as exc:
        raise click.FileError(str(path), exc.strerror or str(exc)) from None
    click.echo(f"wrote {path}", err=True)
