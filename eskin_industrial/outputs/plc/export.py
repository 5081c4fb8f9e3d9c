"""PLC import files for the register image: a flat tag list, a Codesys source and a
TIA Portal PLC tag table.  Pure: the settings in, text (or a workbook's bytes) out.

Everything is derived from the tables of :mod:`~eskin_industrial.outputs.plc.image`
(``REGISTERS``, ``COILS``, ``BITS`` and the numbering of :func:`map_rows`), so that a
register added there appears in every file (read through the module, at each call).

Types are IEC 61131-3's: a 16-bit register is ``WORD`` (bit fields), ``UINT`` or
``INT``; a 32-bit pair ``UDINT`` with the profile's word order stated; a coil or
discrete input ``BOOL``.  A PLC reads a 32-bit pair as one ``UDINT`` only where the
word order on the wire is its own: high word first (``big``) on a Siemens S7, low
word first (``little``) on a Codesys runtime of a little-endian CPU (x86, ARM).  In
the other order the files declare the two words apart, ``NAME_HI`` and ``NAME_LO``,
and the Codesys file has a function that joins them.
"""

from __future__ import annotations

import csv
import io
import re
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal, NamedTuple
from xml.sax.saxutils import escape

from ...frames import FrameFlag
from ...profile import ModbusPlcSection
from . import image
from .image import BIT_DOC, BITS, COILS, Register, Status, map_rows

Table = Literal["holding register", "coil", "discrete input"]
Order = Literal["big", "little"]

#: IEC 61131-3 type of each register kind (a ``u16`` whose unit is ``bits`` is a WORD).
IEC_TYPE = {"bits": "WORD", "u16": "UINT", "i16": "INT", "u32": "UDINT"}
#: TIA Portal's spelling of the IEC types.
TIA_TYPE = {"WORD": "Word", "UINT": "UInt", "INT": "Int", "UDINT": "UDInt", "BOOL": "Bool"}


@dataclass(frozen=True)
class Tag:
    """One Modbus object of the image, as a PLC tag."""

    name: str
    table: Table
    offset: int  #: from the base address
    address: int  #: 0-based protocol address (of the first word of a pair)
    reference: str  #: 1-based Modicon reference (of the first word of a pair)
    iec_type: str
    words: int  #: registers taken (0 for a bit)
    word_order: Order | None  #: of a 32-bit pair
    scale: float  #: physical value = raw x scale, in ``unit``
    unit: str
    label: str  #: the unit as the register map shows it ("0.01 mm", "x 100")
    access: Literal["R", "RW"]
    description: str


def _scale_unit(unit: str, r_scale: float) -> tuple[float, str]:
    """A register's unit string as (scale, unit): ``"0.01 mm"`` -> (0.01, ``"mm"``);
    ``"x r_scale"`` -> (1 / r_scale, ``"1"``); anything else as it is, at scale 1."""
    if unit == "x r_scale":
        return 1.0 / r_scale, "1"
    m = re.fullmatch(r"([0-9.]+(?:e-?[0-9]+)?) (\S.*)", unit)
    if m:
        return float(m.group(1)), m.group(2)
    return 1.0, unit


def _iec(r: Register) -> str:
    return "WORD" if r.unit == "bits" else IEC_TYPE[r.kind]


def tags(settings: ModbusPlcSection, method: str | None = None) -> list[Tag]:
    """Every register, coil and discrete input, in the order of :func:`map_rows`
    (``method``: the deciding method, which names what METHOD_ID and the scores hold)."""
    rows = map_rows(settings, method)
    objects: list[Register | object] = [*image.REGISTERS, *COILS, *BITS]
    out: list[Tag] = []
    for row, obj in zip(rows, objects, strict=True):
        address = int(row["address"].split("-")[0])
        ref = row["ref"].split("-")[0]
        if isinstance(obj, Register):
            scale, unit = _scale_unit(obj.unit, settings.r_scale)
            out.append(Tag(obj.name, "holding register", obj.offset, address, ref, _iec(obj), obj.words,
                           settings.word_order if obj.words == 2 else None, scale, unit, row["unit"], obj.access,
                           row["description"]))
        else:
            table: Table = "coil" if row["table"] == "coil" else "discrete input"
            out.append(Tag(row["name"], table, address - settings.base_address, address, ref, "BOOL", 0, None,
                           1.0, "-", "-", "RW" if row["access"] == "RW" else "R", row["description"]))
    return out


# -- the flat tag list ---------------------------------------------------------------

CSV_COLUMNS = ("name", "table", "address", "reference", "data_type", "word_order", "scale", "unit", "access",
               "description")


def flat_csv(settings: ModbusPlcSection, prefix: str = "", method: str | None = None) -> str:
    """One row per tag: the Modbus numbering, the IEC type, word order, scale and unit
    (``prefix`` before each name: several nodes in one PLC)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(CSV_COLUMNS)
    for t in tags(settings, method):
        w.writerow([prefix + t.name, t.table, t.address, t.reference, t.iec_type, t.word_order or "", f"{t.scale:g}", t.unit,
                    t.access, t.description])
    return buf.getvalue()


# -- the PLC's view: members of a register block ---------------------------------------

@dataclass(frozen=True)
class Member:
    """One declared variable over the register block: a whole register, a 32-bit pair
    in the PLC's own word order, or one word of a pair in the other order."""

    name: str
    offset: int  #: word offset from the base address
    iec_type: str
    comment: str
    access: Literal["R", "RW"] = "R"


def members(registers: Sequence[Register], settings: ModbusPlcSection, native: Order,
            method: str | None = None) -> list[Member]:
    """The registers as declared by a PLC whose 32-bit word order is ``native``;
    gaps in the table become ``RESERVED_<offset>`` words, so that an overlay stays
    aligned with the wire."""
    by_tag = {t.name: t for t in tags(settings, method) if t.table == "holding register"}
    out: list[Member] = []
    at = registers[0].offset if registers else 0
    for r in sorted(registers, key=lambda r: r.offset):
        for gap in range(at, r.offset):
            out.append(Member(f"RESERVED_{gap}", gap, "WORD",
                              "not part of this block (a gap, or a register of the other direction)"))
        t = by_tag[r.name]
        unit = f" [{t.label}]" if t.label not in ("-", "") else ""
        where = f"{t.reference}" + (f"-{_next_ref(t.reference)}" if r.words == 2 else "")
        text = f"{where}{unit}: {t.description}"
        if r.words == 2 and settings.word_order != native:
            first, second = ("HI", "LO") if settings.word_order == "big" else ("LO", "HI")
            out.append(Member(f"{r.name}_{first}", r.offset, "WORD",
                              f"{text} ({settings.word_order} word order: the {first.lower()} word)", r.access))
            out.append(Member(f"{r.name}_{second}", r.offset + 1, "WORD",
                              f"{r.name}: the {second.lower()} word", r.access))
        else:
            out.append(Member(r.name, r.offset, t.iec_type, text, r.access))
        at = r.offset + r.words
    return out


def _next_ref(ref: str) -> str:
    n = int(ref) + 1
    return f"{n:0{len(ref)}d}"


def _span(registers: Sequence[Register]) -> tuple[int, int]:
    """(first offset, registers spanned), gaps included."""
    if not registers:
        return 0, 0
    first = min(r.offset for r in registers)
    return first, max(r.offset + r.words for r in registers) - first


def _published(registers: Sequence[Register]) -> list[Register]:
    return [r for r in registers if r.access == "R"]


def _written(registers: Sequence[Register]) -> list[Register]:
    return [r for r in registers if r.access == "RW"]


# -- the Structured Text function block (docs/plc.md shows this text) --------------------

def _bit(s: Status) -> int:
    return int(s).bit_length() - 1


def _name(s: Status) -> str:
    return s.name or f"BIT{_bit(s)}"  # a single-bit flag always has a name; the stubs allow None


def slip_guard_st() -> str:
    """``FB_SlipGuard``: act on SLIP only when the data is trustworthy.  The register
    offsets and bit numbers come from the tables."""
    reg = image.REG
    st, hb, age, fl = reg["STATUS"].offset, reg["HEARTBEAT"].offset, reg["FRAME_AGE"].offset, reg["FLAGS"].offset
    b = {s: _bit(s) for s in Status}
    unseen = f"bTurnUnseen  := wFlags.{int(FrameFlag.TURN_UNSEEN).bit_length() - 1};"
    # the sensor-fault bits of FLAGS (DEAD_TAXELS, FROZEN, RATE, STREAM): DATA_VALID is already
    # clear with any of them; the block reads them as well, so that an older bridge
    # or a hand-written image cannot hide one
    faults = " OR ".join(f"wFlags.{int(f).bit_length() - 1}"
                         for f in (FrameFlag.DEAD_TAXELS, FrameFlag.FROZEN, FrameFlag.RATE, FrameFlag.STREAM))
    sensor = f"bSensorBad   := {faults};"

    def bit(var: str, s: Status, note: str) -> str:
        lhs = f"{var:<12} := wStatus.{b[s]};"
        return f"{lhs:<29}(* {note} *)"

    return f"""\
FUNCTION_BLOCK FB_SlipGuard
VAR_INPUT
    wStatus     : WORD;   (* %MW{st:<2} STATUS    *)
    wHeartbeat  : WORD;   (* %MW{hb:<2} HEARTBEAT *)
    wFrameAgeMs : WORD;   (* %MW{age:<2} FRAME_AGE *)
    wFlags      : WORD;   (* %MW{fl:<2} FLAGS     *)
    rGripForceN : REAL;   (* current set-point *)
END_VAR
VAR_OUTPUT
    rGripSetN   : REAL;   (* new set-point *)
    bAck        : BOOL;   (* pulse: write COMMAND := 1 (or coil ACK_SLIP := TRUE) *)
    bNoVerdict  : BOOL;   (* the skin cannot tell: do not rely on it *)
    bSensorBad  : BOOL;   (* FLAGS DEAD_TAXELS, FROZEN, RATE or STREAM: the sensor needs service *)
    bTurnUnseen : BOOL;   (* a turn of the part would read stable: no twisting motion on "no slip" *)
END_VAR
VAR
    wLastHeartbeat : WORD;
    tonBridgeDead  : TON;
    rtLatched      : R_TRIG;
    bValid, bStale, bFault, bSlip, bSlipLatched, bAlive, bOffline : BOOL;
END_VAR

{bit("bValid", Status.DATA_VALID, "DATA_VALID  ")}
{bit("bStale", Status.SENSOR_STALE, "SENSOR_STALE")}
{bit("bFault", Status.BUS_FAULT, "BUS_FAULT   ")}
{bit("bSlip", Status.SLIP, "SLIP (live) ")}
{bit("bSlipLatched", Status.SLIP_LATCHED, "SLIP_LATCHED")}
{bit("bOffline", Status.BRIDGE_OFFLINE, "BRIDGE_OFFLINE: the bridge stopped on purpose")}
{unseen:<29}(* FLAGS TURN_UNSEEN: slides are seen, turns not *)
{sensor}  (* FLAGS DEAD_TAXELS, FROZEN, RATE, STREAM *)

(* Bridge watchdog: the heartbeat must move within 500 ms. *)
tonBridgeDead(IN := (wHeartbeat = wLastHeartbeat), PT := T#500MS);
wLastHeartbeat := wHeartbeat;
bAlive := NOT tonBridgeDead.Q;

(* "No slip" is only "no slip" with valid, fresh data from a living bridge. *)
bNoVerdict := NOT bAlive OR NOT bValid OR bStale OR bFault OR bOffline OR bSensorBad;

rGripSetN := rGripForceN;
bAck := FALSE;
rtLatched(CLK := bSlipLatched AND bAlive);
IF rtLatched.Q THEN
    (* A slip was seen (even one shorter than the PLC cycle): grip harder. *)
    rGripSetN := MIN(rGripForceN + 2.0, 20.0);
ELSIF bSlipLatched AND bAlive AND NOT bSlip THEN
    (* The latch stays set while the slip lasts: acknowledge once it is over. *)
    bAck := TRUE;
ELSIF bNoVerdict THEN
    (* Unknown: keep the force, stop the motion that could lose the part, raise an alarm. *)
    rGripSetN := rGripForceN;
END_IF;
END_FUNCTION_BLOCK
"""


JOIN32_DOC = "A 32-bit value from its two words (high word, low word)."


def join32_st() -> str:
    """``F_EskinJoin32``: a UDINT from the two words of a pair in big word order."""
    return """\
FUNCTION F_EskinJoin32 : UDINT
VAR_INPUT
    wHigh : WORD;
    wLow  : WORD;
END_VAR
F_EskinJoin32 := SHL(WORD_TO_UDINT(wHigh), 16) OR WORD_TO_UDINT(wLow);
END_FUNCTION
"""


# -- Codesys -----------------------------------------------------------------------

def ident(name: str) -> str:
    """An IEC identifier from a profile name: letters, digits and single underscores."""
    s = re.sub(r"[^A-Za-z0-9]+", "_", name).strip("_")
    return s if s and not s[0].isdigit() else f"N_{s}"


def _struct(name: str, doc: str, mems: Sequence[Member]) -> str:
    width = max((len(m.name) for m in mems), default=0)
    lines = [f"(* {doc} *)", "{attribute 'pack_mode' := '1'}", f"TYPE {name} :", "STRUCT"]
    for m in mems:
        lines.append(f"    {m.name:<{width}} : {m.iec_type + ';':<7} (* {_comment(m.comment)} *)")
    lines += ["END_STRUCT", "END_TYPE", ""]
    return "\n".join(lines)


def _comment(text: str) -> str:
    return text.replace("(*", "( *").replace("*)", "* )")


class BlockNames(NamedTuple):
    """What a Codesys source and a PLCopen project both name of one node's block."""

    node: str  #: the name as an identifier
    gvl: str  #: the global variable list
    base: int
    word_order: Literal["big", "little"]
    read: list[Member]  #: the published registers as the In type's members
    write: list[Member]  #: the written ones as the Out type's members
    in_type: str
    out_type: str
    first_in: int  #: the first published register and how many
    n_in: int
    first_out: int  #: the first written register and how many
    n_out: int


def block_names(settings: ModbusPlcSection, name: str, method: str | None) -> BlockNames:
    node = ident(name)
    published, written = _published(image.REGISTERS), _written(image.REGISTERS)
    return BlockNames(node, f"GVL_Eskin_{node}", settings.base_address, settings.word_order,
                      members(published, settings, native="little", method=method),
                      members(written, settings, native="little", method=method),
                      f"ST_Eskin_{node}_In", f"ST_Eskin_{node}_Out", *_span(published), *_span(written))


def codesys_st(settings: ModbusPlcSection, name: str, input_word: int = 0, output_word: int = 0,
               method: str | None = None) -> str:
    """A Codesys source: the structured types of the block (what the PLC reads, what
    it writes), a GVL that lays them over the I/O of a Modbus master's channels, and
    ``FB_SlipGuard``; ``name`` (a node's or the profile's) names the types and the GVL.  32-bit values are one UDINT in little word order (the
    runtime's own on x86 and ARM); in big word order two WORDs and ``F_EskinJoin32``."""
    node, gvl, base, wo, read, write, in_type, out_type, first_in, n_in, first_out, n_out = block_names(
        settings, name, method)
    parts = [f"""\
(* eskin-bus PLC import for {name}: the register image of one node.
   Generated by `eskin-bus plc export --format codesys`; the register table is
   docs/plc.md (`eskin-bus plc map`).  Modbus: base address {base}, word order {wo}.

   Bring it into a Codesys project part by part: a DUT for each TYPE, a GVL named
   {gvl} for the two VAR_GLOBAL blocks, a POU (Structured Text) for F_EskinJoin32
   and one for FB_SlipGuard (declaration above the first blank line, the rest its
   implementation; both are the same in the file of every node: one copy serves all).
   Call it with the block's words:
     fbGuard(wStatus := {gvl}.stIn.STATUS, wHeartbeat := {gvl}.stIn.HEARTBEAT,
             wFrameAgeMs := {gvl}.stIn.FRAME_AGE, wFlags := {gvl}.stIn.FLAGS,
             rGripForceN := rForce);

   Bridge in server mode (the PLC is the Modbus master): under the Modbus TCP (or
   serial) master, the bridge's slave device gets two channels:
     - Read Holding Registers (function 3), offset {base + first_in}, length {n_in}
     - Write Multiple Registers (function 16), offset {base + first_out}, length {n_out}
   The device tree assigns each channel its %IW / %QW address in the I/O mapping:
   a text file cannot.  Set the two AT addresses of the GVL to those (here %IW{input_word}
   and %QW{output_word}).  A cyclic write channel writes COMMAND at every cycle: set a bit
   for one write and clear it (or trigger the channel on a rising edge).  Bridge in
   client mode (the PLC is the Modbus slave): the slave device's holding registers
   take the whole block, from register {base}; map them the same way.

   Word order {wo}: """ + (
        "a 32-bit value is one UDINT (low word first, as a little-endian runtime stores it)."
        if wo == "little" else
        "a 32-bit value is two WORDs, NAME_HI then NAME_LO; F_EskinJoin32(NAME_HI, NAME_LO)\n"
        "   gives the UDINT (a UDINT overlay would read the words swapped on x86 and ARM).") + """ *)
"""]
    parts.append(_struct(in_type, f"what the bridge publishes: holding registers {base + first_in}.."
                         f"{base + first_in + n_in - 1}, read", read))
    if write:
        parts.append(_struct(out_type, f"what the PLC writes: holding registers {base + first_out}.."
                             f"{base + first_out + n_out - 1}", write))
    width = max(len(_name(s)) for s in BITS)
    consts = "\n".join(f"    EB_{_name(s):<{width}} : UINT := {_bit(s)};   (* {_comment(BIT_DOC[s])} *)"
                       for s in BITS)
    glob = ["{attribute 'qualified_only'}", "VAR_GLOBAL",
            f"    stIn  AT %IW{input_word} : {in_type};   (* the read channel's first word *)"]
    if write:
        glob.append(f"    stOut AT %QW{output_word} : {out_type};   (* the write channel's first word *)")
    glob += ["END_VAR", "", "(* STATUS bit numbers, the same as the discrete inputs 0.. *)",
             "VAR_GLOBAL CONSTANT", consts, "END_VAR", ""]
    parts.append("\n".join(glob))
    parts.append(f"(* {JOIN32_DOC} *)\n{join32_st()}")
    parts.append(slip_guard_st())
    return "\n".join(parts)


# -- TIA Portal ----------------------------------------------------------------------

TIA_COLUMNS = ("Name", "Path", "Data Type", "Logical Address", "Comment", "Hmi Visible", "Hmi Accessible",
               "Hmi Writeable", "Typeobject ID", "Version ID")


def tia_rows(settings: ModbusPlcSection, name: str, m_byte: int = 0, prefix: str = "",
             method: str | None = None) -> list[list[str]]:
    """The PLC tags of the block in an S7's memory: the holding registers from
    ``%MB m_byte`` (the MB_CLIENT or MB_SERVER buffer, two bytes per register, high
    byte first), and the STATUS bits as Bool tags over the STATUS word; the tag table
    is ``eskin_<name>``, ``prefix`` goes before every tag name (names are unique in
    the whole PLC)."""
    if m_byte % 2:
        raise ValueError(f"m_byte: expected an even byte address (a word's), got {m_byte}")
    path = f"eskin_{ident(name)}"
    rows: list[list[str]] = []
    regs = members(image.REGISTERS, settings, native="big", method=method)
    first = regs[0].offset
    for m in regs:
        byte = m_byte + 2 * (m.offset - first)
        addr = f"%MD{byte}" if m.iec_type == "UDINT" else f"%MW{byte}"
        rows.append([prefix + m.name, path, TIA_TYPE[m.iec_type], addr, m.comment, "True", "True",
                     "True" if m.access == "RW" else "False", "", ""])
    status = m_byte + 2 * (image.REG["STATUS"].offset - first)
    for s in BITS:
        i = _bit(s)
        # big-endian word: bits 8..15 in the first byte, bits 0..7 in the second
        byte = status + (0 if i >= 8 else 1)
        rows.append([prefix + _name(s), path, "Bool", f"%M{byte}.{i % 8}", f"STATUS bit {i}: {BIT_DOC[s]}",
                     "True", "True", "False", "", ""])
    return rows


def tia_xlsx(settings: ModbusPlcSection, name: str, m_byte: int = 0, prefix: str = "",
             method: str | None = None) -> bytes:
    """The tag table as the workbook TIA Portal's "Import" of PLC tags reads: one
    sheet "PLC Tags" with the columns of :data:`TIA_COLUMNS`."""
    return xlsx("PLC Tags", [list(TIA_COLUMNS), *tia_rows(settings, name, m_byte, prefix, method)])


# -- a minimal XLSX writer (Office Open XML, inline strings) ---------------------------

def _col(i: int) -> str:
    s = ""
    i += 1
    while i:
        i, r = divmod(i - 1, 26)
        s = chr(65 + r) + s
    return s


def xlsx(sheet: str, rows: Sequence[Sequence[str]]) -> bytes:
    """One worksheet of text cells as an .xlsx workbook (no dependency: the format's
    required parts only, every cell an inline string)."""
    cells = []
    for r, row in enumerate(rows, 1):
        cs = "".join(f'<c r="{_col(c)}{r}" t="inlineStr"><is><t xml:space="preserve">{escape(str(v))}</t></is></c>'
                     for c, v in enumerate(row) if str(v) != "")  # an empty cell is left out
        cells.append(f'<row r="{r}">{cs}</row>')
    ns = "http://schemas.openxmlformats.org/spreadsheetml/2006/main"
    rel = "http://schemas.openxmlformats.org/officeDocument/2006/relationships"
    pkg = "http://schemas.openxmlformats.org/package/2006"
    parts = {
        "[Content_Types].xml":
            f'<?xml version="1.0" encoding="UTF-8" standalone="yes"?>\n<Types xmlns="{pkg}/content-types">'
            '<Default Extension="rels" ContentType="application/vnd.openxmlformats-package.relationships+xml"/>'
            '<Default Extension="xml" ContentType="application/xml"/>'
            '<Override PartName="/xl/workbook.xml" '
            'ContentType="application/vnd.openxmlformats-officedocument.spreadsheetml.sheet.main+xml"/>'
            '<Override PartName="/xl/worksheets/sheet1.xml" '
            'ContentType="application/vnd.openxmlformats-officedocument.spreadsheetml.worksheet+xml"/>'
            '</Types>',
        "_rels/.rels":
            f'<?xml version="1.0" encoding="UTF-8" standalone="yes"?>\n<Relationships xmlns="{pkg}/relationships">'
            f'<Relationship Id="rId1" Type="{rel}/officeDocument" Target="xl/workbook.xml"/></Relationships>',
        "xl/workbook.xml":
            f'<?xml version="1.0" encoding="UTF-8" standalone="yes"?>\n<workbook xmlns="{ns}" xmlns:r="{rel}">'
            f'<sheets><sheet name="{escape(sheet)}" sheetId="1" r:id="rId1"/></sheets></workbook>',
        "xl/_rels/workbook.xml.rels":
            f'<?xml version="1.0" encoding="UTF-8" standalone="yes"?>\n<Relationships xmlns="{pkg}/relationships">'
            f'<Relationship Id="rId1" Type="{rel}/worksheet" Target="worksheets/sheet1.xml"/></Relationships>',
        "xl/worksheets/sheet1.xml":
            f'<?xml version="1.0" encoding="UTF-8" standalone="yes"?>\n<worksheet xmlns="{ns}">'
            f'<sheetData>{"".join(cells)}</sheetData></worksheet>',
    }
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        for name, text in parts.items():
            # a fixed date: the same table gives the same bytes
            z.writestr(zipfile.ZipInfo(name, date_time=(2020, 1, 1, 0, 0, 0)), text.encode("utf-8"),
                       zipfile.ZIP_DEFLATED)
    return buf.getvalue()
