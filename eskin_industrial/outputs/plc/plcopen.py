"""The register block as a PLCopen XML project (IEC 61131-10, the TC6 XML schema
v2.01): the file Codesys ("Import PLCopenXML") and TwinCAT import.  Pure: the
settings in, the XML text out.

It holds what the Codesys source of :mod:`.export` holds, as objects the tool creates
on import instead of text to paste:

- two structured data types, ``ST_Eskin_<name>_In`` (what the bridge publishes) and
  ``..._Out`` (COMMAND, ENABLE), members in register order, ``pack_mode`` 1;
- the global variable list ``GVL_Eskin_<name>`` that lays them over the I/O words of
  the Modbus channels (``stIn`` at ``%IW<input_word>``, ``stOut`` at
  ``%QW<output_word>``), and ``GVL_Eskin_<name>_Bits``, the STATUS bit numbers as
  constants;
- the POUs ``F_EskinJoin32`` and ``FB_SlipGuard`` (docs/plc.md), their interfaces as
  variable lists and their bodies as Structured Text.

The standard has no place for a global variable list outside a configuration, nor
for pragmas; both go where Codesys's own export puts them, in ``addData`` blocks
under Codesys's names (a tool that does not know them skips them, as the schema
says).  The POUs' interfaces are read from the same Structured Text the Codesys
source and docs/plc.md show, so the three never differ.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass

from ...profile import ModbusPlcSection
from .export import (
    JOIN32_DOC,
    Member,
    _bit,
    _name,
    block_names,
    join32_st,
    slip_guard_st,
)
from .image import BIT_DOC, BITS

TC6 = "http://www.plcopen.org/xml/tc6_0201"
XHTML = "http://www.w3.org/1999/xhtml"
#: Codesys's names of the addData blocks it writes and reads.
CODESYS_GLOBALVARS = "http://www.3s-software.com/plcopenxml/globalvars"
CODESYS_ATTRIBUTES = "http://www.3s-software.com/plcopenxml/attributes"

#: IEC 61131-3 elementary types: an element of their name in TC6 (``<WORD/>``); any
#: other type is ``<derived name="..."/>``.
ELEMENTARY = frozenset({"BOOL", "BYTE", "WORD", "DWORD", "LWORD", "SINT", "INT", "DINT", "LINT", "USINT", "UINT",
                        "UDINT", "ULINT", "REAL", "LREAL", "TIME", "DATE", "DT", "TOD", "STRING", "WSTRING"})

#: A POU's variable sections, Structured Text keyword -> TC6 element.
SECTIONS = {"VAR_INPUT": "inputVars", "VAR_OUTPUT": "outputVars", "VAR_IN_OUT": "inOutVars", "VAR": "localVars",
            "VAR_TEMP": "tempVars"}

_DECL = re.compile(r"\s*(?P<names>[A-Za-z_]\w*(?:\s*,\s*[A-Za-z_]\w*)*)\s*:\s*(?P<type>[A-Za-z_]\w*)\s*;"
                   r"\s*(?:\(\*\s*(?P<doc>.*?)\s*\*\))?\s*")
_HEAD = re.compile(r"(?P<kind>FUNCTION_BLOCK|FUNCTION)\s+(?P<name>\w+)(?:\s*:\s*(?P<ret>\w+))?\s*")


@dataclass(frozen=True)
class Var:
    """One declared variable of a POU."""

    name: str
    iec_type: str
    doc: str = ""


@dataclass(frozen=True)
class Pou:
    """A POU from its Structured Text: the kind, the interface, the body."""

    kind: str  #: "function" or "functionBlock"
    name: str
    return_type: str | None
    sections: tuple[tuple[str, tuple[Var, ...]], ...]  #: (TC6 element, variables), in order
    body: str


def parse_pou(text: str) -> Pou:
    """A ``FUNCTION``/``FUNCTION_BLOCK`` of this package's Structured Text: a header
    line, VAR sections of ``names : TYPE;  (* doc *)`` lines, the body, the END line.
    ValueError for anything else (the texts are ours: a change that breaks this
    breaks the export, never the PLC)."""
    lines = text.strip("\n").split("\n")
    head = _HEAD.fullmatch(lines[0])
    if head is None or not re.fullmatch(r"END_FUNCTION(_BLOCK)?", lines[-1].strip()):
        raise ValueError(f"not a function or function block: {lines[0]!r}")
    sections: list[tuple[str, tuple[Var, ...]]] = []
    i = 1
    while i < len(lines) and lines[i].strip() in SECTIONS:
        element, found = SECTIONS[lines[i].strip()], []
        i += 1
        while lines[i].strip() != "END_VAR":
            m = _DECL.fullmatch(lines[i])
            if m is None:
                raise ValueError(f"{head['name']}: not a declaration: {lines[i]!r}")
            found += [Var(n.strip(), m["type"], m["doc"] or "") for n in m["names"].split(",")]
            i += 1
        sections.append((element, tuple(found)))
        i += 1
    body = "\n".join(lines[i:-1]).strip("\n") + "\n"
    kind = "functionBlock" if head["kind"] == "FUNCTION_BLOCK" else "function"
    return Pou(kind, head["name"], head["ret"], tuple(sections), body)


# -- building the tree ----------------------------------------------------------------

def _q(tag: str) -> str:
    return f"{{{TC6}}}{tag}"


def _sub(parent: ET.Element, tag: str, **attrs: str) -> ET.Element:
    return ET.SubElement(parent, _q(tag), attrs)


def _xhtml(parent: ET.Element, tag: str, text: str) -> None:
    """A formatted text (documentation, a body): one XHTML element holding the text."""
    holder = _sub(parent, tag)
    ET.SubElement(holder, f"{{{XHTML}}}xhtml").text = text


def _type(parent: ET.Element, iec_type: str) -> None:
    t = _sub(parent, "type")
    if iec_type in ELEMENTARY:
        _sub(t, iec_type)
    else:
        _sub(t, "derived", name=iec_type)


def _variable(parent: ET.Element, name: str, iec_type: str, doc: str = "", address: str | None = None,
              initial: str | None = None) -> None:
    v = _sub(parent, "variable", name=name, **({"address": address} if address else {}))
    _type(v, iec_type)
    if initial is not None:
        _sub(_sub(v, "initialValue"), "simpleValue", value=initial)
    if doc:
        _xhtml(v, "documentation", doc)


def _attributes(parent: ET.Element, **attributes: str) -> None:
    """Codesys pragmas (``{attribute 'NAME' := 'VALUE'}``) as its export writes them."""
    add = _sub(parent, "addData")
    data = _sub(add, "data", name=CODESYS_ATTRIBUTES, handleUnknown="implementation")
    holder = _sub(data, "Attributes")
    for key, value in attributes.items():
        _sub(holder, "Attribute", Name=key, Value=value)


def _struct(types: ET.Element, name: str, doc: str, mems: Sequence[Member]) -> None:
    dt = _sub(types, "dataType", name=name)
    struct = _sub(_sub(dt, "baseType"), "struct")
    for m in mems:
        _variable(struct, m.name, m.iec_type, m.comment)
    _attributes(dt, pack_mode="1")
    _xhtml(dt, "documentation", doc)


def _pou(pous: ET.Element, pou: Pou, doc: str) -> None:
    el = _sub(pous, "pou", name=pou.name, pouType=pou.kind)
    interface = _sub(el, "interface")
    if pou.return_type is not None:
        _type(interface, pou.return_type)
        interface[-1].tag = _q("returnType")
    for element, variables in pou.sections:
        vl = _sub(interface, element)
        for v in variables:
            _variable(vl, v.name, v.iec_type, v.doc)
    _xhtml(_sub(el, "body"), "ST", pou.body)
    _xhtml(el, "documentation", doc)


def plcopen_xml(settings: ModbusPlcSection, name: str, input_word: int = 0, output_word: int = 0,
                method: str | None = None, version: str = "") -> str:
    """The PLCopen XML project of one node's block; ``name`` names the types and the
    GVLs as in :func:`~.export.codesys_st`, ``input_word``/``output_word`` the
    ``%IW``/``%QW`` words of the read and the write channel, ``version`` the
    package's (in the file header)."""
    node, gvl, base, wo, read, write, in_type, out_type, first_in, n_in, first_out, n_out = block_names(
        settings, name, method)

    ET.register_namespace("", TC6)
    ET.register_namespace("xhtml", XHTML)
    project = ET.Element(_q("project"))
    # a fixed date: the same block gives the same bytes
    _sub(project, "fileHeader", companyName="eskin-industrial", productName="eskin-bus",
         productVersion=version or "0", creationDateTime="2020-01-01T00:00:00",
         contentDescription=f"eskin-bus register block of {name}: base address {base}, word order {wo}")
    header = _sub(project, "contentHeader", name=f"eskin_{node}", modificationDateTime="2020-01-01T00:00:00")
    coords = _sub(header, "coordinateInfo")
    for lang in ("fbd", "ld", "sfc"):
        _sub(_sub(coords, lang), "scaling", x="1", y="1")

    types = _sub(project, "types")
    data_types = _sub(types, "dataTypes")
    _struct(data_types, in_type, f"what the bridge publishes: holding registers {base + first_in}.."
            f"{base + first_in + n_in - 1} (Read Holding Registers, offset {base + first_in}, length {n_in}), "
            f"word order {wo}", read)
    if write:
        _struct(data_types, out_type, f"what the PLC writes: holding registers {base + first_out}.."
                f"{base + first_out + n_out - 1} (Write Multiple Registers, offset {base + first_out}, "
                f"length {n_out})", write)
    pous = _sub(types, "pous")
    _pou(pous, parse_pou(join32_st()), JOIN32_DOC)
    _pou(pous, parse_pou(slip_guard_st()), "Act on SLIP only when the data is trustworthy (docs/plc.md).")

    _sub(_sub(project, "instances"), "configurations")

    # The global variable lists, where Codesys's export puts a GVL
    add = _sub(project, "addData")
    data = _sub(add, "data", name=CODESYS_GLOBALVARS, handleUnknown="implementation")
    gl = _sub(data, "globalVars", name=gvl)
    _variable(gl, "stIn", in_type, "the read channel's first word", address=f"%IW{input_word}")
    if write:
        _variable(gl, "stOut", out_type, "the write channel's first word", address=f"%QW{output_word}")
    _attributes(gl, qualified_only="")
    _xhtml(gl, "documentation", f"the register block of {name}: set the two addresses to those of the channels in "
           "the I/O mapping")
    data = _sub(add, "data", name=CODESYS_GLOBALVARS, handleUnknown="implementation")
    bits = _sub(data, "globalVars", name=f"{gvl}_Bits", constant="true")
    for s in BITS:
        _variable(bits, f"EB_{_name(s)}", "UINT", BIT_DOC[s], initial=str(_bit(s)))
    _attributes(bits, qualified_only="")
    _xhtml(bits, "documentation", "STATUS bit numbers, the same as the discrete inputs 0..")

    ET.indent(project, "  ")
    return '<?xml version="1.0" encoding="utf-8"?>\n' + ET.tostring(project, encoding="unicode") + "\n"
