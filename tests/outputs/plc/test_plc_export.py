"""PLC import files: each one read back by a reader we did not write (csv, openpyxl,
blark's IEC 61131-3 parser), laid over a rendered register image, gives the values the
bridge published."""
from __future__ import annotations

import csv
import dataclasses
import io
import re
import subprocess
import sys

import openpyxl
import pytest
from blark import parse_source_code
from click.testing import CliRunner

from eskin_industrial import load_profile
from eskin_industrial.cli import main
from eskin_industrial.outputs.plc.export import TIA_COLUMNS, codesys_st, flat_csv, slip_guard_st, tia_xlsx
from eskin_industrial.outputs.plc.image import (
    BITS,
    COILS,
    IMAGE_COUNT,
    REGISTERS,
    STATUS_COUNT,
    Status,
    encode_registers,
    encode_tail,
)
from tests.helpers.paths import PROFILES, ROOT

PROFILE = load_profile(PROFILES / "paper-5x5.toml")
METHOD = PROFILE.detector.method
#: A value of every published register, each one different and using all its bits.
VALUES = {"STATUS": int(Status.CONTACT | Status.SLIP | Status.SLIP_LATCHED | Status.DATA_VALID | Status.BRIDGE_ALIVE
                        | Status.BRIDGE_OFFLINE), "STATE": 3, "R_COE": 1234, "R_DW": 65535, "F_SUM": 0x12345678,
          "XC": -1234, "YC": 321, "HEARTBEAT": 0xBEEF, "FRAME_AGE": 17, "SLIP_EVENTS": 0x00010002,
          "STATE_CHANGES": 0xFFFF0001, "LOST_SCANS": 70000, "BUS_ERRORS": 0x80000000, "FLAGS": 0x8001,
          "METHOD_ID": 7, "SCORE_A": 0x1234, "SCORE_B": 0xFEDC}
WRITTEN = {"COMMAND": 2, "ENABLE": 1}


def settings(word_order="big", base_address=0, r_scale=100.0):
    return dataclasses.replace(PROFILE.modbus.plc, word_order=word_order, base_address=base_address, r_scale=r_scale)


def holding(word_order, base_address):
    """The PLC-side holding registers, keyed by protocol address: the bridge's words."""
    words = encode_registers(VALUES, word_order) + [WRITTEN["COMMAND"], WRITTEN["ENABLE"]] + encode_tail(VALUES)
    return {base_address + i: w for i, w in enumerate(words)}


def signed(v, bits):
    return v - (1 << bits) if v >= 1 << (bits - 1) else v


# -- the flat CSV -----------------------------------------------------------------------

@pytest.mark.parametrize("word_order", ["big", "little"])
def test_flat_csv_read_by_its_columns_gives_the_published_values(word_order):
    base = 100
    rows = list(csv.DictReader(io.StringIO(flat_csv(settings(word_order, base)))))
    assert list(rows[0]) == ["name", "table", "address", "reference", "data_type", "word_order", "scale", "unit",
                             "access", "description"]
    assert len(rows) == len(REGISTERS) + len(COILS) + len(BITS)
    regs = holding(word_order, base)
    prefix = {"holding register": "4", "coil": "0", "discrete input": "1"}
    seen = set()
    for r in rows:
        assert (r["name"], r["table"]) not in seen
        seen.add((r["name"], r["table"]))
        address = int(r["address"])
        # the reference is the table's digit and address + 1 (five digits up to 9999)
        assert r["reference"] == prefix[r["table"]] + f"{address + 1:04d}"
        assert r["data_type"] in {"WORD", "UINT", "INT", "UDINT", "DINT", "REAL", "BOOL"}
        assert float(r["scale"]) > 0
        if r["table"] != "holding register":
            assert r["data_type"] == "BOOL" and r["word_order"] == ""
            continue
        t = r["data_type"]
        if t == "UDINT":
            assert r["word_order"] == word_order
            hi, lo = (regs[address], regs[address + 1]) if word_order == "big" else (regs[address + 1], regs[address])
            value = hi << 16 | lo
        else:
            assert r["word_order"] == ""
            value = signed(regs[address], 16) if t == "INT" else regs[address]
        assert value == {**VALUES, **WRITTEN}[r["name"]], r["name"]
    by_name = {r["name"]: r for r in rows if r["table"] == "holding register"}
    assert (by_name["XC"]["scale"], by_name["XC"]["unit"]) == ("0.01", "mm")
    assert (by_name["R_COE"]["scale"], by_name["R_COE"]["unit"]) == ("0.01", "1")  # r_scale 100
    assert (by_name["F_SUM"]["scale"], by_name["F_SUM"]["unit"]) == ("1", "mN")
    # the discrete inputs are the STATUS bits, in order
    bits = [r for r in rows if r["table"] == "discrete input"]
    assert [r["name"] for r in bits] == [b.name for b in BITS]
    assert [int(r["address"]) - base for r in bits] == [int(b).bit_length() - 1 for b in BITS]


def test_flat_csv_scale_follows_r_scale():
    rows = {r["name"]: r for r in csv.DictReader(io.StringIO(flat_csv(settings(r_scale=1000.0))))}
    assert float(rows["R_COE"]["scale"]) == pytest.approx(0.001)


# -- TIA Portal ---------------------------------------------------------------------

def s7_memory(word_order, m_byte):
    """An S7's M area after MB_CLIENT / MB_SERVER copied the block in: each register
    two bytes, high byte first."""
    mem = bytearray(m_byte + 2 * (STATUS_COUNT + 2) + 16)
    for i, (_, w) in enumerate(sorted(holding(word_order, 0).items())):
        mem[m_byte + 2 * i: m_byte + 2 * i + 2] = w.to_bytes(2, "big")
    return mem


def read_s7(mem, address, tia_type):
    m = re.fullmatch(r"%M([WD]?)(\d+)(?:\.([0-7]))?", address)
    assert m, address
    size, at, bit = m.group(1), int(m.group(2)), m.group(3)
    if tia_type == "Bool":
        assert size == "" and bit is not None
        return bool(mem[at] >> int(bit) & 1)
    assert bit is None
    n = {"W": 2, "D": 4}[size]
    assert at % 2 == 0  # S7 words and double words start at even bytes in these tables
    v = int.from_bytes(mem[at: at + n], "big")
    assert tia_type in {"Word", "UInt", "Int", "UDInt"} and (n == 4) == (tia_type == "UDInt")
    return signed(v, 16) if tia_type == "Int" else v


@pytest.mark.parametrize("word_order", ["big", "little"])
def test_tia_tag_table_is_a_workbook_whose_tags_read_the_published_values(word_order, tmp_path):
    m_byte = 200
    path = tmp_path / "tags.xlsx"
    path.write_bytes(tia_xlsx(settings(word_order, base_address=40), "paper-5x5", m_byte))
    wb = openpyxl.load_workbook(path)
    assert wb.sheetnames == ["PLC Tags"]
    rows = [[c if c is not None else "" for c in row] for row in wb["PLC Tags"].iter_rows(values_only=True)]
    assert tuple(rows[0]) == TIA_COLUMNS
    tags = [dict(zip(TIA_COLUMNS, r)) for r in rows[1:]]
    names = [t["Name"] for t in tags]
    assert len(names) == len(set(names))
    mem = s7_memory(word_order, m_byte)
    read = {t["Name"]: read_s7(mem, t["Logical Address"], t["Data Type"]) for t in tags}
    for t in tags:
        assert t["Path"] == "eskin_paper_5x5"
        assert t["Hmi Visible"] == t["Hmi Accessible"] == "True"
        assert t["Hmi Writeable"] == ("True" if t["Name"] in WRITTEN else "False")
    expect = {**VALUES, **WRITTEN}
    for r in REGISTERS:
        if r.words == 2 and word_order == "little":
            # an S7 reads a double word high word first: the low-word-first pair is two words
            assert r.name not in read
            assert read[f"{r.name}_HI"] << 16 | read[f"{r.name}_LO"] == expect[r.name], r.name
        else:
            assert read[r.name] == expect[r.name], r.name
    for b in BITS:
        assert read[b.name] == bool(VALUES["STATUS"] & b), b.name


def test_tia_rows_refuse_an_odd_m_byte():
    result = CliRunner().invoke(main, ["plc", "export", "-p", str(PROFILES / "paper-5x5.toml"), "--format", "tia",
                                       "--m-byte", "3", "-o", "x"])
    assert result.exit_code == 2 and "--m-byte" in result.output and "even" in result.output


# -- Codesys --------------------------------------------------------------------------

SIZE = {"WORD": 2, "UINT": 2, "INT": 2, "UDINT": 4, "DINT": 4, "REAL": 4}


def parsed(text):
    """The source parsed by blark (an IEC 61131-3 grammar), failing on a syntax error."""
    result = parse_source_code(text)
    assert result.exception is None, result.exception
    return result.transform()


def structs(code):
    out = {}
    for item in code.items:
        if type(item).__name__ == "DataTypeDeclaration":
            decl = item.declaration
            out[str(decl.name)] = [(str(d.variables[0]), str(d.init.spec)) for d in decl.declarations]
    return out


@pytest.mark.parametrize("word_order", ["big", "little"])
def test_codesys_source_parses_and_its_types_overlay_the_channels(word_order):
    code = parsed(codesys_st(settings(word_order, base_address=100), "paper-5x5", input_word=32, output_word=8))
    kinds = [type(i).__name__ for i in code.items]
    assert kinds.count("DataTypeDeclaration") == 2 and "FunctionBlock" in kinds and "Function" in kinds
    types = structs(code)
    assert set(types) == {"ST_Eskin_paper_5x5_In", "ST_Eskin_paper_5x5_Out"}
    text = codesys_st(settings(word_order, base_address=100), "paper-5x5", input_word=32, output_word=8)
    assert "stIn  AT %IW32 : ST_Eskin_paper_5x5_In;" in text and "stOut AT %QW8 : ST_Eskin_paper_5x5_Out;" in text
    # the read channel spans the scores appended after COMMAND and ENABLE
    assert "offset 100, length 24" in text and "offset 120, length 2" in text
    # pack_mode 1: members one after the other; a little-endian runtime stores each
    # channel word as it came, low byte first
    regs = holding(word_order, 100)
    memory = b"".join(regs[100 + i].to_bytes(2, "little") for i in range(IMAGE_COUNT))
    at, read = 0, {}
    for name, iec in types["ST_Eskin_paper_5x5_In"]:
        raw = int.from_bytes(memory[at: at + SIZE[iec]], "little")
        read[name] = signed(raw, 16) if iec == "INT" else raw
        at += SIZE[iec]
    assert at == len(memory)
    assert (read["RESERVED_20"], read["RESERVED_21"]) == (WRITTEN["COMMAND"], WRITTEN["ENABLE"])  # the gap
    for r in REGISTERS:
        if r.access != "R":
            continue
        if r.words == 2 and word_order == "big":
            assert r.name not in read
            assert read[f"{r.name}_HI"] << 16 | read[f"{r.name}_LO"] == VALUES[r.name], r.name
        else:
            assert read[r.name] == VALUES[r.name], r.name
    assert types["ST_Eskin_paper_5x5_Out"] == [("COMMAND", "WORD"), ("ENABLE", "UINT")]


def test_codesys_bit_constants_are_the_status_bits():
    text = codesys_st(settings(), "paper-5x5")
    consts = dict(re.findall(r"EB_(\w+)\s*: UINT := (\d+);", text))
    assert consts == {s.name: str(int(s).bit_length() - 1) for s in BITS}


def test_the_function_block_in_the_docs_is_the_exported_one():
    docs = (ROOT / "docs" / "plc.md").read_text(encoding="utf-8")
    blocks = re.findall(r"```iecst\n(.*?)```", docs, re.S)
    assert blocks == [slip_guard_st()]
    assert slip_guard_st() in codesys_st(settings(), "paper-5x5")
    fb = parsed(slip_guard_st()).items[0]
    assert type(fb).__name__ == "FunctionBlock" and str(fb.name) == "FB_SlipGuard"


def test_slip_guard_reads_the_bits_the_table_gives():
    text = slip_guard_st()
    for var, bit in (("bValid", Status.DATA_VALID), ("bStale", Status.SENSOR_STALE), ("bSlip", Status.SLIP),
                     ("bSlipLatched", Status.SLIP_LATCHED), ("bOffline", Status.BRIDGE_OFFLINE)):
        assert re.search(rf"\b{var}\s*:= wStatus\.{int(bit).bit_length() - 1};", text), var


# -- the command -------------------------------------------------------------------

@pytest.mark.parametrize("fmt,name", [("codesys", "eskin_paper_5x5.st"), ("tia", "eskin_paper_5x5_tags.xlsx"),
                                      ("csv", "eskin_paper_5x5_tags.csv")])
def test_export_command_writes_the_file_into_the_folder(fmt, name, tmp_path):
    res = subprocess.run([sys.executable, "-m", "eskin_industrial", "plc", "export", "-p",
                          str(PROFILES / "paper-5x5.toml"), "--format", fmt, "-o", str(tmp_path / "out")],
                         capture_output=True, timeout=60)
    assert res.returncode == 0, res.stderr
    assert [p.name for p in (tmp_path / "out").iterdir()] == [name]
    data = (tmp_path / "out" / name).read_bytes()
    if fmt == "tia":
        assert data == tia_xlsx(PROFILE.modbus.plc, PROFILE.name, method=METHOD)
    else:
        assert data.decode() == (codesys_st(PROFILE.modbus.plc, PROFILE.name, method=METHOD) if fmt == "codesys"
                                 else flat_csv(PROFILE.modbus.plc, method=METHOD))


def test_export_to_standard_output():
    res = CliRunner().invoke(main, ["plc", "export", "-p", str(PROFILES / "paper-5x5.toml"), "--format", "csv"])
    assert res.exit_code == 0
    assert res.output == flat_csv(PROFILE.modbus.plc, method=METHOD)


@pytest.mark.parametrize("method", ["cof-track", "paper", "force-rate"])
def test_exported_files_say_what_the_profiles_method_puts_in_its_scores(method, tmp_path):
    """METHOD_ID and SCORE_A/SCORE_B hold what the profile's deciding method puts
    there: each file describes them as `plc map` does, not with the generic words."""
    from eskin_industrial.detect.methods import METHODS

    text = (PROFILES / "paper-5x5.toml").read_text()
    path = tmp_path / "p.toml"
    path.write_text(re.sub(r'(?m)^method = "[^"]*"', f'method = "{method}"', text, count=1))
    a, b = METHODS[method].scores
    out = {}
    for fmt in ("csv", "codesys", "tia"):
        res = subprocess.run([sys.executable, "-m", "eskin_industrial", "plc", "export", "-p", str(path),
                              "--format", fmt, "-o", str(tmp_path / "out")], capture_output=True, timeout=60)
        assert res.returncode == 0, res.stderr
    rows = {r["name"]: r["description"] for r in
            csv.DictReader(io.StringIO((tmp_path / "out" / "eskin_paper_5x5_tags.csv").read_text()))}
    assert f"{METHODS[method].code} = {method} here" in rows["METHOD_ID"]
    assert rows["SCORE_A"].startswith(f"{method}'s {a.name}") and rows["SCORE_B"].startswith(f"{method}'s {b.name}")
    shown = CliRunner().invoke(main, ["plc", "map", "-p", str(path), "--format", "csv"]).output
    assert rows["SCORE_A"] in shown and rows["SCORE_B"] in shown  # the same words as the map's
    out["st"] = (tmp_path / "out" / "eskin_paper_5x5.st").read_text()
    assert f"{method}'s {a.name}" in out["st"] and f"{method}'s {b.name}" in out["st"]
    tia = openpyxl.load_workbook(tmp_path / "out" / "eskin_paper_5x5_tags.xlsx")["PLC Tags"]
    comments = {r[0]: r[TIA_COLUMNS.index("Comment")] for r in tia.iter_rows(values_only=True)}
    assert f"{method}'s {a.name}" in comments["SCORE_A"]


def test_a_register_added_to_the_table_appears_in_every_file(monkeypatch, tmp_path):
    from eskin_industrial.outputs.plc import image

    added = image.Register("GRIP_WIDTH", 22, "u32", "0.01 mm", "an added value")
    table = (*image.REGISTERS, added)
    monkeypatch.setattr(image, "REGISTERS", table)
    monkeypatch.setattr(image, "REG", {r.name: r for r in table})
    s = settings("little", base_address=10)
    row = next(r for r in csv.DictReader(io.StringIO(flat_csv(s))) if r["name"] == "GRIP_WIDTH")
    assert (row["address"], row["reference"], row["data_type"], row["word_order"], row["scale"], row["unit"]) == \
        ("32", "40033", "UDINT", "little", "0.01", "mm")
    types = structs(parsed(codesys_st(s, "paper-5x5")))
    assert ("GRIP_WIDTH", "UDINT") in types["ST_Eskin_paper_5x5_In"]
    path = tmp_path / "t.xlsx"
    path.write_bytes(tia_xlsx(s, "paper-5x5"))
    names = {r[0]: r[3] for r in openpyxl.load_workbook(path)["PLC Tags"].iter_rows(values_only=True)}
    assert names["GRIP_WIDTH_LO"] == "%MW44" and names["GRIP_WIDTH_HI"] == "%MW46"  # low word first, S7 high first


def test_export_of_a_bridge_gives_each_node_its_block_and_names(tmp_path):
    bridge = ROOT / "examples" / "deploy" / "bridge.toml"  # gripper-left at 0, gripper-right at 100
    for fmt in ("codesys", "tia", "csv"):
        res = subprocess.run([sys.executable, "-m", "eskin_industrial", "plc", "export", "--config", str(bridge),
                              "--format", fmt, "-o", str(tmp_path), "--m-byte", "1000"], capture_output=True,
                             timeout=60)
        assert res.returncode == 0, res.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        f"eskin_gripper_{side}{suffix}" for side in ("left", "right") for suffix in (".st", "_tags.csv", "_tags.xlsx"))
    tia = {side: [r for r in openpyxl.load_workbook(tmp_path / f"eskin_gripper_{side}_tags.xlsx")["PLC Tags"]
                  .iter_rows(values_only=True)][1:] for side in ("left", "right")}
    names = [r[0] for rows in tia.values() for r in rows]
    assert len(names) == len(set(names))  # one PLC: tag names unique across both tables
    assert all(r[0].startswith(f"gripper_{side}_") and r[1] == f"eskin_gripper_{side}"
               for side, rows in tia.items() for r in rows)
    # one MB_SERVER buffer from %MB1000: the right block 100 registers (200 bytes) further
    left = {r[0].removeprefix("gripper_left_"): r[3] for r in tia["left"]}
    right = {r[0].removeprefix("gripper_right_"): r[3] for r in tia["right"]}
    assert left["STATUS"] == "%MW1000" and right["STATUS"] == "%MW1200" and right["F_SUM"] == "%MD1208"
    assert right["DATA_VALID"] == "%M1201.5"
    csv_right = list(csv.DictReader(io.StringIO((tmp_path / "eskin_gripper_right_tags.csv").read_text())))
    assert (csv_right[0]["name"], csv_right[0]["address"], csv_right[0]["reference"]) == \
        ("gripper_right_STATUS", "100", "40101")
    st = (tmp_path / "eskin_gripper_right.st").read_text()
    assert "offset 100, length 24" in st and "GVL_Eskin_gripper_right" in st
    assert set(structs(parsed(st))) == {"ST_Eskin_gripper_right_In", "ST_Eskin_gripper_right_Out"}


def test_export_of_one_profile_takes_a_node_name_and_base_address():
    res = CliRunner().invoke(main, ["plc", "export", "-p", str(PROFILES / "paper-5x5.toml"), "--format", "csv",
                                    "--node-name", "left", "--base-address", "300"])
    assert res.exit_code == 0, res.output
    first = next(csv.DictReader(io.StringIO(res.output)))
    assert (first["name"], first["address"], first["reference"]) == ("left_STATUS", "300", "40301")


@pytest.mark.parametrize("args,needle", [
    (["--format", "csv"], "-p PROFILE"),  # neither -p nor --config
    (["--format", "csv", "-p", "P", "--config", "C"], "-p PROFILE"),
    (["--format", "csv", "--config", str(ROOT / "examples" / "deploy" / "bridge.toml")], "-o DIR"),
    (["--format", "csv", "--config", str(ROOT / "examples" / "deploy" / "bridge.toml"), "-o", "x",
      "--node-name", "a"], "--node-name"),
])
def test_export_refuses_unclear_requests(args, needle):
    res = CliRunner().invoke(main, ["plc", "export", *args])
    assert res.exit_code == 2 and needle in res.output, res.output
