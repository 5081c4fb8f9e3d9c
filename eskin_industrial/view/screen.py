"""The live view's screen: a :class:`~eskin_industrial.view.snapshot.Snapshot` in,
the lines of one screen out.

Pure code, no I/O and no clock.  Every line is at most ``width`` visible characters
and there are at most ``height`` lines, so the terminal never wraps or scrolls.  With
``color`` the heat map uses ANSI 256-colour backgrounds and the state its colour;
without, the same screen in plain ASCII (a character ramp for the heat map), which
is also what the documentation shows.  What does not fit is left out by priority:
the state and gauges first, then the heat map, the registers, the counters, and the
state-change log takes what is left.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping

import numpy as np

from ..detect.state import GraspState
from ..frames import FrameFlag
from .snapshot import IndicatorScale, Snapshot

#: Plain heat map: light to heavy.
RAMP = " .:-=+*#%@"
#: Colour heat map: 256-colour indices from black through red and yellow to white.
HEAT_COLORS: tuple[int, ...] = (16, 52, 88, 124, 160, 196, 202, 208, 214, 220, 226, 227, 228, 229, 230, 231)
#: From this index on the heat colour is light: the value is written in black.
_LIGHT_FROM = 8

Seg = tuple[str, str]  # (text, SGR parameters; "" for none)
Line = list[Seg]

_STATE_STYLE = {
    "slip": "1;97;41",
    "variable_force": "1;30;48;5;214",
    "stable": "1;30;42",
    "no_contact": "1;97;44",
}
_GREY = "1;97;48;5;244"
_BIT_STYLE = {
    "SLIP": "1;31", "SLIP_LATCHED": "1;31", "DATA_VALID": "1;32", "SENSOR_STALE": "1;33",
    "BUS_FAULT": "1;31", "BRIDGE_OFFLINE": "1;31", "VARIABLE_FORCE": "1;33", "STABLE": "1;32",
}
#: Side by side only when the panel gets at least this many columns.
_PANEL_MIN = 30
_PANEL_MAX = 44


# -- pieces ------------------------------------------------------------------------

def heat_level(force: float, top: float) -> float:
    """Force as a fraction of the colour scale, in [0, 1]."""
    if not math.isfinite(force) or top <= 0:
        return 0.0
    return min(max(force / top, 0.0), 1.0)


def heat_char(level: float) -> str:
    return RAMP[min(int(level * len(RAMP)), len(RAMP) - 1)]


def heat_color(level: float) -> int:
    return HEAT_COLORS[min(int(level * len(HEAT_COLORS)), len(HEAT_COLORS) - 1)]


def fit_number(value: float, width: int) -> str:
    """``value`` in at most ``width`` characters, right-aligned, with as many
    decimals as fit (two at most)."""
    if not math.isfinite(value):
        return "?".rjust(width)
    if abs(value) < 0.005:
        value = 0.0  # calibration noise around zero must not read "-0.00"
    for decimals in (2, 1, 0):
        text = f"{value:.{decimals}f}"
        if len(text) <= width:
            return text.rjust(width)
    return ">" * width


def _emit(line: Line, width: int, color: bool) -> str:
    out: list[str] = []
    room = width
    for text, sgr in line:
        if room <= 0:
            break
        text = text[:room]
        room -= len(text)
        out.append(f"\x1b[{sgr}m{text}\x1b[0m" if color and sgr and text else text)
    return "".join(out)


def _width(line: Line) -> int:
    return sum(len(t) for t, _ in line)


def _pad(line: Line, width: int) -> Line:
    w = _width(line)
    return line + [(" " * (width - w), "")] if w < width else line


def _flow(tokens: Iterable[Line], width: int, indent: str = "") -> list[Line]:
    """Tokens laid out left to right, two spaces apart, wrapped at ``width``."""
    lines: list[Line] = []
    cur: Line = []
    for tok in tokens:
        if cur and _width(cur) + 2 + _width(tok) > width:
            lines.append(cur)
            cur = [(indent, "")] if indent else []
        if cur and _width(cur) > len(indent):
            cur = cur + [("  ", "")]
        cur = cur + tok
    if cur:
        lines.append(cur)
    return lines


# -- blocks ------------------------------------------------------------------------

def _cell_widths(color: bool) -> tuple[int, ...]:
    # plain cells: ramp character(s) and the value; colour cells: the value on the colour
    return (6, 4, 2, 1) if color else (6, 5, 2, 1)


def _heat_cell(force: float, level: float, w: int, color: bool) -> Seg:
    if color:
        c = heat_color(level)
        fg = 16 if HEAT_COLORS.index(c) >= _LIGHT_FROM else 231
        text = (" " + fit_number(force, w - 2) + " ") if w >= 6 else (fit_number(force, w - 1) + " ") if w >= 4 else " " * w
        return text, f"48;5;{c};38;5;{fg}"
    ch = heat_char(level)
    if w >= 6:
        return ch * 2 + fit_number(force, 3) + " ", ""
    if w == 5:
        return ch + fit_number(force, 3) + " ", ""
    return ch * w, ""


def _heat_width(s: Snapshot, w: int) -> int:
    cols = s.forces.shape[1] if s.forces is not None and s.forces.ndim == 2 else 1
    return _name_width(s) + cols * w


def _name_width(s: Snapshot) -> int:
    return (max(len(n) for n in s.row_names) + 1) if s.row_names else 0


def heat_block(s: Snapshot, w: int, color: bool) -> list[Line]:
    """Title, one line per taxel row, and the colour scale."""
    if s.forces is None or s.forces.size == 0:
        return [[("taxels: no scan yet", "")]]
    f = np.asarray(s.forces, dtype=np.float64)
    top = max(float(np.nanmax(f)) if np.isfinite(f).any() else 0.0, s.scale_min_n)
    nw = _name_width(s)
    lines: list[Line] = [[("taxels, N", "1")]]
    for r in range(f.shape[0]):
        name = (s.row_names[r] if s.row_names else "").ljust(nw)
        line: Line = [(name, "")] if nw else []
        line += [_heat_cell(float(v), heat_level(float(v), top), w, color) for v in f[r]]
        lines.append(line)
    if color:
        ramp: Line = [(" ", f"48;5;{c}") for c in HEAT_COLORS]
    else:
        ramp = [(f"[{RAMP}]", "")]
    lines.append([("0 ", "")] + ramp + [(f" {top:.1f} N", "")])
    return lines


def _state_text(s: Snapshot) -> tuple[str, str, str]:
    """Big label, its style, and the line under it."""
    if s.state is None or s.stale:
        why = "sensor stale: no verdict" if s.stale else "waiting for data"
        return "UNKNOWN", _GREY, why
    label = s.state.replace("_", " ").upper()
    if not s.valid:
        return label, _GREY, "not valid (warm-up): no verdict"
    return label, _STATE_STYLE.get(s.state, "1"), "valid"


def _gauge(name: str, value: float | None, slip: float | None, variable: float | None, width: int) -> Line:
    """``name [#####:###|---]  value``: the bar up to the value, ``|`` at the slip
    threshold, ``:`` at the varying-force threshold; ``>`` past the end of the scale."""
    num = "     -" if value is None else fit_number(value, 6)
    bar_w = max(width - len(name) - 3 - 1 - 6 - (len(f" /{slip:g}") if slip is not None else 0), 4)
    top = 2.0 * slip if slip else max(2.0 * (variable or 0.0), (value or 0.0) * 1.25, 1.0)
    v = 0.0 if value is None or not math.isfinite(value) else max(value, 0.0)
    filled = min(int(round(v / top * bar_w)), bar_w)
    at = {int(round(slip / top * bar_w)) if slip else -1: "|",
          int(round(variable / top * bar_w)) if variable else -1: ":"}
    level = "1;32" if not variable or v <= variable else "1;33"
    if slip is not None and v > slip:
        level = "1;31"
    bar: Line = []
    for i in range(bar_w):
        mark = at.get(i)
        if i == bar_w - 1 and v > top:
            bar.append((">", level))
        elif mark is not None:
            bar.append((mark, "1"))
        elif i < filled:
            bar.append(("#", level))
        else:
            bar.append(("-", "2"))
    out: Line = [(f"{name} [", "")] + _merge(bar) + [("] ", ""), (num, "1")]
    if slip is not None:
        out.append((f" /{slip:g}", "2"))
    return out


def _merge(line: Line) -> Line:
    """Adjacent segments of one style as one (fewer escape codes on the wire)."""
    out: Line = []
    for text, sgr in line:
        if out and out[-1][1] == sgr:
            out[-1] = (out[-1][0] + text, sgr)
        else:
            out.append((text, sgr))
    return out


def panel_block(s: Snapshot, width: int, color: bool) -> list[Line]:
    """The state, big; validity, force and centre of force; the two gauges."""
    label, style, under = _state_text(s)
    inner = max(width - 2, len(label))
    if color:
        box = [[(" " * (inner + 2), style)], [(label.center(inner + 2), style)], [(" " * (inner + 2), style)]]
    else:
        edge = "+" + "-" * inner + "+"
        box = [[(edge, "")], [("|" + label.center(inner) + "|", "")], [(edge, "")]]
    info: Line = [(under, "1;31" if s.valid is False and s.state is not None and not s.stale else "")]
    if s.f_sum is not None:
        info.append((f"  F {s.f_sum:.2f} N", ""))
    if s.cof is not None and s.state not in (None, "no_contact"):
        info.append((f"  CoF {s.cof[0]:.1f},{s.cof[1]:.1f} mm", ""))
    sc: IndicatorScale = s.scale
    names = [n.ljust(max(len(x) for x in sc.names)) for n in sc.names]
    lines = box + [info] + [[(text, "1")] for text in s.extra]
    lines.append(_gauge(names[0], s.r_coe, sc.slip[0], sc.variable[0], width))
    lines.append(_gauge(names[1], s.r_dw, sc.slip[1], sc.variable[1], width))
    if sc.meaning:
        lines.append([(sc.meaning, "2")])
    return lines


_UNITS = {"F_SUM": " mN", "FRAME_AGE": " ms"}


def register_block(s: Snapshot, width: int) -> list[Line]:
    title = "PLC registers" + (f", {s.registers_from}" if s.registers_from else "")
    if s.registers is None:
        return [[(title, "1")], [("none published yet", "2")]]
    regs: Mapping[str, int] = s.registers
    status = regs.get("STATUS", 0)
    bits = s.status_bits
    head: list[Line] = [[(f"STATUS 0x{status:04x}", "1")]] + [[(b, _BIT_STYLE.get(b, ""))] for b in bits]
    if "DATA_VALID" not in bits:
        head.append([("(no DATA_VALID)", "2")])
    tokens: list[Line] = []
    for name, value in regs.items():
        if name == "STATUS":
            continue
        if name == "STATE":
            label = GraspState(value).label if value in GraspState._value2member_map_ else "?"
            tokens.append([(f"STATE {value} ({label})", "")])
        elif name == "FLAGS":
            desc = FrameFlag.describe(value)
            tokens.append([(f"FLAGS 0x{value:04x}" + (f" {desc}" if desc else ""), "")])
        else:
            tokens.append([(f"{name} {value}{_UNITS.get(name, '')}", "")])
    return [[(title, "1")]] + _flow(head, width) + _flow(tokens, width)


def counter_block(s: Snapshot, width: int) -> list[Line]:
    tokens = [[(f"{k} {v}", "1;31" if v and k in ("lost", "torn", "malformed", "drops", "bus errors") else "")]
              for k, v in s.counters.items()]
    return _flow([[("counters", "1")]] + tokens, width)


def header_line(s: Snapshot, width: int) -> Line:
    left = f"{s.title}  {s.source}".rstrip()
    right = f"{s.elapsed_s:.1f} s"
    if s.scan_rate_hz is not None:
        right = f"{s.scan_rate_hz:.0f} scans/s  {right}"
    if len(left) + 1 + len(right) > width:
        right = f"{s.elapsed_s:.1f} s"  # narrow: the rate goes first
    if len(left) + 1 + len(right) > width:
        room = width - len(right) - 1
        left = left[:room] if room > 0 else ""
    if not left:
        return [(right[-width:], "1")]
    return [(left, "1"), (" " * (width - len(left) - len(right)), ""), (right, "")]


# -- the screen --------------------------------------------------------------------

def _top(s: Snapshot, width: int, color: bool) -> tuple[list[Line], list[Line] | None]:
    """Heat map and panel side by side when they fit (one block), else each alone."""
    for w in _cell_widths(color):
        heat = heat_block(s, w, color)
        left_w = max(_width(line) for line in heat)
        panel_w = min(width - left_w - 2, _PANEL_MAX)
        if panel_w >= _PANEL_MIN:
            panel = panel_block(s, panel_w, color)
            rows = max(len(heat), len(panel))
            heat += [[] for _ in range(rows - len(heat))]
            panel += [[] for _ in range(rows - len(panel))]
            return [_pad(h, left_w + 2) + p for h, p in zip(heat, panel)], None
    panel = panel_block(s, min(width, _PANEL_MAX), color)
    for w in _cell_widths(color):
        if _heat_width(s, w) <= width:
            return panel, heat_block(s, w, color)
    return panel, heat_block(s, 1, color)


def render(snapshot: Snapshot, width: int, height: int, color: bool) -> list[str]:
    """The screen for ``snapshot``: at most ``height`` lines of at most ``width``
    visible characters; ANSI colour codes only when ``color``."""
    if width <= 0 or height <= 0:
        return []
    s = snapshot
    first, heat_alone = _top(s, width, color)
    # (priority, lines): lower numbers are kept longer; the state outlives the header
    blocks: list[tuple[int, list[Line]]] = [(1, [header_line(s, width)]), (0, first)]
    if heat_alone is not None:
        blocks.append((2, heat_alone))
    blocks += [(3, register_block(s, width)), (4, counter_block(s, width))]
    while len(blocks) > 1 and sum(len(b) for _, b in blocks) > height:
        blocks.remove(max(blocks, key=lambda b: b[0]))
    lines: list[Line] = []
    room = height - sum(len(b) for _, b in blocks)
    gaps = len(blocks) - 1
    spaced = room >= gaps + 3  # blank lines between blocks only if the log still gets some
    for i, (_, b) in enumerate(blocks):
        if i and spaced:
            lines.append([])
        lines += b
    room = height - len(lines)
    if room >= 3 and s.log:
        lines.append([])
        lines.append([("state changes", "1")])
        lines += [[(text, "")] for text in s.log[-(room - 2):]]
    return [_emit(line, width, color) for line in lines[:height]]
