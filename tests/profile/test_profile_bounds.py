"""Every numeric profile key has a plausible range, checked when the profile loads
(`profile check`, `--check`, every command that starts): `pitch_mm = 1e200` gave an
OverflowError traceback in `detect`, `pitch_mm = 1e308` an infinite centre of force
and `stable valid=1` through a slide, `rate_hz = 1e-300` was accepted."""

from __future__ import annotations

import copy
import dataclasses
import tomllib
import typing
from collections.abc import Iterator

import pytest
from click.testing import CliRunner

from eskin_industrial.cli import main
from eskin_industrial.profile import Profile
from eskin_industrial.schema import SchemaError, build
from tests.helpers.paths import PROFILES

BASE = tomllib.loads((PROFILES / "paper-5x5.toml").read_text(encoding="utf-8"))


def numeric_keys(cls: type, prefix: tuple[str, ...] = ()) -> Iterator[tuple[tuple[str, ...], str]]:
    """(dotted path, "float" / "int" / "floats" (a list)) of every numeric key."""
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        if not f.init:
            continue
        tp = hints[f.name]
        if dataclasses.is_dataclass(tp):
            yield from numeric_keys(tp, (*prefix, f.name))
            continue
        text = str(tp)
        if "Literal" in text:
            continue
        if "tuple[float" in text:
            yield (*prefix, f.name), "floats"
        elif "float" in text:
            yield (*prefix, f.name), "float"
        elif "int" in text:
            yield (*prefix, f.name), "ints" if "tuple" in text else "int"


KEYS = sorted(numeric_keys(Profile))


def with_value(path: tuple[str, ...], value: object) -> dict:
    table = copy.deepcopy(BASE)
    at = table
    for part in path[:-1]:
        at = at.setdefault(part, {})
    at[path[-1]] = value
    return table


def refused(path: tuple[str, ...], kind: str, v: float) -> bool:
    if kind == "floats":
        value: object = [v] * (25 if path[-1] in ("x_mm", "y_mm") else 1)
    elif kind == "ints":
        value = [int(v)]
    elif kind == "int":
        value = int(v)
    else:
        value = v
    try:
        build(Profile, with_value(path, value))
    except SchemaError:
        return True
    return False


def test_every_numeric_key_is_walked():
    names = {".".join(p) for p, _ in KEYS}
    assert {"layout.pitch_mm", "sensor.rate_hz", "detector.cof_track.z", "calibration.zero",
            "output.hold_s"} <= names and len(names) > 90


@pytest.mark.parametrize(("path", "kind"), KEYS, ids=[".".join(p) for p, _ in KEYS])
def test_every_numeric_key_has_a_plausible_range(path, kind):
    huge = 2.0**62 if kind in ("int", "ints") else 1e308
    assert refused(path, kind, huge), f"{'.'.join(path)} = {huge:g} accepted"
    assert refused(path, kind, -huge), f"{'.'.join(path)} = {-huge:g} accepted"
    if kind in ("float", "floats") and refused(path, kind, 0.0):
        # a key that must be above 0 has a plausible least value too
        assert refused(path, kind, 1e-300), f"{'.'.join(path)} = 1e-300 accepted"


@pytest.mark.parametrize(("key", "value", "message"), [
    ("pitch_mm = 5.0", "pitch_mm = 1e200", "[layout] pitch_mm: expected a value in [0.01, 1000], got 1e+200"),
    ("pitch_mm = 5.0", "pitch_mm = 1e308", "[layout] pitch_mm: expected a value in [0.01, 1000], got 1e+308"),
    ("rate_hz = 100.0", "rate_hz = 1e-300", "[sensor] rate_hz: expected a value in [1, 100000], got 1e-300"),
])
def test_absurd_settings_are_one_line_errors_before_anything_starts(tmp_path, key, value, message):
    text = (PROFILES / "paper-5x5.toml").read_text(encoding="utf-8")
    assert key in text
    path = tmp_path / "absurd.toml"
    path.write_text(text.replace(key, value, 1), encoding="utf-8")
    rec = tmp_path / "r.csv"
    rec.write_text("t," + ",".join(f"f{i}" for i in range(25)) + "\n" +
                   "".join(f"{k / 100},{','.join(['0.1'] * 25)}\n" for k in range(100)), encoding="utf-8")
    for args in (["profile", "check", str(path)], ["detect", "-p", str(path), str(rec)],
                 ["bridge", "-p", str(path), "--source", f"recording:{rec}", "--check"]):
        res = CliRunner().invoke(main, args)
        assert res.exit_code == 2, (args, res.output)
        lines = [ln for ln in res.output.splitlines() if ln.strip()]
        assert len(lines) == 1 and message in lines[0], (args, res.output)
