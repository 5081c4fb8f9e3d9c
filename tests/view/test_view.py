"""The live view's renderer on synthetic snapshots (pure: no terminal, no clock)."""
from __future__ import annotations

import re

import numpy as np
import pytest

from eskin_industrial.detect.settings import DetectorSettings, VaryingForceSettings
from eskin_industrial.detect.updates import Update
from eskin_industrial.node import Health
from eskin_industrial.outputs.plc.image import read_back, status_names
from eskin_industrial.profile import ModbusPlcSection
from eskin_industrial.view import IndicatorScale, Snapshot, indicator_scale, render
from eskin_industrial.view.screen import HEAT_COLORS, RAMP, fit_number
from eskin_industrial.view.terminal import visible_width
from tests.helpers.snapshots import StatusImage

FINGERS = ("index", "middle", "ring", "little")
PAPER_SCALE = IndicatorScale(("R_coe", "R_dw"), "paper", (2.5, 2.5), (0.5, 0.5))
ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")


def registers(update: Update | None, word_order: str = "big", frame_age_s: float | None = 0.004) -> dict[str, int]:
    image = StatusImage(ModbusPlcSection(word_order=word_order), 0.2)
    if update is not None:
        image.observe(Update(update.t - 0.1, 0.1, 0.1, 1, True, update.f_sum, update.xc, update.yc, 0))
        image.observe(update)
    return read_back(image.render(Health(frame_age_s, False, 2, 1)), image.tail, word_order)


def snap(forces=None, state="slip", valid=True, stale=False, r_coe=3.1, r_dw=0.2, **kw) -> Snapshot:
    if forces is None:
        forces = np.arange(20, dtype=float).reshape(4, 5) / 4.0  # 0 .. 4.75 N, all different
    u = Update(12.3, r_coe or 0.0, r_dw or 0.0, {"no_contact": 0, "stable": 1, "variable_force": 2, "slip": 3}.get(state or "", 1),
               valid, 6.02, 10.1, 30.2, 0)
    base = dict(forces=forces, row_names=FINGERS if forces.shape[0] == 4 else None, r_coe=r_coe, r_dw=r_dw,
                scale=PAPER_SCALE, state=state, valid=valid, stale=stale, f_sum=6.02, cof=(10.1, 30.2),
                registers=registers(u), registers_from="as the PLC reads them",
                counters={"scans": 1234, "lost": 0, "drops": 0}, elapsed_s=12.3, scan_rate_hz=100.0,
                source="hand-4x5 | paper | virtual", title="eskin-bus test",
                log=tuple(f"{t:7.2f} s  stable" for t in range(30)))
    base.update(kw)
    regs = base["registers"]
    if "status_bits" not in kw and regs is not None:  # as the caller decodes them beside the registers
        base["status_bits"] = status_names(regs["STATUS"])
    return Snapshot(**base)


def heat_rows(lines: list[str]) -> list[str]:
    rows = [next(line for line in lines if ANSI.sub("", line).startswith(name)) for name in FINGERS]
    assert len(rows) == 4
    return rows


def test_plain_heat_map_characters_and_values_follow_the_forces():
    rng = np.random.default_rng(3)
    forces = rng.permutation(np.linspace(0.0, 5.0, 20)).reshape(4, 5)
    lines = render(snap(forces), 80, 24, color=False)
    chars, values = [], []
    for line in heat_rows(lines):
        cells = line[len("middle "):]
        for c in range(5):
            cell = cells[6 * c: 6 * c + 6]
            assert cell[0] == cell[1]  # two ramp characters, then the value
            chars.append(cell[0])
            values.append(float(cell[2:5]))
    np.testing.assert_allclose(values, forces.ravel(), atol=0.051)
    order = np.argsort(forces.ravel(), kind="stable")
    levels = [RAMP.index(chars[i]) for i in order]
    assert levels == sorted(levels)  # heavier taxel, denser character
    assert chars[order[-1]] == "@" and chars[order[0]] == " "
    assert len(set(chars)) >= 8  # the ramp is used, not two levels


def test_color_heat_map_colours_follow_the_forces():
    forces = np.linspace(0.0, 5.0, 20)[::-1].reshape(4, 5).copy()
    lines = render(snap(forces), 80, 24, color=True)
    colours = []
    for line in heat_rows(lines):
        colours += [int(c) for c in re.findall(r"\x1b\[48;5;(\d+);38;5;\d+m", line)]
    assert len(colours) == 20
    levels = [HEAT_COLORS.index(c) for c in colours]
    order = np.argsort(forces.ravel(), kind="stable")
    assert [levels[i] for i in order] == sorted(levels)
    assert colours[int(np.argmax(forces))] == HEAT_COLORS[-1] and colours[int(np.argmin(forces))] == HEAT_COLORS[0]


def gauge(lines: list[str], name: str) -> tuple[str, str]:
    line = next(ANSI.sub("", line) for line in lines if re.search(name + r"\s+\[", ANSI.sub("", line)))
    tail = line[line.index(name):]
    return tail[tail.index("[") + 1: tail.index("]")], tail[tail.index("]") + 1:]


def test_gauges_mark_the_thresholds_and_fill_to_the_value():
    lines = render(snap(r_coe=3.1, r_dw=0.2), 80, 24, color=False)
    bar, rest = gauge(lines, "R_coe")
    n = len(bar)
    assert n >= 10
    assert bar.index("|") == round(n / 2)  # slip threshold 2.5 on a 0..5 scale
    assert bar.index(":") == round(0.5 / 5 * n)  # varying-force threshold 0.5
    assert bar[bar.index("|") + 1] == "#"  # 3.1 is past the slip threshold
    assert float(rest.split()[0]) == pytest.approx(3.1) and "/2.5" in rest
    bar, rest = gauge(lines, "R_dw")
    assert bar[bar.index(":") + 1:] .strip("-|") == ""  # 0.2: below both thresholds, nothing past ':'
    assert bar[:bar.index(":")].count("#") == round(0.2 / 5 * n)
    over, _ = gauge(render(snap(r_coe=40.0), 80, 24, color=False), "R_coe")
    assert over.endswith(">")  # off the scale


def test_gauges_of_a_method_with_its_own_scale():
    sc = indicator_scale("cof-track", DetectorSettings())
    assert sc.slip == (1.0, 1.0) and sc.variable == (None, None)
    paper = indicator_scale("paper", DetectorSettings(slip_r_coe=3.0, slip_r_dw=2.0))
    assert paper.slip == (3.0, 2.0) and paper.variable == (None, None)  # varying force: the total force's test
    own = DetectorSettings(slip_r_coe=3.0, slip_r_dw=2.0, varying_force=VaryingForceSettings(evidence="method"))
    assert indicator_scale("paper", own).variable == (0.5, 0.5)  # the paper's own reading: its thresholds
    assert sc.names == ("onset_score", "slow_score")  # the gauges show the method's own scores
    bar, rest = gauge(render(snap(r_coe=0.6, scale=sc), 80, 24, color=False), "onset_score")
    assert ":" not in bar and bar.index("|") == round(len(bar) / 2) and "/1" in rest


@pytest.mark.parametrize("state, label, style", [
    ("slip", "SLIP", "41m"), ("variable_force", "VARIABLE FORCE", "48;5;214m"), ("stable", "STABLE", "42m"),
])
def test_states_are_shown_big_and_coloured(state, label, style):
    plain = render(snap(state=state), 80, 24, color=False)
    box = next(i for i, line in enumerate(plain) if re.search(rf"\|\s+{label}\s+\|", line))
    assert re.search(r"\+-{20,}\+", plain[box - 1]) and re.search(r"\+-{20,}\+", plain[box + 1])
    coloured = render(snap(state=state), 80, 24, color=True)
    assert style in coloured[box] and label in ANSI.sub("", coloured[box])
    assert "valid" in ANSI.sub("", coloured[box + 2])


@pytest.mark.parametrize("kw, label, why", [
    (dict(state="slip", valid=False), "SLIP", "not valid"),
    (dict(state="stable", stale=True), "UNKNOWN", "sensor stale"),
    (dict(state=None, r_coe=None, r_dw=None, forces=None, registers=None), "UNKNOWN", "waiting for data"),
])
def test_no_verdict_is_grey_and_says_so(kw, label, why):
    lines = render(snap(**kw), 80, 24, color=True)
    text = [ANSI.sub("", line) for line in lines]
    row = next(i for i, line in enumerate(text) if re.search(rf"\s{label}\s", line) and "STATE" not in line)
    assert "48;5;244m" in lines[row]  # grey, whatever the state
    assert "41m" not in lines[row] and "42m" not in lines[row]
    assert any(why in line for line in text)


def test_registers_are_shown_as_the_image_rendered_them():
    u = Update(12.3, 3.12, 1.2, 3, True, 70.5, 10.1, -3.2, 0)
    lines = [ANSI.sub("", line) for line in render(snap(registers=registers(u)), 100, 40, color=True)]
    text = "\n".join(lines)
    for token in ("SLIP", "SLIP_LATCHED", "DATA_VALID", "ENABLED", "STATE 3 (slip)", "R_COE 312", "R_DW 120",
                  "F_SUM 70500 mN", "XC 1010", "YC -320", "FRAME_AGE 4 ms", "SLIP_EVENTS 1", "LOST_SCANS 2",
                  "BUS_ERRORS 1", "as the PLC reads them"):
        assert token in text, token
    stale = "\n".join(render(snap(registers=registers(u, frame_age_s=None)), 100, 40, color=False))
    assert "SENSOR_STALE" in stale and "(no DATA_VALID)" in stale and "FRAME_AGE 65535 ms" in stale


def test_register_decoding_honours_the_word_order():
    u = Update(1.0, 1.0, 1.0, 3, True, 70.5, 1.0, 1.0, 0)
    big, little = registers(u, "big"), registers(u, "little")
    assert big == little and big["F_SUM"] == 70500


SIZES = [(80, 24), (120, 50), (60, 20), (48, 16), (40, 24), (30, 12), (24, 8), (20, 4), (12, 3), (1, 1)]


@pytest.mark.parametrize("width, height", SIZES)
@pytest.mark.parametrize("color", [False, True])
@pytest.mark.parametrize("rows", [4, 5])
def test_the_screen_fits_the_terminal(width, height, color, rows):
    forces = np.linspace(0, 9, rows * 5).reshape(rows, 5)
    lines = render(snap(forces, row_names=FINGERS if rows == 4 else None), width, height, color)
    assert 0 < len(lines) <= height
    assert all(visible_width(line) <= width for line in lines), lines
    if not color:
        assert not any("\x1b" in line for line in lines)
    if width >= 20 and height >= 4:
        assert any("SLIP" in ANSI.sub("", line) for line in lines)  # the state survives every cut


def test_a_full_screen_has_everything_and_the_newest_log_lines():
    text = [ANSI.sub("", line) for line in render(snap(), 80, 24, color=True)]
    joined = "\n".join(text)
    for part in ("eskin-bus test", "taxels, N", "R_coe [", "R_dw  [", "PLC registers", "counters",
                 "scans 1234", "state changes"):
        assert part in joined, part
    assert text[-1].strip() == "29.00 s  stable"  # the log ends with the newest line
    assert len(text) == 24


def test_plain_render_has_no_escape_codes_in_any_state():
    for kw in (dict(), dict(state="stable"), dict(state=None, forces=None, registers=None, r_coe=None, r_dw=None),
               dict(stale=True), dict(valid=False)):
        assert not any("\x1b" in line for line in render(snap(**kw), 80, 24, color=False))


def test_numbers_fit_their_cells():
    assert fit_number(3.14159, 4) == "3.14"
    assert fit_number(12.345, 3) == " 12"
    assert fit_number(-0.001, 4) == "0.00"
    assert fit_number(123456.0, 3) == ">>>"
    assert fit_number(float("nan"), 3) == "  ?"


def test_a_watch_snapshots_the_newest_values_of_a_running_pipeline(hand_profile):
    from eskin_industrial.calibration import Calibrator
    from eskin_industrial.frames import RawScan
    from eskin_industrial.outputs.plc.kept import KeptRegisters
    from eskin_industrial.pipeline import Pipeline
    from eskin_industrial.view.live import Watch
    from eskin_industrial.view.snapshot import RegisterTable
    from tests.helpers.scenes import grasp
    from tests.helpers.snapshots import node_status, snapshot_of

    pipe = Pipeline(hand_profile, rate_hz=100.0)
    status = node_status(hand_profile.stale_s)
    kept = KeptRegisters(hand_profile.modbus.plc)
    published: list = []

    def table() -> RegisterTable | None:
        t = kept.table()
        return None if t is None else RegisterTable(*t)

    watch = Watch(hand_profile, pipe, method="cof-track", snapshot=lambda: published[-1] if published else None,
                  registers=table, registers_from="as the bridge would publish them",
                  counters=lambda: {"scans": pipe.counters.scans, "lost_scans": pipe.counters.lost_scans, "other": 7},
                  source="hand-4x5", title="eskin-bus monitor", started=100.0)
    empty = watch.snapshot(100.5)
    assert empty.forces is None and empty.state is None and empty.stale and empty.registers is None
    f = grasp(120, n=20, seed=2)
    raw = Calibrator.from_section(hand_profile.calibration, 20).to_raw(f)
    for i, r in enumerate(raw):
        for u in pipe.push(RawScan(i, i / 100.0, r)):
            status.observe(u)
    watch.note("    1.00 s  stable")
    published.append(snapshot_of(status, 0.002))
    kept.publish(published[-1])
    s = watch.snapshot(101.5)
    assert s.forces.shape == (4, 5) and s.row_names == ("index", "middle", "ring", "little")
    np.testing.assert_allclose(s.forces.ravel(), f[-1], atol=0.01)
    assert s.state == "stable" and not s.stale and s.registers["STATE"] == 1 and "DATA_VALID" in s.status_bits
    assert s.counters == {"scans": 120, "lost": 0}  # the view's names, in its order; others left out
    assert s.scale.slip == (1.0, 1.0) and s.log == ("    1.00 s  stable",) and s.elapsed_s == 1.5
    assert s.scan_rate_hz == pytest.approx(120.0)  # scans since the first snapshot, a second before
    published.append(snapshot_of(status, 5.0))  # the node has gone quiet
    assert watch.snapshot(101.7).stale


def test_the_monitor_view_shows_the_deciding_methods_scores_with_the_registers(hand_profile):
    """SCORE_A and SCORE_B are published in a second run (after COMMAND and ENABLE):
    the view's register block shows them too, as a sink kept them."""
    from eskin_industrial.outputs.plc.kept import KeptRegisters
    from eskin_industrial.pipeline import Pipeline
    from eskin_industrial.view.live import Watch
    from eskin_industrial.view.snapshot import RegisterTable
    from tests.helpers.snapshots import node_status, snapshot_of

    status = node_status(hand_profile.stale_s)
    status.observe(Update(1.0, 0.5, 0.2, 3, True, 6.0, 10.0, 12.0, 0, 2.5, 0.75))
    kept = KeptRegisters(hand_profile.modbus.plc)
    kept.publish(snapshot_of(status, 0.002))
    assert len(kept.tail) == 2
    pipe = Pipeline(hand_profile, rate_hz=100.0)
    watch = Watch(hand_profile, pipe, method="cof-track", snapshot=lambda: None,
                  registers=lambda: RegisterTable(*kept.table()), registers_from="as the bridge would publish them",
                  counters=lambda: {}, source="hand-4x5", title="eskin-bus monitor", started=0.0)
    s = watch.snapshot(1.0)
    scale = hand_profile.modbus.plc.r_scale
    assert s.registers["SCORE_A"] == round(2.5 * scale) and s.registers["SCORE_B"] == round(0.75 * scale)
    text = ANSI.sub("", "\n".join(render(s, 120, 40, color=False)))
    assert f"SCORE_A {round(2.5 * scale)}" in text and "METHOD_ID" in text
    without = Watch(hand_profile, pipe, method="cof-track", snapshot=lambda: None, counters=lambda: {}, source="",
                    title="", started=0.0).snapshot(1.0)
    assert without.registers is None and without.status_bits == ()
