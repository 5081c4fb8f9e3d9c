"""Fuzz tests of the file readers: recording CSVs, CAN logs and profiles.

A bad file is one :class:`InputFormatError` (or :class:`ProfileError`) line naming
the file and where in it; never another exception, never a traceback.
"""
from __future__ import annotations

import json
import math
import re
import tempfile
import tomllib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from eskin_industrial.bus.can.layout import CanLayout, decode_messages
from eskin_industrial.bus.can.log import read_can_log
from eskin_industrial.errors import InputFormatError, ProfileError
from eskin_industrial.profile import Profile, parse_profile
from eskin_industrial.recording import read_recording
from tests.helpers.fuzz import fuzz
from tests.helpers.paths import PROFILES


def _write(name: str, content: bytes) -> Path:
    # hypothesis runs many examples per test function: a fresh directory each, not tmp_path
    path = Path(tempfile.mkdtemp(prefix="fuzz-")) / name
    path.write_bytes(content)
    return path


def _one_line_naming(exc: Exception, path: Path) -> str:
    msg = str(exc)
    assert "\n" not in msg and msg.startswith(f"{path}: "), msg
    return msg


# -- recordings ---------------------------------------------------------------------

cells = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-10**6, 10**6).map(str),
    st.sampled_from(["", " ", "nan", "inf", "-inf", "1e5", "x", "1,5", '"1"', "0x10", "1_0", "\t2", "1;2", "\x00"]),
    st.text(max_size=4),
)


@st.composite
def recordings(draw) -> bytes:
    """A valid recording, then perhaps mangled: a bad cell, a short or long row, an
    empty line, stray line endings, a broken header, or random bytes."""
    n = draw(st.integers(1, 4))
    prefix = draw(st.sampled_from(["f", "raw"]))
    header = "t," + ",".join(f"{prefix}{i}" for i in range(n))
    rows = [[repr(float(t))] + [repr(v) for v in draw(st.lists(st.floats(-1e3, 1e3), min_size=n, max_size=n))]
            for t in range(draw(st.integers(0, 5)))]
    how = draw(st.sampled_from(["none", "cell", "width", "empty", "cr", "header", "bytes", "text"]))
    if how == "bytes":
        return draw(st.binary(max_size=200))
    if how == "text":
        return draw(st.text(max_size=200)).encode("utf-8", "surrogatepass")
    if rows and how == "cell":
        r = draw(st.integers(0, len(rows) - 1))
        rows[r][draw(st.integers(0, n))] = draw(cells)
    elif rows and how == "width":
        r = draw(st.integers(0, len(rows) - 1))
        rows[r] = rows[r][:-1] if draw(st.booleans()) else rows[r] + ["1.0"]
    elif how == "header":
        header = draw(st.sampled_from(["", "x", "t", "t,", f"t,{prefix}1", "time,f0", "\ufefft,f0", "t,f0,raw1"]))
    lines = [header] + [",".join(r) for r in rows]
    if how == "empty":
        lines.insert(draw(st.integers(1, len(lines))), "")
    sep = draw(st.sampled_from(["\n", "\r\n"])) if how != "cr" else "\r"
    text = sep.join(lines) + draw(st.sampled_from(["", "\n", "\n\n"]))
    return text.encode("utf-8", "surrogatepass")


@fuzz(300)
@given(content=recordings())
@pytest.mark.slow
def test_a_recording_reads_or_fails_with_one_line_naming_file_and_line(content):
    path = _write("rec.csv", content)
    try:
        rec = read_recording(path)
    except InputFormatError as exc:
        msg = _one_line_naming(exc, path)
        # a problem in a row names its line; file-level problems say what is missing
        assert re.search(r": line \d+|: empty file|: no data rows|: not a text|: cannot parse", msg), msg
        return
    assert rec.values.ndim == 2 and rec.values.shape == (len(rec.t), rec.taxels) and len(rec.t) >= 1
    assert rec.values.dtype == np.float64


@fuzz(100)
@given(n=st.integers(1, 4), k=st.integers(1, 6), data=st.data())
def test_a_bad_cell_is_reported_at_its_line(n, k, data):
    rows = [[f"{i * 0.01:.2f}"] + ["1.5"] * n for i in range(k)]
    r, col = data.draw(st.integers(0, k - 1)), data.draw(st.integers(0, n))
    rows[r][col] = data.draw(st.sampled_from(["x", "1..2", "--1", "1e", "#", "nan(", "1 2"]))
    text = "t," + ",".join(f"f{i}" for i in range(n)) + "\n" + "\n".join(",".join(row) for row in rows) + "\n"
    path = _write("cell.csv", text.encode())
    with pytest.raises(InputFormatError) as info:
        read_recording(path)
    assert _one_line_naming(info.value, path).startswith(f"{path}: line {r + 2}, column {col + 1}: not a number")


# -- CAN logs -----------------------------------------------------------------------

def _candump_line(t: float, can_id: int, data: bytes, ext: bool, fd: bool) -> str:
    ident = f"{can_id:08X}" if ext else f"{can_id:03X}"
    sep = "##0" if fd else "#"
    return f"({t:.6f}) vcan0 {ident}{sep}{data.hex().upper()}"


@st.composite
def can_logs(draw) -> bytes:
    """A candump log, perhaps truncated anywhere, with mangled or random lines."""
    lines = [_candump_line(draw(st.floats(0, 1e6)), draw(st.integers(0x200, 0x20F)),
                           draw(st.binary(max_size=8)), False, False) for _ in range(draw(st.integers(0, 6)))]
    lines += [_candump_line(draw(st.floats(0, 1e6)), draw(st.integers(0, 0x1FFFFFFF)),
                            draw(st.binary(max_size=64)), True, True) for _ in range(draw(st.integers(0, 2)))]
    junk = st.one_of(
        st.text(max_size=60),
        st.sampled_from(["(1.0) vcan0 200#", "(x) vcan0 200#00", "(1.0) vcan0 #00", "(1.0) vcan0 200#0",
                         "(1.0) vcan0 200#ZZ", "(1.0) vcan0 2000000000#00", "(1.0)", "() vcan0 200#00",
                         "(1.0) vcan0 200#R", "(1.0) vcan0 200##F00", "(nan) vcan0 200#00",
                         "(inf) vcan0 200#0011", "(1e400) vcan0 20F#0011223344556677"]),
    )
    for _ in range(draw(st.integers(0, 3))):
        lines.insert(draw(st.integers(0, len(lines))), draw(junk))
    content = "\n".join(lines).encode("utf-8", "surrogatepass") + b"\n"
    if draw(st.booleans()):
        content = content[:draw(st.integers(0, len(content)))]
    return content


@fuzz(200)
@given(content=can_logs() | st.binary(max_size=200))
def test_a_can_log_replays_or_fails_with_one_line(content):
    path = _write("traffic.log", content)
    try:
        messages = list(read_can_log(path))
    except InputFormatError as exc:
        _one_line_naming(exc, path)
        return
    # whatever the log held goes through the assembler without raising
    lay = CanLayout(25, 16, "little", 0x200)
    scans, asm = decode_messages(lay, messages, 100.0)
    assert sum(asm.counters[k] for k in ("frames", "foreign_frames", "error_frames")) == len(messages)
    assert all(math.isfinite(s.t) for s in scans)


# -- profiles -----------------------------------------------------------------------

def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
    if isinstance(v, int):
        return str(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{json.dumps(k)} = {_toml_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(type(v))


def _dump(table: dict) -> str:
    """A profile table back to TOML: a section per table, nested tables inline except
    the two-level [modbus.node] / [modbus.plc]."""
    out = []
    for section, body in table.items():
        if not isinstance(body, dict):
            out.append(f"{json.dumps(section)} = {_toml_value(body)}")
            continue
        if section == "modbus" and all(isinstance(x, dict) for x in body.values()):
            for sub, items in body.items():
                out.append(f"[modbus.{json.dumps(sub)}]")
                out += [f"{json.dumps(k)} = {_toml_value(x)}" for k, x in items.items()]
            continue
        out.append(f"[{json.dumps(section)}]")
        out += [f"{json.dumps(k)} = {_toml_value(x)}" for k, x in body.items()]
    return "\n".join(out) + "\n"


BASES = {name: tomllib.loads((PROFILES / name).read_text()) for name in ("paper-5x5.toml", "hand-4x5.toml")}
odd_values = st.one_of(
    st.booleans(), st.integers(-2**40, 2**40), st.sampled_from([0, -1, 1, 0.0, -0.0, 12, 16, 255, 256, 0x7FF, 2**63 - 1]),
    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=6), st.sampled_from(["little", "db2", "uint16"]),
    st.lists(st.floats(-1e3, 1e3) | st.integers(0, 9), max_size=26), st.just({}), st.just({"zero": 1.0}),
)


def _leaves(table: dict, path: tuple = ()) -> list[tuple]:
    out = []
    for k, v in table.items():
        out.append(path + (k,))
        if isinstance(v, dict):
            out += _leaves(v, path + (k,))
    return out


@st.composite
def mutated_profiles(draw) -> str:
    table = json.loads(json.dumps(BASES[draw(st.sampled_from(sorted(BASES)))]))  # a deep copy
    for _ in range(draw(st.integers(1, 3))):
        where = draw(st.sampled_from(_leaves(table)))
        parent = table
        for k in where[:-1]:
            parent = parent[k]
        how = draw(st.sampled_from(["drop", "value", "unknown"]))
        if how == "drop":
            del parent[where[-1]]
        elif how == "value":
            parent[where[-1]] = draw(odd_values)
        else:
            parent[draw(st.sampled_from(["extra", "rate", "base_idx", "Zero"]))] = draw(odd_values)
    return _dump(table)


@fuzz(400)
@given(text=mutated_profiles())
def test_a_mutated_profile_loads_or_fails_with_one_line_naming_section_and_key(text):
    try:
        profile = parse_profile(text, "fuzz.toml")
    except ProfileError as exc:
        msg = str(exc)
        assert "\n" not in msg, msg
        # "[section] key: ..." (the section alone for a whole section), never an empty "[]"
        assert re.match(r"fuzz\.toml: (\[[^\]\s]+\]( \S+)?: |not valid TOML: )", msg), msg
        return
    assert isinstance(profile, Profile) and profile.taxels >= 1


def _numeric_leaves(table: dict, path: tuple = ()) -> list[tuple]:
    out = []
    for k, v in table.items():
        if isinstance(v, dict):
            out += _numeric_leaves(v, path + (k,))
        elif isinstance(v, (int, float)) and not isinstance(v, bool):
            out.append(path + (k,))
    return out


SPECIAL = [math.inf, -math.inf, math.nan, 1e300, -1e300, 1e-300, 0, -1, 10**30, 2**63]


def _profile_error_or_load(text: str) -> None:
    try:
        parse_profile(text, "fuzz.toml")
    except ProfileError as exc:
        msg = str(exc)
        assert "\n" not in msg and re.match(r"fuzz\.toml: \[[^\]\s]+\] \S+: ", msg), msg


@pytest.mark.parametrize("name", sorted(BASES))
def test_every_number_of_a_profile_at_the_extremes(name):
    """Each numeric key in turn set to infinities, NaN, huge, tiny, zero, negative:
    loads or is refused naming its [section] key, never anything else."""
    for where in _numeric_leaves(BASES[name]):
        for value in SPECIAL:
            table = json.loads(json.dumps(BASES[name]))
            parent = table
            for k in where[:-1]:
                parent = parent[k]
            parent[where[-1]] = value
            _profile_error_or_load(_dump(table))


@fuzz(150)
@given(data=st.data())
def test_pairs_of_extreme_numbers_in_a_profile(data):
    """Two keys at once (a huge rate with a huge hop overflows where neither alone does)."""
    table = json.loads(json.dumps(BASES[data.draw(st.sampled_from(sorted(BASES)))]))
    leaves = _numeric_leaves(table)
    for where in data.draw(st.lists(st.sampled_from(leaves), min_size=2, max_size=2, unique=True)):
        parent = table
        for k in where[:-1]:
            parent = parent[k]
        parent[where[-1]] = data.draw(st.sampled_from([1e300, 1e-300, 1e10, 1e-10, 1e200]))
    _profile_error_or_load(_dump(table))


def test_huge_rate_and_hop_name_the_rate():
    table = json.loads(json.dumps(BASES["hand-4x5.toml"]))
    table["sensor"]["rate_hz"] = 1e300
    table["detector"].update(window_s=1e300, hop_s=1e300, lag_s=1.0)
    with pytest.raises(ProfileError, match=r"^fuzz\.toml: \[sensor\] rate_hz: expected a value in \[1, "
                                           r"100000\], got 1e\+300$"):
        parse_profile(_dump(table), "fuzz.toml")
    table["sensor"]["rate_hz"] = 1e5  # the largest rate and the longest window: too many samples
    table["detector"].update(window_s=600.0, hop_s=0.1)
    with pytest.raises(ProfileError, match=r"^fuzz\.toml: \[detector\] window_s: expected at most 1000000 samples"):
        parse_profile(_dump(table), "fuzz.toml")
    table["sensor"]["rate_hz"] = math.inf
    with pytest.raises(ProfileError, match=r"^fuzz\.toml: \[sensor\] rate_hz: expected a finite number, got inf$"):
        parse_profile(_dump(table), "fuzz.toml")


def test_an_empty_wavelet_name_is_a_profile_error():
    # PyWavelets raises TypeError (not ValueError) for "": it must still be one line
    table = json.loads(json.dumps(BASES["hand-4x5.toml"]))
    table["detector"]["wavelet"] = ""
    with pytest.raises(ProfileError, match=r"^fuzz\.toml: \[detector\] wavelet: expected a discrete PyWavelets"):
        parse_profile(_dump(table), "fuzz.toml")
